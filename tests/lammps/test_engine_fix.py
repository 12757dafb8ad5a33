"""The engine's own ``fix rigidmd/ipi`` (plugin/rigidmd_ipi.cpp) against the in-process
calculator: cell shapes and changes, atoms far outside, neighbour builds, what is tallied,
the fall-back to ``fix ipi``, waiting ranks, and an engine started by hand over TCP.

The liquid is ``tests/data/water_box_27.traj`` (27 TIP3P waters, 9.3 Å box) with
``lj/cut/coul/long 4.5`` and PPPM at 1e-5 (``PPPM_27``).
"""

import os
import time
import warnings

import numpy as np
import pytest
from helpers import (
    PPPM_27,
    free_port,
    processes_named,
    start_by_hand,
    water_box_27,
)

from rigidmd.ipi.processes import cpu_seconds, descendants
from rigidmd.lammps import LAMMPSCalculator, boxplugin
from rigidmd.lammps import engine as engine_module
from rigidmd.lammps.engine import LAMMPSEngine

pytestmark = pytest.mark.lammps


def assert_equal_to_in_process(atoms, reference):
    """Energy, forces and stress of ``atoms`` (engine) equal ``reference`` (in-process).

    The reference gets the same atoms wrapped into the cell (the in-process
    calculator's own handling of far-away atoms is not under test here).  Measured
    (27 waters, 1 and 2 ranks): energy 0 to 2e-13 eV, forces 2e-14 eV/Å (8e-11 on
    forces of 1e4 eV/Å after a random 0.8 Å shake), stress 5e-15 relative; the
    engine's numbers pass Bohr and Hartree both ways.  Bounds: 100 times those.
    """
    reference.set_cell(atoms.cell)
    reference.positions = atoms.positions
    reference.wrap()
    energy = reference.get_potential_energy()
    forces = reference.get_forces()
    stress = reference.get_stress()
    assert atoms.get_potential_energy() == pytest.approx(energy, rel=1e-13, abs=1e-11)
    np.testing.assert_allclose(atoms.get_forces(), forces, rtol=0,
                               atol=1e-12 * max(1.0, np.abs(forces).max()))
    np.testing.assert_allclose(atoms.get_stress(), stress, rtol=0,
                               atol=1e-12 * np.abs(stress).max())


def npt_like_cells(cell, tilted, n=4, seed=0):
    """A sequence of cells as a barostat makes them: small changes of every edge
    (and, when ``tilted``, of the tilts)."""
    rng = np.random.default_rng(seed)
    cells = []
    for _ in range(n):
        cell = cell * (1 + rng.normal(scale=2e-3))
        if tilted:
            cell = cell + np.tril(rng.normal(scale=0.02, size=(3, 3)), -1)
        cells.append(cell)
    return cells


@pytest.mark.parametrize("tilted", [False, True])
def test_equal_to_the_in_process_calculator_through_cells_and_far_atoms(tilted):
    atoms = water_box_27()
    if tilted:
        cell = atoms.cell.array.copy()
        cell[1, 0], cell[2, 0], cell[2, 1] = 0.9, -0.6, 0.4
        atoms.set_cell(cell, scale_atoms=True)
    rng = np.random.default_rng(1)
    with LAMMPSEngine(PPPM_27) as engine:
        atoms.calc = engine
        atoms.get_forces()
        assert engine.engine_fix == "rigidmd/ipi"
        reference = atoms.copy()
        reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
        assert_equal_to_in_process(atoms, reference)
        for cell in npt_like_cells(atoms.cell.array, tilted):
            atoms.set_cell(cell, scale_atoms=True)
            atoms.positions += rng.normal(scale=0.02, size=atoms.positions.shape)
            assert_equal_to_in_process(atoms, reference)
        # whole molecules moved by lattice vectors far out of the cell, both ways
        far = atoms.get_tags() % 4 == 0
        atoms.positions[far] += atoms.cell.array.T @ np.array([3, -7, 12])
        atoms.positions[atoms.get_tags() % 4 == 1] -= 5 * atoms.cell[2]
        assert_equal_to_in_process(atoms, reference)
        atoms.set_cell(atoms.cell * 1.002, scale_atoms=True)  # a new cell with them out
        assert_equal_to_in_process(atoms, reference)


