"""The ``relax:`` section of a run configuration: a rigid relaxation before MD.

::

    relax:
      fmax: 0.05                  # eV/Å (a bare number, or '0.05 eV/A')
      steps: 1000                 # optimizer steps allowed
      optimizer: RigidLBFGS       # RigidLBFGS | PreconLBFGS | PreconFIRE | BFGS | LBFGS | FIRE
                                  # | BFGSLineSearch | GPMin | MDMin
      cell: false                 # false | true (full) | iso | aniso | full
      pressure: 0 bar             # target pressure with the cell (bar, atm, GPa, Pa, eV/A^3)
      trajectory: relax.traj      # in outputs.directory; every optimizer step
      log: relax.log              # the optimizer's log

``rigidmd run`` relaxes the structure first (a new run, not a restart or a
resume), then draws velocities and runs MD from the relaxed structure;
``rigidmd relax CONFIG`` only relaxes (see :mod:`rigidmd.run.relaxstructure`).
"""

from dataclasses import dataclass
from pathlib import Path

from ase import units

from rigidmd.config.couplingsection import LARGEST_PRESSURE
from rigidmd.config.quantities import (
    PRESSURE_UNITS,
    ConfigError,
    mapping,
    parse_quantity,
    whole_number,
)

__all__ = ["RelaxSection"]

FORCE_UNITS = {"eV/A": 1.0}


@dataclass
class RelaxSection:
    """How to relax the structure before MD (quantities in ASE units).

    Attributes
    ----------
    fmax : float
        eV/Å.
    steps : int
    optimizer : str
    cell : bool or str
        False, or one of ``iso``, ``aniso``, ``full``.
    pressure : float
        eV/Å³.
    trajectory, log : str
        File names in the output directory.
    """

    KEYS = ("relax",)
    FIELDS = ("fmax", "steps", "optimizer", "cell", "pressure", "trajectory", "log")

    fmax: float = 0.05
    steps: int = 1000
    optimizer: str = "RigidLBFGS"
    cell: object = False
    pressure: float = 0.0
    trajectory: str = "relax.traj"
    log: str = "relax.log"

    @classmethod
    def from_config(cls, raw, base=None):
        """The section of ``raw["relax"]``, or None when there is none."""
        from rigidmd.relax.cell import CELL_MODES
        from rigidmd.relax.filter import OPTIMIZERS

        if "relax" not in raw or raw["relax"] is None:
            return None
        section = mapping("relax", raw["relax"], cls.FIELDS)
        if raw.get("restart") is not None:
            raise ConfigError("relax: a restart continues a run's dynamics; relax its last "
                              "frame with 'rigidmd relax' and start a new run from that")
        out = cls()
        if "fmax" in section:
            out.fmax = parse_quantity("relax.fmax", section["fmax"], FORCE_UNITS,
                                      default_unit="eV/A")
            if not out.fmax > 0:
                raise ConfigError(f"relax.fmax: must be positive, got {section['fmax']!r}")
        if "steps" in section:
            out.steps = whole_number("relax.steps", section["steps"], minimum=1)
        if "optimizer" in section:
            if section["optimizer"] not in OPTIMIZERS:
                raise ConfigError(f"relax.optimizer: {section['optimizer']!r} is not one of "
                                  f"{', '.join(OPTIMIZERS)}")
            out.optimizer = section["optimizer"]
        if "cell" in section:
            cell = section["cell"]
            if cell is True:
                cell = "full"
            if not (cell is False or cell in CELL_MODES):
                raise ConfigError(f"relax.cell: expected false, true or one of "
                                  f"{', '.join(CELL_MODES)}, got {cell!r}")
            out.cell = cell
        if "pressure" in section:
            if out.cell is False:
                raise ConfigError("relax.pressure: a target pressure needs relax.cell "
                                  "(iso, aniso or full)")
            out.pressure = parse_quantity("relax.pressure", section["pressure"],
                                          PRESSURE_UNITS)
            if abs(out.pressure) > LARGEST_PRESSURE:  # as a barostat's target
                limit = LARGEST_PRESSURE / units.GPa
                raise ConfigError(f"relax.pressure: {section['pressure']} is beyond "
                                  f"±{limit:.4g} GPa (±{limit * 1e4:.4g} bar), where "
                                  "molecules no longer stay whole; is the unit right?")
        for key in ("trajectory", "log"):
            if key in section:
                name = section[key]
                if not isinstance(name, str) or not name:
                    raise ConfigError(f"relax.{key}: expected a file name, got {name!r}")
                if key == "trajectory" and not name.lower().endswith(".traj"):
                    raise ConfigError(f"relax.trajectory: {name} would hold an ASE trajectory "
                                      "under another format's name; end it in .traj")
                setattr(out, key, name)
        return out

    def check_paths(self, directory, others=None) -> None:
        """Refuse in one line, before anything is written, relaxation outputs that would
        overwrite each other or another output (``others``: field -> path, the run's), a
        folder given as a file, or a folder that does not exist.

        The relaxation writes ``trajectory``, ``log`` and, beside the trajectory, its
        state file (``relax.traj`` -> ``relax.state.npz``) in ``directory``, which also
        holds the lock file.
        """
        from rigidmd.config.sections import check_output_files

        directory = Path(directory)
        trajectory = directory / self.trajectory
        check_output_files(directory, [
            ("relax.trajectory", "relax.trajectory", trajectory),
            ("relax.trajectory", "the relaxation's state file (beside relax.trajectory)",
             trajectory.with_suffix(".state.npz")),
            ("relax.log", "relax.log", directory / self.log)],
            {Path(path).resolve(): name for name, path in (others or {}).items()})

    def check_structure(self, atoms) -> None:
        """Refuse in one line, before anything is written, a cell relaxation the structure
        cannot have: its cell not periodic in all three directions, or (with a calculator
        on the atoms) no stress."""
        if self.cell is False:
            return
        given = "true (full)" if self.cell == "full" else self.cell  # as either was written
        if not atoms.pbc.all():
            raise ConfigError(f"relax.cell: {given} relaxes the cell, which needs a "
                              f"structure periodic in all three directions (its pbc is "
                              f"{atoms.pbc.tolist()}); give relax.cell: false")
        calc = atoms.calc
        if calc is not None and "stress" not in getattr(calc, "implemented_properties",
                                                        ("stress",)):
            raise ConfigError(f"relax.cell: {given} relaxes the cell, which needs the "
                              f"stress, and the calculator {type(calc).__name__} gives none; "
                              "give relax.cell: false or a calculator with stress")
