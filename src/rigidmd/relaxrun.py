"""Relaxing the structure of a run: ``rigidmd relax CONFIG`` and the ``relax:`` section.

:func:`relax_structure` relaxes the rigid bodies (and the cell) of a run's
start with :func:`rigidmd.optimize.relax`, writing the optimizer's trajectory
(every step, so the last frame is the structure reached) and log in the
output directory.  A relaxation that does not converge within its steps
raises :class:`RelaxationNotConverged` with one line naming the trajectory
whose last frame holds the structure reached.
"""

import sys

from rigidmd.optimize import relax

__all__ = ["relax_structure", "RelaxationNotConverged", "relax_only"]


class RelaxationNotConverged(RuntimeError):
    """A relaxation reached its step limit above ``fmax``."""


def relax_structure(atoms, bodies, section, directory, stream=sys.stdout):
    """Relax ``atoms`` in place as ``section`` says; files go to ``directory``.

    Parameters
    ----------
    atoms : ase.Atoms
        With its calculator.
    bodies : rigidmd.RigidBodies
    section : rigidmd.config.relaxsection.RelaxSection
    directory : pathlib.Path
    stream : file
        Where the one-line summary goes.

    Returns
    -------
    rigidmd.optimize.Relaxation

    Raises
    ------
    RelaxationNotConverged
        Not converged within ``section.steps`` (the trajectory holds the
        structure reached).
    """
    from rigidmd.core.bodies import store_bodies_in_tags

    directory.mkdir(parents=True, exist_ok=True)
    store_bodies_in_tags(atoms, bodies.body_ids)  # every frame carries the bodies
    trajectory = directory / section.trajectory
    log = directory / section.log
    result = relax(atoms, bodies, fmax=section.fmax, steps=section.steps,
                   optimizer=section.optimizer, cell=section.cell,
                   scalar_pressure=section.pressure, trajectory=str(trajectory),
                   logfile=str(log))
    cell = f", cell {section.cell}" if section.cell else ""
    if not result.converged:
        raise RelaxationNotConverged(
            f"relax: {section.optimizer} did not reach fmax {section.fmax:g} eV/Å in "
            f"{section.steps} steps (largest generalized force {result.fmax:.3g} eV/Å); the "
            f"structure reached is the last frame of {trajectory}; raise relax.steps or "
            "restart from it")
    print(f"relaxed {bodies} ({section.optimizer}{cell}) in {result.steps} steps to fmax "
          f"{result.fmax:.3g} eV/Å, energy {result.energy:.6f} eV; wrote {trajectory} and "
          f"{log}", file=stream)
    return result


def relax_only(raw, stream=sys.stdout, trust=False):
    """``rigidmd relax CONFIG``: build the structure and calculator, relax, write.

    Parameters
    ----------
    raw : dict
        A configuration as :func:`rigidmd.config.load_config` returns; the MD
        keys may be present and are ignored, a missing ``relax:`` section is
        the defaults of :class:`~rigidmd.config.relaxsection.RelaxSection`.
    trust : bool
        ``--trust``: let the calculator section run what could run code
        (:mod:`rigidmd.config.trust`), as for ``rigidmd run``.

    Returns
    -------
    int
        Exit status: 0.
    """
    from pathlib import Path

    from rigidmd.config import known_keys
    from rigidmd.config.quantities import ConfigError
    from rigidmd.config.relaxsection import RelaxSection
    from rigidmd.config.sections import CalculatorSection, OutputsSection, StructureSection
    from rigidmd.config.trust import check_output_paths

    raw = dict(raw)
    base = Path(raw.pop("_base", "."))
    unknown = sorted(set(raw) - known_keys(), key=str)
    if unknown:
        raise ConfigError(f"{unknown[0]}: unknown key; allowed: "
                          f"{', '.join(sorted(known_keys()))}")
    check_output_paths(raw, trust)
    structure = StructureSection.from_config(raw, base)
    calculator = CalculatorSection.from_config(raw, base)
    calculator.check_trust(trust)
    outputs = OutputsSection.from_config(raw, base)
    section = RelaxSection.from_config(raw, base) or RelaxSection()
    atoms = structure.build_atoms()
    bodies = structure.resolve_bodies(atoms)
    atoms.calc = calculator.build(atoms)
    relax_structure(atoms, bodies, section, outputs.directory, stream)
    return 0
