"""LAMMPS in its own process (``fix ipi``) against the in-process calculator; its life cycle.

The periodic liquid is ``tests/data/water_box_27.traj`` (27 TIP3P waters in a
9.3 Å box) with ``lj/cut/coul/long 4.5`` and PPPM_27 at 1e-5, as in
``lammps/test_calculator.py``.
"""

import glob
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
from ase import units
from ase.io import read
from helpers import DATA, PPPM_27, processes_named, start_cli_run, water_box_27

from rigidmd import RigidNPT, RigidVerlet, rigid_maxwell_boltzmann
from rigidmd.ipi import EngineError, IPICalculator
from rigidmd.ipi.connection import sweep_stale_sockets
from rigidmd.ipi.processes import descendants
from rigidmd.lammps import LAMMPSCalculator
from rigidmd.lammps.engine import LAMMPSEngine

pytestmark = pytest.mark.lammps


def assert_same(atoms, reference):
    """Energy, forces and stress of ``atoms`` (engine) equal ``reference`` (in-process).

    Both run LAMMPS with the same k-space parameters; the engine's numbers come
    through ``fix ipi``'s 8-digit Bohr and Hartree and back with the same constants:
    measured 0 eV in energy (27 waters), 6e-15 eV/Å in forces, 5e-15 relative in
    stress.  The tolerances leave a factor of 100 for roundoff.
    """
    reference.positions = atoms.positions
    reference.set_cell(atoms.cell)
    energy = reference.get_potential_energy()
    assert atoms.get_potential_energy() == pytest.approx(energy, rel=1e-13, abs=1e-12)
    np.testing.assert_allclose(atoms.get_forces(), reference.get_forces(), rtol=0, atol=1e-12)
    stress = reference.get_stress()
    np.testing.assert_allclose(atoms.get_stress(), stress, rtol=0,
                               atol=1e-12 * np.abs(stress).max())


def test_engine_equals_the_in_process_calculator_through_cell_changes():
    """Orthorhombic, scaled, tilted (the engine restarts with a triclinic box) and a
    triclinic cell scaled again; shear stresses included (fix ipi's upper triangle)."""
    atoms = water_box_27()
    with LAMMPSEngine(PPPM_27) as engine:
        atoms.calc = engine
        atoms.get_potential_energy()
        reference = atoms.copy()
        reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
        assert_same(atoms, reference)
        rng = np.random.default_rng(0)
        atoms.positions += rng.normal(scale=0.05, size=atoms.positions.shape)
        assert_same(atoms, reference)
        atoms.set_cell(atoms.cell * 1.01, scale_atoms=True)
        assert_same(atoms, reference)
        cell = atoms.cell.array.copy()
        cell[1, 0] += 0.6
        cell[2, 1] -= 0.4
        atoms.set_cell(cell, scale_atoms=True)
        assert_same(atoms, reference)
        assert abs(atoms.get_stress()[3]) > 1e-5  # a shear stress to compare
        atoms.set_cell(atoms.cell * 0.995, scale_atoms=True)
        assert_same(atoms, reference)
        log = engine.log
        assert log.exists()
    assert not log.exists()  # close() removes the engine's temporary folder


def test_a_rotated_triclinic_cell_and_two_ranks():
    """A general (rotated, tilted) cell on 2 MPI ranks: rotated into LAMMPS's frame."""
    atoms = water_box_27()
    cell = atoms.cell.array.copy()
    cell[1, 0], cell[2, 0] = 0.5, -0.3
    atoms.set_cell(cell, scale_atoms=True)
    rotation = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
    rotation *= np.sign(np.linalg.det(rotation))
    atoms.set_cell(atoms.cell.array @ rotation.T)
    atoms.positions = atoms.positions @ rotation.T
    with LAMMPSEngine(PPPM_27, processes=2) as engine:
        atoms.calc = engine
        atoms.get_potential_energy()
        reference = atoms.copy()
        reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
        assert_same(atoms, reference)
        atoms.set_cell(atoms.cell * 1.003, scale_atoms=True)
        assert_same(atoms, reference)


