"""Rigid water under a trained ML potential (CHGNet 0.3.0): energy conservation and payoff.

The same cluster of waters (CHGNet's own water geometry, from
:func:`rigidmd.relax.relax_bodies`; rigid 300 K velocities from
:func:`rigidmd.rigid_maxwell_boltzmann`) is run in NVE for ``--ps`` each

* rigid, rigidmd's ``RigidVerlet`` (NO_SQUISH) at 0.25, 0.5, 1 and 2 fs;
* rigid, ASE's route: ``FixBondLengths`` on O-H, O-H and H-H (RATTLE) with
  ASE's ``VelocityVerlet``, from the same positions and velocities, same steps;
* flexible, ASE's ``VelocityVerlet`` at 0.25 and 0.5 fs (every atom free,
  Maxwell-Boltzmann at 300 K);

with CHGNet in float32 (as it ships) and in float64, with a diagnostic
variant of the model whose angle features are smooth at 180°
(:func:`smooth_angle_encoder`), and with ASE's TIP3P as a smooth control.
Per run: the conserved energy's peak-to-peak span over every step, its RMS
about a straight-line fit, the fit's slope (drift), the RMS of its change
over one step and that change's correlation with the next step's (near +1
when the step resolves the forces' variation), the characteristic frequency
of the waters' net forces and torques (:func:`force_frequency`), force calls
per ps and, for rigidmd, its own time per step (wall time less the time in
the force call).

Then the model's smoothness: forces against central differences of the
energy at a thermal configuration (float32 and float64); the energy along a
path that takes a water dimer's O-H...O through the straight line; the
energy as one water turns rigidly by ±0.01 rad (CHGNet against TIP3P); and
rigidmd over 10 fs at steps down to 1/32 fs.

Needs CHGNet and a CPU PyTorch, in their own environment (not the test
extra)::

    python -m venv --system-site-packages venv-chgnet
    venv-chgnet/bin/pip install -e ".[chgnet]" torch==2.13.0
    OMP_NUM_THREADS=1 venv-chgnet/bin/python benchmarks/ml_potential.py [--molecules 8] [--ps 0.2]
        [--runs VARIANT/ROUTE ...] [--no-smoothness] [--quick] [--output FILE]

The results are printed; ``--output FILE`` also writes them there (the recorded run is
``benchmarks/ml_potential.txt``, written over only when named).  The runs are
deterministic, so ``--runs`` can split them over processes run side by side, each with its
own ``--output``.
"""

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from ase import units  # noqa: E402
from ase.calculators.calculator import Calculator, all_changes  # noqa: E402
from ase.calculators.tip3p import TIP3P  # noqa: E402
from ase.constraints import FixBondLengths  # noqa: E402
from ase.md.velocitydistribution import MaxwellBoltzmannDistribution, Stationary  # noqa: E402
from ase.md.verlet import VelocityVerlet  # noqa: E402
from chgnet.graph import converter as chgnet_converter  # noqa: E402
from chgnet.model import CHGNet  # noqa: E402
from chgnet.model import model as chgnet_model  # noqa: E402
from pymatgen.core import Lattice, Structure  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402

from rigidmd import RigidVerlet, kinetic_energy, rigid_maxwell_boltzmann  # noqa: E402
from rigidmd.relax import relax_bodies  # noqa: E402
from rigidmd.systems import water_cluster  # noqa: E402

torch.set_num_threads(1)
DTYPES = {"float32": torch.float32, "float64": torch.float64}


