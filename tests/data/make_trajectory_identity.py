"""Write the reference trajectories that every refactoring must reproduce bit for bit.

Each ensemble and barostat combination rigidmd offers, on both backends, runs
``STEPS`` steps of a small periodic fluid (27 rigid LJ dimers plus, for the
mixed case, free atoms) from the same start; the conserved energy after each
step and the final positions, momenta and cell are stored in
``tests/data/trajectory_identity.npz`` together with the versions of the
packages that decide the floating-point results (Python, NumPy, numba, ASE).
``tests/project/test_trajectory_identity.py`` runs the same cases and compares: bit for
bit when those versions are the stored ones (the pinned environment,
``.ci/pinned.txt``), else within a bound the test explains.

Run from the repository root: ``python tests/data/make_trajectory_identity.py``.
"""

import pathlib
import platform
import sys

import numpy as np
from ase import units

HERE = pathlib.Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

STEPS = 30
DT = 5 * units.fs
OUT = HERE / "trajectory_identity.npz"


def cases():
    """Name -> function (atoms, backend) -> dynamics, for every combination."""
    import rigidmd
    from rigidmd.couplings.barostats import CRescaleBarostat, MTKBarostat
    from rigidmd.couplings.montecarlo import MonteCarloBarostat
    from rigidmd.couplings.thermostats import LangevinThermostat, NoseHooverThermostat

    T, P = 80.0, 50 * units.bar

    def rng():
        return np.random.default_rng(11)

    return {
        "verlet": lambda a, b: rigidmd.RigidVerlet(a, DT, bodies="tags", backend=b),
        "verlet_richardson": lambda a, b: rigidmd.RigidVerlet(
            a, DT, bodies="tags", backend=b, integrator="richardson"),
        "langevin": lambda a, b: rigidmd.RigidLangevin(
            a, DT, T, 0.01, rng=rng(), bodies="tags", backend=b),
        "langevin_baoab": lambda a, b: rigidmd.RigidLangevinBAOAB(
            a, DT, T, 0.01, rng=rng(), bodies="tags", backend=b),
        "bussi": lambda a, b: rigidmd.RigidBussi(
            a, DT, T, 100 * units.fs, rng=rng(), bodies="tags", backend=b),
        "nose_hoover": lambda a, b: rigidmd.RigidNoseHoover(
            a, DT, T, 100 * units.fs, bodies="tags", backend=b),
        "npt_mtk_iso": lambda a, b: rigidmd.RigidNPT(
            a, DT, T, P, 100 * units.fs, 1000 * units.fs, bodies="tags", backend=b),
        "npt_mtk_tri": lambda a, b: rigidmd.RigidNPT(
            a, DT, T, P, 100 * units.fs, 1000 * units.fs, couple="tri", bodies="tags",
            backend=b),
        "crescale_iso": lambda a, b: rigidmd.RigidCRescale(
            a, DT, T, P, 100 * units.fs, 500 * units.fs, 1e-4 / units.bar, rng=rng(),
            bodies="tags", backend=b),
        "crescale_aniso": lambda a, b: rigidmd.RigidCRescale(
            a, DT, T, P, 100 * units.fs, 500 * units.fs, 1e-4 / units.bar, couple="aniso",
            rng=rng(), bodies="tags", backend=b),
        "mc_bussi": lambda a, b: rigidmd.RigidMCBarostat(
            a, DT, T, P, 100 * units.fs, every=3, rng=rng(), adapt_moves=5, step=0.02,
            bodies="tags", backend=b),
        "langevin_crescale": lambda a, b: rigidmd.RigidDynamics(
            a, DT, bodies="tags", backend=b, couplings=[
                LangevinThermostat(T, 0.01, rng=rng(), fixcm=False),
                CRescaleBarostat(T, P, 500 * units.fs, 1e-4 / units.bar, rng=rng())]),
        "nose_hoover_mtk": lambda a, b: rigidmd.RigidDynamics(
            a, DT, bodies="tags", backend=b, couplings=[
                NoseHooverThermostat(T, 100 * units.fs),
                MTKBarostat(T, P, 1000 * units.fs, couple="aniso")]),
        "langevin_mc": lambda a, b: rigidmd.RigidDynamics(
            a, DT, bodies="tags", backend=b, couplings=[
                LangevinThermostat(T, 0.01, rng=rng(), fixcm=False),
                MonteCarloBarostat(T, P, every=3, rng=rng(), adapt_moves=5, step=0.02)]),
        "respa_bussi": "respa",
        "respa_baoab": "respa",
        "free_atoms_bussi": "free",
    }


def start(name):
    """The starting atoms of a case (a new object each call)."""
    from helpers import PeriodicLJ, dimer_fluid

    import rigidmd

    atoms = dimer_fluid(n_side=3, spacing=4.6, seed=5, temperature_K=80, rc=5.5)
    if name.startswith("respa"):
        atoms.calc = rigidmd.MultipleTimeStep(PeriodicLJ(rc=5.5, epsilon=0.005),
                                              PeriodicLJ(rc=5.5, epsilon=0.001), substeps=3)
    if name.startswith("free_atoms"):
        tags = atoms.get_tags()
        tags[:4] = 0  # two dimers become four free atoms
        atoms.set_tags(tags)
        rigidmd.rigid_maxwell_boltzmann(atoms, 80, bodies="tags",
                                        rng=np.random.default_rng(5))
    return atoms


def dynamics(name, atoms, backend):
    from ase import units

    import rigidmd

    made = cases()[name]
    if made == "respa":
        rng = np.random.default_rng(11)
        if name == "respa_bussi":
            return rigidmd.RigidBussi(atoms, 3 * DT, 80.0, 100 * units.fs, rng=rng,
                                      bodies="tags", backend=backend)
        return rigidmd.RigidLangevinBAOAB(atoms, 3 * DT, 80.0, 0.01, rng=rng, bodies="tags",
                                          backend=backend)
    if made == "free":
        return rigidmd.RigidBussi(atoms, DT, 80.0, 100 * units.fs,
                                  rng=np.random.default_rng(11), bodies="tags",
                                  backend=backend)
    return made(atoms, backend)


def run_case(name, backend):
    """The conserved energy after each step; positions, momenta and cell at the end.

    A difference in any bit of any step grows in the chaotic dynamics and shows in
    the final state, so the final arrays and the energies' record suffice."""
    atoms = start(name)
    dyn = dynamics(name, atoms, backend)
    energies = []
    dyn.attach(lambda: energies.append(dyn.get_conserved_energy()), interval=1)
    dyn.run(STEPS)  # one run: a run's start may evaluate the forces again
    energies = energies[1:]  # the observers also see the start
    return {"positions": atoms.get_positions(), "momenta": atoms.get_momenta(),
            "cells": atoms.cell.array.copy(), "energies": np.array(energies)}


def versions():
    import ase
    import numba

    return {"python": platform.python_version(), "numpy": np.__version__,
            "numba": numba.__version__, "ase": ase.__version__}


def main():
    data = {}
    for name in cases():
        for backend in ("numpy", "numba"):
            for key, value in run_case(name, backend).items():
                data[f"{name}/{backend}/{key}"] = value
    for key, value in versions().items():
        data[f"version/{key}"] = np.array(value)
    np.savez_compressed(OUT, **data)
    print(f"wrote {OUT} ({len(cases())} cases x 2 backends x {STEPS} steps)")


if __name__ == "__main__":
    main()
