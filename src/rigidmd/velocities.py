r"""Thermal velocities for rigid bodies (the rigid analogue of ASE's
:func:`ase.md.velocitydistribution.MaxwellBoltzmannDistribution`)."""

import numpy as np
from ase import units

from rigidmd import operators as ops
from rigidmd import quaternion as quat
from rigidmd.bodies import RigidBodies
from rigidmd.state import RigidState

__all__ = ["rigid_maxwell_boltzmann"]


def rigid_maxwell_boltzmann(atoms, temperature_K, bodies=None, rng=None):
    r"""Give the atoms rigid-body velocities drawn at a temperature.

    Each body gets a centre-of-mass velocity with components drawn from
    :math:`\mathcal N(0, k_B T / M)` and a body-frame angular momentum with
    components :math:`L_{b,k} \sim \mathcal N(0, k_B T I_k)` (none about a
    zero-moment axis); each point particle gets :math:`v \sim \mathcal N(0,
    k_B T/m)`.  Atom momenta are set to :math:`m_i (V + \omega \times r_i)`,
    so they are rigid-consistent: a :class:`~rigidmd.RigidVerlet` started
    from them removes no kinetic energy.

    Parameters
    ----------
    atoms : ase.Atoms
    temperature_K : float
        Temperature (K), non-negative.
    bodies : optional
        Body specification, as for :class:`~rigidmd.RigidVerlet`.
    rng : numpy.random.Generator, optional
        Source of random numbers (``numpy.random.default_rng()`` if omitted).
    """
    if not (np.isfinite(temperature_K) and temperature_K >= 0):
        raise ValueError(f"temperature_K must be finite and >= 0, got {temperature_K!r}")
    rng = np.random.default_rng() if rng is None else rng
    geometry = RigidBodies.resolve(atoms, bodies).geometry(atoms)
    model, q = geometry.model, geometry.quaternions
    kT = units.kB * temperature_K
    nb = model.n_bodies
    V = rng.normal(size=(nb, 3)) * np.sqrt(kT / model.mass)[:, None]
    L_body = rng.normal(size=(nb, 3)) * np.sqrt(kT * model.moments)
    state = RigidState(X=geometry.com, V=V, q=q, p=ops.conjugate_momentum(q, L_body),
                       x=np.zeros((0, 3)), v=np.zeros((0, 3)), cell=atoms.cell.array.copy())
    r = quat.rotate(q[model.atom_body], model.body_coordinates)
    momenta = np.zeros((len(atoms), 3))
    momenta[model.order] = model.atom_masses[:, None] * ops.atom_velocities(state, r, model)
    momenta[model.free] = rng.normal(size=(model.n_free, 3)) * np.sqrt(
        kT * model.free_masses)[:, None]
    atoms.set_momenta(momenta, apply_constraint=False)
