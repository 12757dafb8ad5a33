"""What ASE asks of a filter besides coordinates and forces: the atoms' own answers.

:class:`AtomsFacade` is the part of :class:`rigidmd.relax.filter.RigidFilter`
that hands ASE's optimizers, trajectories and loggers the real atoms'
cell, periodicity, calculator, symbols and stress, as ``ase.filters`` do.
"""

try:  # ASE >= 3.24
    from ase.filters import OptimizableFilter as _Optimizable
except ImportError:  # pragma: no cover - ASE 3.23
    from ase.optimize.optimize import OptimizableAtoms as _Optimizable

__all__ = ["AtomsFacade", "OptimizableFilter"]

OptimizableFilter = _Optimizable  #: ASE's optimizable of a filter (its class by version)


class AtomsFacade:
    """Delegates to ``self.atoms`` (an :class:`ase.Atoms`) what a filter passes through."""

    def iterimages(self):
        """The real atoms, for trajectories."""
        return self.atoms.iterimages()

    def get_cell(self):
        return self.atoms.get_cell()

    def get_pbc(self):
        return self.atoms.get_pbc()

    @property
    def calc(self):
        return self.atoms.calc

    def get_calculator(self):
        return self.atoms.calc

    def get_chemical_symbols(self):
        return self.atoms.get_chemical_symbols()

    def has(self, name):
        return self.atoms.has(name)

    def __ase_optimizable__(self):
        return _Optimizable(self)

    def get_stress(self, *args, **kwargs):
        return self.atoms.get_stress(*args, **kwargs)
