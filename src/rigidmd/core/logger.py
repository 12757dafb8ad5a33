"""The MD log of a rigid dynamics: ASE's columns, the conserved energy, and P, V, density.

The first five columns are those of ASE's :class:`~ase.md.MDLogger`
(``Time[ps] Etot[eV] Epot[eV] Ekin[eV] T[K]``), so tools that read ASE logs
read these; then the quantity the dynamics conserves (``Econs[eV]``, the total
energy for NVE), the translational and rotational temperatures (``T_tr[K]``,
``T_rot[K]``, over the degrees of freedom of
:func:`rigidmd.core.observables.kinetic_dof`) and, for a periodic cell, the
molecular pressure (``P[bar]``, when a barostat runs or ``log_pressure`` asks for it), the volume
(``V[A^3]``) and the density (``rho[g/cm3]``), then the columns of the coupling
parts that have any (:attr:`rigidmd.core.coupling.Coupling.log_columns`, e.g.
``MCacc[%]``, a Monte Carlo barostat's acceptance since the start).  Energies
carry 6 decimals (µeV), so a slow drift shows as a line, not as steps.

The kinetic columns (``Etot``, ``Ekin``, ``T``, ``T_tr``, ``T_rot``) are those of
:meth:`~rigidmd.core.observables.RigidObservables.get_kinetic_energies`: for a
:class:`~rigidmd.RigidLangevinBAOAB` the momenta right after its O step (which
sample the bath's temperature), otherwise the Atoms' momenta.  ``Econs`` is always
that of the end-of-step state.
"""

from ase import units
from ase.md.logger import MDLogger

__all__ = ["RigidLogger", "LOG_COLUMNS"]

#: Column names, in order; the last four are optional.
LOG_COLUMNS = ("Time[ps]", "Etot[eV]", "Epot[eV]", "Ekin[eV]", "T[K]", "Econs[eV]", "T_tr[K]",
               "T_rot[K]", "P[bar]", "V[A^3]", "rho[g/cm3]")


class RigidLogger(MDLogger):
    """Log lines of a :class:`~rigidmd.core.dynamics.RigidDynamics` (an ASE ``MDLogger``).

    Parameters
    ----------
    dyn : rigidmd.core.dynamics.RigidDynamics
    logfile : str or file
        ``"-"`` for standard output.
    pressure : bool
        Log the molecular pressure (needs a calculator with stress).
    mode : str, default ``"a"``
        How a named file is opened.
    header : bool, default True
    """

    def __init__(self, dyn, logfile, pressure=False, mode="a", header=True):
        self.log_pressure = bool(pressure)
        self.periodic = bool(dyn.atoms.pbc.all())
        super().__init__(dyn, dyn.atoms, logfile, header=False, mode=mode, comm=dyn.comm)
        columns = list(LOG_COLUMNS[:8])
        self.fmt = "%-10.4f %14.6f %14.6f %14.6f %8.2f %14.6f %8.2f %8.2f"
        if self.log_pressure:
            columns.append("P[bar]")
            self.fmt += " %11.3f"
        if self.periodic:
            columns += ["V[A^3]", "rho[g/cm3]"]
            self.fmt += " %12.3f %10.5f"
        widths = [-10, 14, 14, 14, 8, 14, 8, 8] + ([11] if self.log_pressure else [])
        widths += [12, 10] if self.periodic else []
        #: The coupling parts that add columns (their ``log_values()`` at each line).
        self.parts = [part for part in getattr(dyn, "couplings", ()) if part.log_columns]
        for part in self.parts:
            for name in part.log_columns:
                columns.append(name)
                widths.append(max(9, len(name)))
                self.fmt += f" %{widths[-1]}.2f"
        self.fmt += "\n"
        self.hdr = " ".join(f"{name:{'<' if w < 0 else '>'}{abs(w)}}"
                            for name, w in zip(columns, widths, strict=True))
        if header:
            self.logfile.write(self.hdr + "\n")

    def __call__(self):
        dyn, atoms = self.dyn, self.atoms
        epot = atoms.get_potential_energy()
        ekin, T = dyn.get_reported_kinetic_energy()  # the Atoms', or BAOAB's after O
        row = [dyn.get_time() / (1000 * units.fs), epot + ekin, epot, ekin, T,
               dyn.get_conserved_energy(), *dyn.get_kinetic_temperatures()]
        if self.log_pressure:
            row.append(dyn.get_pressure() / units.bar)
        if self.periodic:
            row += [dyn.get_volume(), dyn.get_density()]
        for part in self.parts:
            row += part.log_values()
        self.logfile.write(self.fmt % tuple(row))
        self.logfile.flush()