def smooth_angle_encoder(encoder, width=0.05):
    r"""Replace CHGNet's angle features by ones smooth at 0 and 180° (diagnostic only).

    CHGNet expands the angle :math:`\theta = \arccos(\hat b_i\cdot\hat b_j)`
    between two bonds of an atom in :math:`\sin n\theta` and :math:`\cos n\theta`.
    :math:`\sin\theta = \sqrt{1-c^2}` is a cone in the atoms' coordinates at
    :math:`\theta = \pi`: the energy has a cusp, the force a jump, wherever
    three atoms pass through a straight line (an O-H...O hydrogen bond does).
    Here :math:`\theta` is replaced by :math:`\operatorname{atan2}(s^2/\sqrt{s^2+w^2},
    c)` with :math:`s^2 = 1-c^2`, which differs from it only within about ``width``
    rad of 0 and π and is smooth there.  A different model, used only to show
    what the cusp does to the dynamics.
    """
    fourier = encoder.fourier_expansion

    def forward(bond_i, bond_j):
        cosine = torch.sum(bond_i * bond_j, dim=1)
        s2 = torch.clamp(1 - cosine**2, min=0)
        return fourier(torch.atan2(s2 / torch.sqrt(s2 + width**2), cosine))

    encoder.forward = forward


def load_chgnet(dtype="float32", smooth=False):
    """CHGNet 0.3.0 (the weights in the wheel), in ``dtype``; see :class:`CHGNetCluster`."""
    model = CHGNet.load(verbose=False)
    if dtype == "float64":
        model = model.to(torch.float64)
        assemble = model.composition_model._assemble_graphs  # casts to float32 itself
        model.composition_model._assemble_graphs = lambda graphs: assemble(graphs).double()
    if smooth:
        smooth_angle_encoder(model.angle_basis_expansion)
    return model


class CHGNetCluster(Calculator):
    """CHGNet on a cluster: the atoms centred in a cubic box of ``box`` Å (CHGNet is periodic).

    Energy and forces only (``task="ef"``; no stress, no magnetic moments).
    CHGNet builds its graph in a module-level dtype (float32); it is set to
    the model's own for each call, so float32 and float64 models can live in
    one process.
    """

    implemented_properties = ["energy", "forces"]

    def __init__(self, model, dtype="float32", box=30.0):
        super().__init__()
        self.model, self.dtype, self.box = model, dtype, box

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        dtype = DTYPES[self.dtype]
        chgnet_converter.TORCH_DTYPE = chgnet_model.TORCH_DTYPE = dtype
        default = torch.get_default_dtype()
        torch.set_default_dtype(dtype)
        try:
            positions = self.atoms.positions - self.atoms.positions.mean(axis=0) + self.box / 2
            structure = Structure(Lattice.cubic(self.box), self.atoms.get_chemical_symbols(),
                                  positions, coords_are_cartesian=True)
            graph = self.model.graph_converter(structure)
            result = self.model.predict_graph(graph, task="ef")
        finally:
            torch.set_default_dtype(default)
            chgnet_converter.TORCH_DTYPE = chgnet_model.TORCH_DTYPE = torch.float32
        scale = len(self.atoms) if self.model.is_intensive else 1
        self.results = {"energy": float(result["e"]) * scale,
                        "forces": np.asarray(result["f"], dtype=float)}


def start_state(n, seed=3):
    """Waters in CHGNet's (float64) water geometry with rigid 300 K velocities."""
    relaxed = relax_bodies(water_cluster(n, seed=seed),
                           CHGNetCluster(load_chgnet("float64"), "float64"))
    atoms = relaxed.atoms
    rigid_maxwell_boltzmann(atoms, 300, rng=np.random.default_rng(7))
    return atoms, relaxed.templates["OHH"]


def water_pairs(n):
    """O-H, O-H and H-H of every water (atoms O, H, H in order)."""
    return [(3 * i + a, 3 * i + b) for i in range(n) for a, b in ((0, 1), (0, 2), (1, 2))]


def counted(calc):
    """``calc`` with ``calls`` and ``seconds``: how often, and how long, it computed."""
    calc.calls, calc.seconds = 0, 0.0
    compute = calc.calculate

    def calculate(*args, **kwargs):
        begin = time.perf_counter()
        compute(*args, **kwargs)
        calc.seconds += time.perf_counter() - begin
        calc.calls += 1

    calc.calculate = calculate
    return calc