def test_it_re_neighbours_only_when_an_atom_moved_half_the_skin():
    """LAMMPS's count of neighbour-list builds (sent with the forces): none for small
    moves, moves by lattice vectors and small cell changes; one when an atom moved more
    than half the skin (2 Å)."""
    atoms = water_box_27()
    with LAMMPSEngine(PPPM_27) as engine:
        atoms.calc = engine
        atoms.get_forces()
        assert engine.neighbor_builds == 0  # the set-up's build is not counted
        for _ in range(5):
            atoms.positions += 0.05
            atoms.get_forces()
        atoms.positions[:9] += 2 * atoms.cell[0] - atoms.cell[1]
        atoms.get_forces()
        atoms.set_cell(atoms.cell * 1.001, scale_atoms=True)
        atoms.get_forces()
        assert engine.neighbor_builds == 0
        atoms.positions[3] += [1.2, 0.0, 0.0]
        atoms.get_forces()
        assert engine.neighbor_builds == 1
        atoms.get_forces()
        assert engine.neighbor_builds == 1


@pytest.mark.parametrize("processes", [1, 2])
def test_a_cell_shrunk_with_the_atoms_left_in_place_re_neighbours(processes):
    """A cell change with no atom moving (``set_cell(..., scale_atoms=False)``): set_box
    set the new box but forced a re-neighbouring only at a flip, and LAMMPS's check, which
    looks only at atom displacements, saw nothing move, so a cell shrunk by 15 % (the far
    corner 2.4 Å away, past the 2 Å skin) killed the engine ("Out of range atoms - cannot
    compute PPPM"; without k-space: energies 1.7e-3 eV off, silently).  Now the step
    re-neighbours when the box has moved by more than half the skin since the last build,
    and only then: a 2 % change (the far corner 0.32 Å away) builds nothing.  Numbers as
    in assert_equal_to_in_process."""
    atoms = water_box_27()
    atoms.wrap()
    atoms.positions *= 0.9  # (inside the cell, also when moved by 0.6 Å below)
    with LAMMPSEngine(PPPM_27, processes=processes) as engine:
        atoms.calc = engine
        atoms.get_forces()
        reference = atoms.copy()
        reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
        # Moved past half the skin: LAMMPS builds its lists at the positions sent, in
        # their own images (the set-up's positions from the data file differ from them
        # by roundoff, which LAMMPS's check would count as motion).
        atoms.positions += 0.6
        atoms.get_forces()
        assert engine.neighbor_builds == 1
        cell = atoms.cell.array.copy()
        atoms.set_cell(cell * 1.02, scale_atoms=False)
        assert_equal_to_in_process(atoms, reference)
        assert engine.neighbor_builds == 1
        atoms.set_cell(cell * 0.85, scale_atoms=False)
        assert_equal_to_in_process(atoms, reference)
        assert engine.neighbor_builds == 2


def test_only_what_is_asked_for_is_tallied():
    """RMDTALLY: forces alone carry no energy or stress; the stress alone no energy;
    what comes equals the in-process calculator's."""
    atoms = water_box_27()
    with LAMMPSEngine(PPPM_27) as engine:
        atoms.calc = engine
        engine.calculate(atoms, ["forces"], ["positions"])
        assert set(engine.results) == {"forces"}
        reference = atoms.copy()
        reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
        np.testing.assert_allclose(engine.results["forces"], reference.get_forces(), rtol=0,
                                   atol=1e-12)
        engine.calculate(atoms, ["stress"], ["positions"])
        assert set(engine.results) == {"forces", "stress"}
        np.testing.assert_allclose(engine.results["stress"], reference.get_stress(), rtol=0,
                                   atol=1e-12 * np.abs(reference.get_stress()).max())
        engine.calculate(atoms, ["energy"], [])
        assert set(engine.results) == {"forces", "stress", "energy", "free_energy"}
        assert engine.results["energy"] == pytest.approx(reference.get_potential_energy(),
                                                         rel=1e-13)