def test_a_tilt_past_half_a_box_is_reduced_and_a_flip_keeps_the_engine():
    """LAMMPS keeps |xy| <= lx/2 (its minimum image assumes it): a barostat's cell may
    go further.  The engine gets the same lattice in the reduced basis (equal, to
    roundoff, to LAMMPSCalculator given that basis); when the basis flips, as native
    LAMMPS re-neighbours, fix rigidmd/ipi re-maps the atoms in the running engine (fix
    ipi, the fall-back, cannot: a new engine starts).  (Without it a 64-water triclinic
    RigidNPT run, its cell sheared far, stopped with LAMMPS's "Out of range atoms -
    cannot compute PPPM_27".)"""
    atoms = water_box_27()
    length = atoms.cell[0, 0]
    with LAMMPSEngine(PPPM_27) as engine:
        atoms.calc = engine
        for xy, flips in ((0.45, 0), (0.55, 1), (1.3, 1)):
            cell = atoms.cell.array.copy()
            cell[1, 0] = xy * length
            atoms.set_cell(cell, scale_atoms=True)
            atoms.get_potential_energy()
            if xy == 0.45:
                first = engine.pid
                reference = atoms.copy()
                reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
            else:
                # the basis flipped: the same engine with fix rigidmd/ipi
                assert (engine.pid == first) == (engine.engine_fix == "rigidmd/ipi")
            reduced = atoms.copy()
            reduced_cell = cell.copy()
            reduced_cell[1] -= flips * cell[0]
            reduced.set_cell(reduced_cell)
            reduced.calc = reference.calc
            assert atoms.get_potential_energy() == pytest.approx(
                reduced.get_potential_energy(), rel=1e-13)
            np.testing.assert_allclose(atoms.get_forces(), reduced.get_forces(), atol=1e-12)
            stress = reduced.get_stress()
            np.testing.assert_allclose(atoms.get_stress(), stress,
                                       atol=1e-12 * np.abs(stress).max())


def test_virial_lower_triangle_is_mirrored():
    """fix ipi sends xy, xz, yz only; a full virial (ASE's client) is symmetrised."""
    from rigidmd.ipi import symmetric_virial

    upper = np.array([[1.0, 2.0, 3.0], [0.0, 4.0, 5.0], [0.0, 0.0, 6.0]])
    full = np.array([[1.0, 2.0, 3.0], [2.0, 4.0, 5.0], [3.0, 5.0, 6.0]])
    np.testing.assert_array_equal(symmetric_virial(upper), full)
    np.testing.assert_array_equal(symmetric_virial(upper.T), full)
    np.testing.assert_array_equal(symmetric_virial(full), full)


def test_a_dead_engine_raises_naming_its_log_and_the_step_is_undone():
    atoms = water_box_27()
    rigid_maxwell_boltzmann(atoms, 300, bodies="tags", rng=np.random.default_rng(2))
    engine = LAMMPSEngine(PPPM_27, timeout=30)
    atoms.calc = engine
    dyn = RigidVerlet(atoms, units.fs, bodies="tags")
    dyn.run(2)
    before = atoms.positions.copy(), atoms.get_momenta().copy()
    lmp = [p for p in descendants(os.getpid()) if p in processes_named("lmp")]
    assert len(lmp) == 1
    os.kill(lmp[0], signal.SIGKILL)
    start = time.monotonic()
    with pytest.raises(EngineError, match=r"closed the connection.*log.lammps") as err:
        dyn.run(1)
    assert time.monotonic() - start < 10
    log = Path(str(err.value).rsplit(" ", 1)[-1])
    assert log.exists()  # kept, to be read
    np.testing.assert_array_equal(atoms.positions, before[0])
    np.testing.assert_array_equal(atoms.get_momenta(), before[1])
    dyn.run(1)  # a fresh engine takes over
    assert dyn.nsteps == 3
    engine.close()