def run(start, route, dt_fs, ps, calculator):
    """One NVE run from ``start`` with a fresh ``calculator()``; the conserved energy every step."""
    atoms = start.copy()
    atoms.calc = calc = counted(calculator())
    if route == "rigidmd":
        dyn = RigidVerlet(atoms, dt_fs * units.fs)
    else:
        if route == "RATTLE":
            atoms.set_constraint(FixBondLengths(water_pairs(len(atoms) // 3)))
        else:  # flexible
            MaxwellBoltzmannDistribution(atoms, temperature_K=300,
                                         rng=np.random.default_rng(7))
            Stationary(atoms)
        dyn = VelocityVerlet(atoms, dt_fs * units.fs)
    energies, generalized = [], []

    def record():
        energies.append(atoms.get_potential_energy() + kinetic_energy(atoms))
        generalized.append(body_forces(atoms))

    record()
    dyn.attach(record)
    steps = int(round(ps * 1000 / dt_fs))
    calls, inside = calc.calls, calc.seconds
    begin = time.perf_counter()
    dyn.run(steps)
    wall = time.perf_counter() - begin
    energies = np.array(energies)
    t = np.arange(len(energies)) * dt_fs / 1000
    fit = np.polyfit(t, energies, 1)
    change = np.diff(energies)
    force, torque = (force_frequency(np.array([g[i] for g in generalized]), dt_fs)
                     for i in (0, 1))
    return {"span": np.ptp(energies), "rms": np.std(energies - np.polyval(fit, t)),
            "drift": fit[0], "step_rms": np.sqrt(np.mean(change**2)),
            "step_corr": np.corrcoef(change[:-1], change[1:])[0, 1],
            "nu_force": force, "nu_torque": torque,
            "calls_per_ps": (calc.calls - calls) / ps,
            "own_ms": 1e3 * (wall - (calc.seconds - inside)) / steps,
            "call_ms": 1e3 * (calc.seconds - inside) / (calc.calls - calls),
            "energies": energies}


def body_forces(atoms):
    """Net force (eV/Å) and torque about the centre of mass (eV) of every water, (n, 3) each."""
    x = atoms.positions.reshape(-1, 3, 3)
    f = atoms.get_forces(apply_constraint=False).reshape(-1, 3, 3)
    m = atoms.get_masses().reshape(-1, 3, 1)
    centre = (m * x).sum(axis=1, keepdims=True) / m.sum(axis=1, keepdims=True)
    return f.sum(axis=1), np.cross(x - centre, f).sum(axis=1)


def force_frequency(series, dt_fs):
    r"""Characteristic frequency of a force time series (cm⁻¹).

    :math:`\nu = \frac{1}{2\pi c}\sqrt{\langle|\dot G|^2\rangle /
    \langle|G - \bar G|^2\rangle}`, :math:`\dot G` by differences over one
    step; for a harmonic force it is the oscillator's frequency.  Only
    resolved where the step is short against it (0.25 fs: up to ~10⁴ cm⁻¹).
    """
    rate = np.diff(series, axis=0) / dt_fs
    spread = series - series.mean(axis=0)
    omega = np.sqrt(np.mean(rate**2) / np.mean(spread**2))  # rad / fs
    return omega / (2 * np.pi * 2.99792458e-5)


def warm_up(start):
    """One rigid step on zero forces: numba's compilation out of every timing."""

    class Zero(Calculator):
        implemented_properties = ["energy", "forces"]

        def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
            super().calculate(atoms, properties, system_changes)
            self.results = {"energy": 0.0, "forces": np.zeros((len(self.atoms), 3))}

    atoms = start.copy()
    atoms.calc = Zero()
    RigidVerlet(atoms, units.fs).run(2)


def conservation(start, ps, lines, variants):
    """Every run of every variant; a table row each, the results by (variant, route, step)."""
    warm_up(start)
    lines += ["| model | route | step (fs) | span (eV) | RMS (eV) | drift (eV/ps) | "
              "per-step change, RMS (eV) | its step-to-step correlation | "
              "ν(net force) (cm⁻¹) | ν(torque) (cm⁻¹) | force calls / ps | ms / call | "
              "rigidmd's own ms / step |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    results = {}
    for name, calculator, routes in variants:
        for route, dt in routes:
            r = run(start, route, dt, ps, calculator)
            own = f"{r['own_ms']:.2f}" if route == "rigidmd" else "-"
            lines.append(f"| {name} | {route} | {dt:g} | {r['span']:.2e} | {r['rms']:.2e} | "
                         f"{r['drift']:+.2e} | {r['step_rms']:.1e} | {r['step_corr']:+.2f} | "
                         f"{r['nu_force']:.0f} | {r['nu_torque']:.0f} | "
                         f"{r['calls_per_ps']:.0f} | {r['call_ms']:.1f} | {own} |")
            print(lines[-1], flush=True)
            results[(name, route, dt)] = r
    return results


def finite_differences(atoms, lines):
    """Model forces against -dE/dx by central differences, every coordinate."""
    lines += ["| model | h (Å) | max abs(F - F_fd) (eV/Å) | RMS (eV/Å) | max abs(F) (eV/Å) |",
              "|---|---|---|---|---|"]
    for dtype, h in (("float32", 1e-2), ("float32", 1e-3), ("float64", 1e-3),
                     ("float64", 1e-4)):
        calc = CHGNetCluster(load_chgnet(dtype), dtype)
        a = atoms.copy()
        a.calc = calc
        forces = a.get_forces()
        fd = np.zeros_like(forces)
        for i in range(len(a)):
            for k in range(3):
                e = []
                for sign in (1, -1):
                    b = atoms.copy()
                    b.calc = calc
                    b.positions[i, k] += sign * h
                    e.append(b.get_potential_energy())
                fd[i, k] = -(e[0] - e[1]) / (2 * h)
        err = forces - fd
        lines.append(f"| {dtype} | {h:g} | {np.abs(err).max():.1e} | "
                     f"{np.sqrt(np.mean(err**2)):.1e} | {np.abs(forces).max():.2f} |")
        print(lines[-1], flush=True)


def rotation_scan(start, lines, molecules=(0, 5), half_width=0.01, points=41):
    r"""Energy as one water of ``start`` turns rigidly about its centre of mass, CHGNet and TIP3P.

    Its curvature :math:`d^2E/d\varphi^2` (eV/rad²) from the torques' differences,
    for angles :math:`\varphi` of ±``half_width`` rad about one random axis;
    and the largest mismatch between the energy's change and the trapezoid rule
    on the torque (is the torque the energy's derivative?).
    """
    axis = np.random.default_rng(1).normal(size=3)
    axis /= np.linalg.norm(axis)
    angles = np.linspace(-half_width, half_width, points)
    h = angles[1] - angles[0]
    lines += ["| water | model | energy range (meV) | min and max of d²E/dφ² (eV/rad²) | "
              "d²E/dφ² every 0.002 rad (eV/rad²) | worst trapezoid mismatch (eV) |",
              "|---|---|---|---|---|---|"]
    model = load_chgnet("float64")
    for mol in molecules:
        body = slice(3 * mol, 3 * mol + 3)
        masses = start.get_masses()[body]
        centre = masses @ start.positions[body] / masses.sum()
        for name, calc in (("CHGNet float64", CHGNetCluster(model, "float64")),
                           ("TIP3P", TIP3P(rc=40))):
            energies, torques = [], []
            for phi in angles:
                a = start.copy()
                a.positions[body] = centre + Rotation.from_rotvec(phi * axis).apply(
                    start.positions[body] - centre)
                a.calc = calc
                energies.append(a.get_potential_energy())
                arm = a.positions[body] - centre
                torques.append(np.cross(arm, a.get_forces()[body]).sum(axis=0) @ axis)
            energies, torques = np.array(energies), np.array(torques)
            curvature = -np.diff(torques) / h
            trapezoid = np.diff(energies) + 0.5 * (torques[1:] + torques[:-1]) * h
            lines.append(f"| {mol} | {name} | {1e3 * np.ptp(energies):.3f} | "
                         f"{curvature.min():+.3f}, {curvature.max():+.3f} | "
                         + " ".join(f"{c:+.3f}" for c in curvature[::4]) + " | "
                         f"{np.abs(trapezoid).max():.1e} |")
            print(lines[-1], flush=True)


def small_steps(start, lines, fs=10.0):
    """rigidmd with CHGNet (float64) for ``fs`` femtoseconds at steps down to 1/32 fs."""
    model = load_chgnet("float64")
    lines += ["| step (fs) | span (eV) | per-step change, RMS (eV) | "
              "its step-to-step correlation |", "|---|---|---|---|"]
    for dt in (0.03125, 0.0625, 0.125, 0.25, 0.5):
        r = run(start, "rigidmd", dt, fs / 1000, lambda: CHGNetCluster(model, "float64"))
        lines.append(f"| {dt:g} | {r['span']:.2e} | {r['step_rms']:.2e} | "
                     f"{r['step_corr']:+.2f} |")
        print(lines[-1], flush=True)


def linear_dimer(water, r_hb=1.95):
    """A water dimer whose donor O-H...O is straight; the acceptor's H away from it."""
    donor = water.copy()
    donor.positions -= donor.positions[0]
    axis = donor.positions[1] / np.linalg.norm(donor.positions[1])
    acceptor = water.copy()
    acceptor.positions -= acceptor.positions[0]
    bisector = acceptor.positions[1:].mean(axis=0)
    acceptor.rotate(bisector, axis)  # acceptor's H point away, along the O-H...O line
    acceptor.positions += donor.positions[1] + r_hb * axis
    return donor + acceptor, axis


def cusp(water, lines):
    """Energy and force as the acceptor crosses the donor's O-H line."""
    dimer, axis = linear_dimer(water)
    side = np.cross(axis, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    offsets = np.linspace(-0.02, 0.02, 9)  # Å, about ±0.6° at 1.95 Å
    lines += ["| model | acceptor offset (Å) | E - E(0) (meV) | dE/ds from forces (eV/Å) |",
              "|---|---|---|---|"]
    for name, dtype, smooth in (("float64", "float64", False),
                                ("float64, smooth angles", "float64", True)):
        calc = CHGNetCluster(load_chgnet(dtype, smooth), dtype)
        rows = []
        for s in offsets:
            a = dimer.copy()
            a.positions[3:] += s * side
            a.calc = calc
            rows.append((s, a.get_potential_energy(), -np.dot(a.get_forces()[3:].sum(0), side)))
        e0 = rows[len(rows) // 2][1]
        for s, e, slope in rows:
            lines.append(f"| {name} | {s:+.3f} | {1e3 * (e - e0):+.3f} | {slope:+.4f} |")
        print("\n".join(lines[-len(rows):]), flush=True)


#: Model variants by name: (label in the table, dtype or None for TIP3P, smooth angles).
VARIANTS = {"float32": ("float32", "float32", False), "float64": ("float64", "float64", False),
            "smooth": ("float64, smooth angles", "float64", True),
            "tip3p": ("TIP3P (control)", None, False)}
#: Every run of the default invocation, as variant/route.
ALL_RUNS = ("float32/rigidmd", "float32/RATTLE", "float32/flexible", "float64/rigidmd",
            "smooth/rigidmd", "tip3p/rigidmd", "tip3p/RATTLE")


def model_variants(tokens, quick):
    """``(label, calculator factory, [(route, step)])`` for ``variant/route`` tokens."""
    steps = (1.0, 2.0) if quick else (0.25, 0.5, 1.0, 2.0)
    variants = []
    for name in dict.fromkeys(token.split("/")[0] for token in tokens):
        label, dtype, smooth = VARIANTS[name]
        if dtype is None:
            calculator = lambda: TIP3P(rc=40)  # noqa: E731
        else:
            model = load_chgnet(dtype, smooth)
            calculator = lambda model=model, dtype=dtype: CHGNetCluster(model, dtype)  # noqa: E731
        routes = [(route, dt) for token in tokens if token.split("/")[0] == name
                  for route in [token.split("/")[1]]
                  for dt in (steps[:2] if route == "flexible" else steps)]
        variants.append((label, calculator, routes))
    return variants


def own_time(start, lines, steps=200, rounds=7):
    """rigidmd's own time per step: ``RigidVerlet`` on replayed forces, best of ``rounds``.

    The table's own time is wall time less the time in the force call, so it
    also holds this script's recording every step (energies, net forces and
    torques); this is the integrator's step alone, its force call costing
    nothing (fixed random forces of thermal size).
    """

    class Replay(Calculator):
        implemented_properties = ["energy", "forces"]

        def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
            super().calculate(atoms, properties, system_changes)
            forces = np.random.default_rng(0).normal(scale=0.3, size=(len(self.atoms), 3))
            self.results = {"energy": 0.0, "forces": forces}

    atoms = start.copy()
    atoms.calc = counted(Replay())
    dyn = RigidVerlet(atoms, units.fs)
    dyn.run(2)
    best = np.inf
    for _ in range(rounds):
        begin, inside = time.perf_counter(), atoms.calc.seconds
        dyn.run(steps)
        best = min(best, (time.perf_counter() - begin - (atoms.calc.seconds - inside)) / steps)
    lines.append(f"rigidmd's own time per step ({len(atoms) // 3} waters, RigidVerlet, forces "
                 f"replayed; best of {rounds} x {steps} steps): {1e3 * best:.2f} ms")
    print(lines[-1], flush=True)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--molecules", type=int, default=8)
    p.add_argument("--ps", type=float, default=0.2)
    p.add_argument("--runs", nargs="*", default=list(ALL_RUNS), choices=ALL_RUNS,
                   help="which variant/route runs (default: all)")
    p.add_argument("--no-smoothness", action="store_true",
                   help="leave out the smoothness checks after the runs")
    p.add_argument("--quick", action="store_true",
                   help="0.01 ps, float32, rigidmd and RATTLE at 1 and 2 fs only")
    p.add_argument("--output", type=Path,
                   help="also write the results here (default: printed only)")
    args = p.parse_args(argv)
    ps = 0.01 if args.quick else args.ps
    start, water = start_state(args.molecules)
    lines = [f"# {__doc__.splitlines()[0]}", "",
             f"{args.molecules} waters, CHGNet geometry (O-H {water.get_distance(0, 1):.4f} Å, "
             f"H-O-H {water.get_angle(1, 0, 2):.2f}°), rigid 300 K start "
             f"(kinetic energy {kinetic_energy(start):.3f} eV), {ps:g} ps per run, one thread", ""]
    runs = ["float32/rigidmd", "float32/RATTLE"] if args.quick else args.runs
    results = conservation(start, ps, lines, model_variants(runs, args.quick)) if runs else {}
    if not args.quick:
        lines.append("")
        own_time(start, lines)
    if not (args.quick or args.no_smoothness):
        lines += ["", "Forces against central differences of the energy, the start configuration"]
        finite_differences(start, lines)
        lines += ["", "A water dimer whose O-H...O crosses the straight line (s = 0); "
                  "dE/ds = -(force on the acceptor) along s"]
        cusp(water, lines)
        lines += ["", "One water turned rigidly by ±0.01 rad about its centre of mass "
                  "(the rest of the start configuration fixed)"]
        rotation_scan(start, lines)
        lines += ["", "rigidmd, CHGNet float64, 10 fs from the same start at small steps"]
        small_steps(start, lines)
    text = "\n".join(lines) + "\n"
    if args.output is not None:
        args.output.write_text(text)
    print(text)
    return results


if __name__ == "__main__":
    main()