def test_without_the_plugin_fix_ipi_is_used_and_said_once(monkeypatch):
    monkeypatch.setenv("RIGIDMD_LAMMPS_PLUGIN", "0")
    monkeypatch.setattr(engine_module, "_WARNED", [])
    boxplugin.forget()
    try:
        atoms = water_box_27()
        with pytest.warns(UserWarning, match=r"LAMMPSEngine: no rigidmd LAMMPS plugin "
                          r"\(switched off by RIGIDMD_LAMMPS_PLUGIN\); the engine runs "
                          r"LAMMPS's fix ipi"):
            with LAMMPSEngine(PPPM_27) as engine:
                atoms.calc = engine
                atoms.get_forces()
                assert engine.engine_fix == "ipi"
                assert "all ipi " in (engine.log.parent / "in.engine").read_text()
                reference = atoms.copy()
                reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
                np.testing.assert_allclose(atoms.get_forces(), reference.get_forces(),
                                           rtol=0, atol=1e-12)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # the second engine says nothing
            with LAMMPSEngine(PPPM_27) as engine:
                atoms.calc = engine
                atoms.get_forces()
                assert engine.engine_fix == "ipi"
    finally:
        monkeypatch.undo()
        boxplugin.forget()  # the next user looks for the plugin again


def idle_rank_cpu(poll_us):
    """CPU seconds the two ranks of an engine use in one second without a call."""
    atoms = water_box_27()
    with LAMMPSEngine(PPPM_27, processes=2, poll_us=poll_us) as engine:
        atoms.calc = engine
        for _ in range(10):
            atoms.positions += 0.001
            atoms.get_forces()
        ranks = [p for p in descendants(engine.pid) if p in processes_named("lmp")]
        assert len(ranks) == 2
        before = cpu_seconds(ranks)
        time.sleep(1.0)
        return cpu_seconds(ranks) - before


def test_waiting_ranks_do_not_spin():
    """Two ranks: while rigidmd does not call, rank 1 naps, where MPICH's own wait
    (poll_us=0) polls.  Measured against that spinning wait in the same test, since what
    a spinning rank gets depends on the machine's load: quiet, it takes a whole core and
    the naps 0-3 % of one; at load 9-10 on 2 cores the spinner got 0.29 s and the napping
    ranks 0.18 s in a second.  Bound: half the spinning wait's CPU."""
    spinning = idle_rank_cpu(0)
    napping = idle_rank_cpu(500)
    assert napping < 0.5 * spinning, (napping, spinning)


@pytest.mark.parametrize("processes, threads, launch, cores, expected", [
    (2, None, True, 2, 0), (16, None, True, 16, 0), (15, None, True, 16, 500),
    (4, 2, True, 8, 0), (4, 2, True, 12, 500), (2, None, False, 2, 500)])
def test_ranks_that_take_every_core_wait_in_mpi(monkeypatch, tmp_path, processes, threads,
                                                launch, cores, expected):
    """The default ``poll_us``: the naps only where the engine leaves a core to spare (16
    napping ranks on 16 cores made a step 13-16x native's, MPI's own wait 1.1x); an
    engine started elsewhere naps (its host's cores are not known).  The choice reaches
    the fix's input; a given ``poll_us`` is kept."""
    from rigidmd.lammps.engine import default_poll_us

    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: set(range(cores)))
    assert default_poll_us(processes, threads, launch) == expected
    engine = LAMMPSEngine(PPPM_27, processes=processes, threads=threads, launch=launch)
    assert engine.poll_us == expected
    engine.write_input(water_box_27(), tmp_path)
    assert engine.engine_fix == "rigidmd/ipi"
    assert f" poll {expected}\n" in (tmp_path / "in.engine").read_text()
    assert LAMMPSEngine(PPPM_27, processes=processes, poll_us=250).poll_us == 250