def test_a_hung_engine_raises_within_the_timeout():
    atoms = water_box_27()
    with LAMMPSEngine(PPPM_27, timeout=2, connect_timeout=60) as engine:
        atoms.calc = engine
        atoms.get_potential_energy()
        lmp = [p for p in descendants(os.getpid()) if p in processes_named("lmp")]
        os.kill(lmp[0], signal.SIGSTOP)
        atoms.positions[0] += 0.01
        start = time.monotonic()
        with pytest.raises(EngineError, match=r"no forces within 2 s.*log.lammps"):
            atoms.get_forces()
        assert time.monotonic() - start < 10  # 2 s, then the engine is killed
        assert not any(p in processes_named("lmp") for p in lmp)  # killed, even stopped


@pytest.mark.slow
@pytest.mark.parametrize("processes", [1, 2])
def test_sigkill_of_its_python_leaves_no_engine(tmp_path, processes):
    script = tmp_path / "run.py"
    script.write_text(textwrap.dedent(f"""
        import sys
        from ase.io import read
        from rigidmd.lammps import tip3p_charges
        from rigidmd.lammps.engine import LAMMPSEngine
        atoms = read({str(DATA / "water_box_27.traj")!r})
        atoms.set_initial_charges(tip3p_charges(atoms))
        atoms.calc = LAMMPSEngine({PPPM_27!r}, processes={processes})
        atoms.get_forces()
        print("ready", flush=True)
        sys.stdin.read()
    """))
    proc = subprocess.Popen([sys.executable, str(script)], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        engine = descendants(proc.pid)
        ranks = [p for p in engine if p in processes_named("lmp")]
        assert len(ranks) == processes
        for rank in ranks:  # busy ranks: they would never notice the socket closing
            os.kill(rank, signal.SIGSTOP)
        proc.kill()
        proc.wait()
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and any(
                os.path.exists(f"/proc/{p}") and p in processes_named(name)
                for p in engine for name in ("lmp", "mpirun", "mpiexec.hydra",
                                             "hydra_pmi_proxy")):
            time.sleep(0.2)
        left = [p for p in engine for name in ("lmp", "mpirun", "mpiexec.hydra",
                                               "hydra_pmi_proxy", "python")
                if p in processes_named(name)]
        assert not left, f"processes left: {left}"
        # A process killed outright cannot remove its socket file; the next calculator's
        # sweep does (here called directly, as IPICalculator does before it listens).
        stale = glob.glob(f"/tmp/ipi_rigidmd-{proc.pid}-*")
        assert len(stale) == 1, stale
        assert stale[0] in sweep_stale_sockets()
        assert not os.path.lexists(stale[0])
    finally:
        if proc.poll() is None:
            proc.kill()


@pytest.mark.parametrize("couple", ["iso", "aniso", "tri"])
def test_npt_through_the_engine_follows_the_in_process_calculator(couple):
    """RigidNPT (MTK): the cell moves every step (under "tri" its six components, so the
    shear stresses matter, and the cell leaves LAMMPS's lower-triangular form); 20 steps
    through both calculators with the same k-space parameters agree to roundoff growth
    (measured: iso and aniso cells equal, positions 2e-15 Å; tri cells 2e-14 Å,
    positions 3e-14 Å; bound 1e-12 Å)."""
    atoms = water_box_27()
    rigid_maxwell_boltzmann(atoms, 300, bodies="tags", rng=np.random.default_rng(3))
    runs = []
    with LAMMPSEngine(PPPM_27) as engine:
        for calc in (engine, None):
            a = atoms.copy()
            a.calc = calc if calc is not None else LAMMPSCalculator(
                PPPM_27 + [engine.kspace_parameters])
            dyn = RigidNPT(a, units.fs, 300, 1.01325 * units.bar, 50 * units.fs,
                           200 * units.fs, bodies="tags", couple=couple)
            dyn.run(20)
            runs.append((a.positions.copy(), a.cell.array.copy()))
    moved = np.abs(runs[0][1] - atoms.cell.array)
    assert moved.max() > 1e-3
    if couple == "tri":
        assert moved[~np.eye(3, dtype=bool)].max() > 1e-4  # the cell tilts
    np.testing.assert_allclose(runs[0][1], runs[1][1], rtol=0, atol=1e-12)
    np.testing.assert_allclose(runs[0][0], runs[1][0], rtol=0, atol=1e-12)


ASE_CLIENT = """
import sys
from ase.calculators.socketio import SocketClient
from ase.calculators.tip3p import TIP3P
from ase.io import read
atoms = read(sys.argv[1])
atoms.calc = TIP3P(rc=4.5)
SocketClient(unixsocket=sys.argv[2]).run(atoms, use_stress=False)
"""


@pytest.mark.slow
def test_an_ase_calculator_in_ases_socket_client_gives_the_same_trajectory(tmp_path):
    """Any i-PI engine: ASE's TIP3P in ASE's SocketClient, in a subprocess.

    20 steps of 27 periodic waters; positions and forces cross the socket in Bohr
    and Hartree and back: measured 1.8e-15 Å and 4e-16 Å/ASE-time from the
    in-process run (bound 1e-13)."""
    atoms = water_box_27()
    rigid_maxwell_boltzmann(atoms, 300, bodies="tags", rng=np.random.default_rng(4))
    atoms.write(tmp_path / "start.traj")
    (tmp_path / "client.py").write_text(ASE_CLIENT)
    name = f"rigidmd-test-{os.getpid()}"
    from ase.calculators.tip3p import TIP3P

    local = atoms.copy()
    local.calc = TIP3P(rc=4.5)
    RigidVerlet(local, units.fs, bodies="tags").run(20)
    with IPICalculator(unixsocket=name, timeout=30) as calc:
        remote = atoms.copy()
        remote.calc = calc
        client = None
        try:
            calc.listen()
            client = subprocess.Popen([sys.executable, str(tmp_path / "client.py"),
                                       str(tmp_path / "start.traj"), name])
            RigidVerlet(remote, units.fs, bodies="tags").run(20)
        finally:
            calc.close()
            if client is not None:
                client.wait(timeout=10)
    np.testing.assert_allclose(remote.positions, local.positions, rtol=0, atol=1e-13)
    np.testing.assert_allclose(remote.get_velocities(), local.get_velocities(), rtol=0,
                               atol=1e-13)


RUN = """
structure: {builtin: water_box, n_side: 3}
bodies: mol-id
calculator: {name: lammps, water_model: {name: tip3p, cutoff: 4.5, kspace: pppm},
             processes: PROCESSES}
thermostat: {kind: nose_hoover, temperature: 300 K, tdamp: 50 fs}
barostat: {kind: mtk, pressure: 1 atm, pdamp: 200 fs}
velocities: {temperature: 300 K, seed: 1}
timestep: 1 fs
steps: 60
outputs: {directory: out, trajectory: md.traj, log: md.log, interval: 10,
          checkpoint_interval: 10}
"""


def start_run(path, processes, *args):
    return start_cli_run(path, RUN.replace("PROCESSES", str(processes)), *args)


@pytest.mark.slow
def test_rigidmd_run_with_an_engine_stops_on_sigterm_and_resumes(tmp_path):
    """``processes: 2``: SIGTERM checkpoints and stops the engine; --resume continues
    (on 1 process: where the forces run is not part of the run's identity).

    NPT (MTK): the checkpoint carries the engine's k-space parameters; the resumed
    engine builds its neighbour lists at other steps, so the forces differ in the last
    bits: after 60 steps the positions measured 9e-15 Å and the cell 5e-15 Å from the
    run left alone (bound 1e-12 Å)."""
    plain = start_run(tmp_path / "plain", 2)
    _, stderr = plain.communicate(timeout=600)
    assert plain.returncode == 0, stderr
    proc = start_run(tmp_path / "stopped", 2)
    log = tmp_path / "stopped" / "out" / "md.log"
    deadline = time.monotonic() + 300
    while not (log.exists() and len(log.read_text().splitlines()) > 3):
        assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
        time.sleep(0.05)
    engine = [p for p in descendants(proc.pid) if p in processes_named("lmp")]
    assert len(engine) == 2
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 143, stderr
    assert "--resume" in stdout
    time.sleep(1.0)  # the watchdog's SIGTERM, then SIGKILL, 0.5 s apart
    assert not [p for p in engine if p in processes_named("lmp")]
    resumed = start_run(tmp_path / "stopped", 1, "--resume")  # processes may change
    _, stderr = resumed.communicate(timeout=600)
    assert resumed.returncode == 0, stderr
    ours = read(tmp_path / "stopped" / "out" / "md.traj", ":")
    theirs = read(tmp_path / "plain" / "out" / "md.traj", ":")
    assert len(ours) == len(theirs) == 7
    np.testing.assert_allclose(ours[-1].cell.array, theirs[-1].cell.array, rtol=0, atol=1e-12)
    np.testing.assert_allclose(ours[-1].positions, theirs[-1].positions, rtol=0, atol=1e-12)


def test_threads_in_one_process_and_in_the_engine(tmp_path):
    """``threads=2``: LAMMPS's OpenMP styles, the same numbers (other summation order:
    measured 1.7e-13 eV, forces 3e-16 eV/Å, stress 2e-15 relative)."""
    atoms = water_box_27()
    plain = LAMMPSCalculator(PPPM_27)
    threaded = LAMMPSCalculator(PPPM_27, threads=2)
    assert threaded.cmdargs[-5:] == ["-sf", "omp", "-pk", "omp", "2"]
    energy = plain.get_potential_energy(atoms)
    assert threaded.get_potential_energy(atoms) == pytest.approx(energy, rel=1e-13)
    np.testing.assert_allclose(threaded.get_forces(atoms), plain.get_forces(atoms), atol=1e-13)
    stress = plain.get_stress(atoms)
    np.testing.assert_allclose(threaded.get_stress(atoms), stress,
                               atol=1e-13 * np.abs(stress).max())
    with LAMMPSEngine(PPPM_27, threads=2, workdir=tmp_path) as engine:
        assert engine.get_potential_energy(atoms) == pytest.approx(energy, rel=1e-13)
        log = (tmp_path / "log.lammps").read_text()
        assert "using 2 OpenMP thread(s) per MPI task" in log
        assert "pair lj/cut/coul/long/omp" in log
    for bad in (0, 1.5, True):
        with pytest.raises(ValueError, match="threads must be a positive whole number"):
            LAMMPSCalculator(PPPM_27, threads=bad)
        with pytest.raises(ValueError, match="threads must be a positive whole number"):
            LAMMPSEngine(PPPM_27, threads=bad)


@pytest.mark.slow
def test_rigidmd_run_with_an_engine_started_elsewhere(tmp_path):
    """``address: unix:NAME``: the input is written to out/engine; lmp started there
    connects and the run completes."""
    from rigidmd.lammps.engine import lammps_executable

    name = f"rigidmd-cli-{os.getpid()}"
    path = tmp_path / "elsewhere"
    path.mkdir()
    (path / "run.yaml").write_text(RUN.replace("processes: PROCESSES", f"address: unix:{name}")
                                   .replace("steps: 60", "steps: 20"))
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "rigidmd.run.cli", "run", "run.yaml"], cwd=path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    engine = None
    try:
        deck = path / "out" / "engine" / "in.engine"
        deadline = time.monotonic() + 120
        while not deck.exists():
            assert proc.poll() is None and time.monotonic() < deadline, proc.stderr.read()
            time.sleep(0.05)
        time.sleep(0.2)
        assert f"fix rmd_ipi all rigidmd/ipi {name} 0 unix" in deck.read_text()
        lmp, lmp_env = lammps_executable()
        engine = subprocess.Popen([str(lmp), "-in", "in.engine", "-screen", "none"],
                                  cwd=deck.parent, env=lmp_env)
        stdout, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 0, stderr
        assert "waiting for an engine" in stderr
        assert len(read(path / "out" / "md.traj", ":")) == 3
    finally:
        for p in (proc, engine):
            if p is not None and p.poll() is None:
                p.kill()
        if engine is not None:
            engine.wait(timeout=30)  # EXIT at the end of the run: LAMMPS leaves
