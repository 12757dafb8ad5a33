"""BAOAB against RigidLangevin at 1, 2, 4 fs: configurational and kinetic temperatures, exactly.

128 rigid water-shaped tops (TIP3P's geometry) whose atoms are tethered to fixed
points by springs proportional to their masses: the centres of mass are harmonic
oscillators of frequency omega = 0.125 / fs and the rotations nearly so, so the
exact <U> is known (3/2 kT per body for the translation, a quadrature over the
rotation group for the rotation; tests/couplings/test_baoab.py checks both schemes at
omega dt = 0.5).  Friction 1 / (50 fs), 2 ps of equilibration, 16 ps per point,
errors from 10 blocks.  T_conf is T <U> / <U>_exact.  Writes
baoab_tethered_tops.txt; run with ``python validation/baoab_tethered_tops.py``
(about 10 minutes on one core).
"""

from pathlib import Path

import numpy as np
from ase import Atoms, units
from ase.calculators.calculator import Calculator, all_changes

from rigidmd import RigidLangevin, RigidLangevinBAOAB

T, N, OMEGA = 300.0, 128, 0.125 / units.fs


class Tethers(Calculator):
    """Each atom pulled to its anchor by a spring of stiffness ``k`` times its mass."""

    implemented_properties = ("energy", "forces")

    def __init__(self, anchors, masses, k):
        super().__init__()
        self.anchors, self.km = anchors, k * masses[:, None]

    def calculate(self, atoms=None, properties=("energy",), system_changes=all_changes):
        super().calculate(atoms, properties, system_changes)
        d = self.atoms.positions - self.anchors
        self.results = {"energy": 0.5 * float(np.sum(self.km * d * d)), "forces": -self.km * d}


def tethered_tops(n, omega):
    """``n`` rigid waters (TIP3P's geometry) far apart, tethered at frequency ``omega``."""
    water = np.array([[0.0, 0, 0], [0.7570, 0.5859, 0], [-0.7570, 0.5859, 0]])
    atoms = Atoms("OH2" * n, positions=np.concatenate([water + [5.0 * i, 0, 0]
                                                       for i in range(n)]))
    k = omega**2
    atoms.calc = Tethers(atoms.positions.copy(), atoms.get_masses(), k)
    return atoms, k, [[3 * i, 3 * i + 1, 3 * i + 2] for i in range(n)]


def exact_rotational_energy(moments, k, kT):
    r""":math:`\langle k(1-\cos\theta)\,n^\mathsf{T}In\rangle` over the Haar measure
    :math:`\sin^2(\theta/2)\,d\theta\,d^2n`, by quadrature (converged to 1e-6)."""
    theta = np.linspace(0.0, np.pi, 2001)
    x, wx = np.polynomial.legendre.leggauss(96)
    phi = np.linspace(0.0, 2 * np.pi, 193)[:-1]
    sin = np.sqrt(1 - x[:, None] ** 2)
    nIn = (moments[0] * (sin * np.cos(phi)) ** 2 + moments[1] * (sin * np.sin(phi)) ** 2
           + moments[2] * x[:, None] ** 2)
    U = k * (1 - np.cos(theta))[:, None, None] * nIn
    weight = np.exp(-U / kT) * (np.sin(theta / 2) ** 2)[:, None, None] * wx[:, None]
    return float(np.trapezoid((U * weight).sum((1, 2)), theta)
                 / np.trapezoid(weight.sum((1, 2)), theta))


def block_mean(values, n=10):
    blocks = np.array([b.mean() for b in np.array_split(np.asarray(values), n)])
    return blocks.mean(), blocks.std(ddof=1) / np.sqrt(n)


def point(cls, fs):
    dt, kT, k = fs * units.fs, units.kB * T, OMEGA**2
    atoms, _, bodies = tethered_tops(N, OMEGA)
    dyn = cls(atoms, dt, T, 1.0 / (50 * units.fs), rng=np.random.default_rng(7), fixcm=False,
              bodies=bodies)
    anchors, M = dyn.state.X.copy(), dyn.model.mass
    rows = []

    def record():
        if dyn.nsteps < int(2000 / fs):
            return
        U = 0.5 * float(np.sum(atoms.calc.km * (atoms.positions - atoms.calc.anchors) ** 2))
        U_tr = 0.5 * k * float(M @ ((dyn.state.X - anchors) ** 2).sum(1))
        end = (dyn.get_translational_kinetic_energy(), dyn.get_rotational_kinetic_energy())
        rows.append((U_tr, U - U_tr, *dyn.get_kinetic_temperatures(),
                     *(2 * K / (3 * N * units.kB) for K in end)))

    record.modifies_atoms = record.wants_properties = False
    dyn.attach(record, interval=max(1, 4 // fs))
    dyn.run(int(18000 / fs))
    rows = np.array(rows)
    exact = (1.5 * N * kT, N * exact_rotational_energy(dyn.model.moments[0], k, kT))
    out = []
    for c in range(6):
        mean, error = block_mean(rows[:, c])
        scale = T / exact[c] if c < 2 else 1.0
        out.append(f"{mean * scale:6.1f} ± {error * scale:3.1f}")
    return out


def main():
    lines = ["dt  integrator          T_conf,tr     T_conf,rot    T_tr (logged) T_rot (logged)"
             " T_tr (end)    T_rot (end)   [K; bath 300 K]"]
    for fs in (1, 2, 4):
        for cls in (RigidLangevinBAOAB, RigidLangevin):
            lines.append(f"{fs} fs {cls.__name__:19s} " + " ".join(point(cls, fs)))
            print(lines[-1], flush=True)
    Path(__file__).with_suffix(".txt").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