def engine_input(engine):
    return (engine._workdir / "in.engine").read_text()


def test_engines_of_one_process_nap_while_the_other_computes(monkeypatch):
    """Two engines of 2 ranks on 2 cores, the levels of a split: each took MPI's own wait
    (poll_us=0) when it was made, so the idle one's rank kept a core busy while the other
    computed; the split at 6 fs, k = 2, made 4-28 ns/day on 216 waters where naps make
    45-55 (validation/respa_lammps_cost.py --engine 2).  Now each decides at its start,
    knowing the other engines of the process that run or are yet to start."""
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    atoms = water_box_27()
    with LAMMPSEngine(PPPM_27, processes=2) as first, \
            LAMMPSEngine(PPPM_27, processes=2) as second:
        for engine in (first, second):
            atoms.calc = engine
            atoms.get_forces()
            assert engine.poll_us == 500 and " poll 500\n" in engine_input(engine)
    with LAMMPSEngine(PPPM_27, processes=2) as alone:  # the others are closed
        atoms.calc = alone
        atoms.get_forces()
        assert alone.poll_us == 0 and " poll 0\n" in engine_input(alone)
        with LAMMPSEngine(PPPM_27, processes=2) as late, \
                pytest.warns(UserWarning, match=rf"another engine of this process \(watchdog "
                             rf"pid {alone.pid}\) waits with poll_us=0, its ranks keeping 1 "
                             r"core\(s\) busy while this one computes"):
            atoms.calc = late
            atoms.get_forces()
        assert late.poll_us == 500
    with LAMMPSEngine(PPPM_27, processes=2, poll_us=0) as given, \
            LAMMPSEngine(PPPM_27, processes=2, poll_us=0) as other:
        assert given.poll_us == other.poll_us == 0  # given: kept


def test_a_refused_engine_is_no_engine_of_the_process():
    """A constructor refused (here its kspace_parameters) had joined the process's engines
    half-made; while anything kept it (an interactive session's last traceback), every
    later ``LAMMPSEngine(...)`` failed with "'LAMMPSEngine' object has no attribute
    '_proc'"."""
    with pytest.raises(ValueError, match="kspace_parameters must be one") as refused:
        LAMMPSEngine(PPPM_27, kspace_parameters="kspace_style pppm 1e-4")
    kept = refused.value.__traceback__  # holds the half-made object's frame
    engine = LAMMPSEngine(PPPM_27)
    assert engine.poll_us in (0, 500) and kept is not None


def test_two_engines_of_one_process_may_not_share_a_socket(tmp_path):
    """The levels of a split given one ``unixsocket`` (or port): the fast level started
    and computed, then the full level failed with "in use by another live process"; now
    the second engine is refused when it is made."""
    first = LAMMPSEngine(PPPM_27, unixsocket="rigidmd-test-shared")
    with pytest.raises(ValueError, match="LAMMPSEngine: unixsocket 'rigidmd-test-shared' is "
                                         "already that of another engine of this process"):
        LAMMPSEngine(PPPM_27, unixsocket="rigidmd-test-shared")
    port = LAMMPSEngine(PPPM_27, port=34571)
    with pytest.raises(ValueError, match="LAMMPSEngine: port 34571 on 'localhost' is already"):
        LAMMPSEngine(PPPM_27, port=34571)
    assert first.pid is None and port.pid is None  # nothing started
    first.close()
    port.close()


@pytest.mark.parametrize("processes", [1, 2])
def test_rank_zero_says_how_long_the_others_took_to_join(processes):
    """``broadcast_us``: rank 0's mean wait per call for the other ranks to take the
    positions (their wake-up from the naps); none on one rank.  Measured (two ranks, 5 calls,
    2 cores): 0.9-1.5 µs in 31 engines on a quiet machine and beside three busy loops;
    1.0-2.4 µs in 35 of 36 and 13 µs in one at load 9 (three such runs side by side with four
    matrix products).  The bound, half the longest nap (poll_us 500 µs), is exceeded by ranks
    that sleep a whole nap past rank 0's arrival in three calls of five (100 µs each call);
    it is 19 times the worst measured, for a loaded CI machine."""
    atoms = water_box_27()
    with LAMMPSEngine(PPPM_27, processes=processes, poll_us=500) as engine:
        atoms.calc = engine
        for _ in range(5):
            atoms.positions += 0.001
            atoms.get_forces()
        waited = engine.broadcast_us
    if processes == 1:
        assert waited is None
    else:
        assert 0.0 < waited < 250.0, waited


@pytest.mark.parametrize("processes", [1, 2])
def test_an_engine_started_by_hand_over_tcp(tmp_path, processes):
    """As on a second node: launch=False writes the input, someone starts
    ``[mpirun -np 2] lmp -in in.engine`` there, it connects to our port; results equal
    the in-process calculator's; close() sends EXIT and LAMMPS ends its run normally."""
    port = free_port()
    engine = LAMMPSEngine(PPPM_27, processes=processes, launch=False, port=port,
                          workdir=tmp_path, timeout=60)
    thread, started = start_by_hand(engine, tmp_path)
    atoms = water_box_27()
    try:
        atoms.calc = engine
        atoms.get_forces()
        reference = atoms.copy()
        reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
        assert_equal_to_in_process(atoms, reference)
        atoms.set_cell(atoms.cell * 0.998, scale_atoms=True)
        assert_equal_to_in_process(atoms, reference)
    finally:
        engine.close()
        thread.join()
        code = started[0].wait(timeout=60)
    assert code == 0  # EXIT ends the run; LAMMPS leaves by itself
    text = (tmp_path / "log.lammps").read_text()
    assert f"fix rmd_ipi all rigidmd/ipi localhost {port}" in text
    assert "Loop time of" in text
    assert not [p for p in descendants(started[0].pid) if p in processes_named("lmp")]


@pytest.mark.parametrize("processes", [1, 2])
def test_a_flip_of_the_basis_keeps_the_engine(processes):
    """A cell sheared through several flips of its reduced basis (b from 0.3 to 2.7 box
    lengths and back to -1.6, c with it): the engine re-maps its atoms and re-neighbours,
    as native LAMMPS at a flip, and each call equals the in-process calculator (which
    reduces the basis alike).  Before: every flip started a new engine (a Monte Carlo
    barostat with couple tri: 15 engines in 150 steps)."""
    atoms = water_box_27()
    lengths, length = atoms.cell.lengths(), atoms.cell.array[0, 0]
    with LAMMPSEngine(PPPM_27, processes=processes, triclinic=True) as engine:
        atoms.calc = engine
        atoms.get_potential_energy()
        first = engine.pid
        reference = atoms.copy()
        reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
        # (the last: a flip with the atoms where they were, no motion to trigger LAMMPS's
        # neighbour check)
        for shear, scale in ((0.3, True), (0.6, True), (1.4, True), (2.7, True),
                             (0.45, True), (-0.55, True), (-1.6, True), (-1.45, False)):
            cell = np.diag(lengths)
            cell[1, 0], cell[2, 0], cell[2, 1] = shear * length, 0.3 * shear * length, \
                -0.7 * shear * length
            atoms.set_cell(cell, scale_atoms=scale)
            assert_equal_to_in_process(atoms, reference)
            assert engine.pid == first, shear
