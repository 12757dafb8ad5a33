r"""Thermal velocities for rigid bodies (the rigid analogue of ASE's
:func:`ase.md.velocitydistribution.MaxwellBoltzmannDistribution`), and the
rigid temperature of stored frames."""

import numpy as np
from ase import units

from rigidmd.core import operators as ops
from rigidmd.core import quaternion as quat
from rigidmd.core.bodies import RigidBodies
from rigidmd.core.dof import kinetic_energy
from rigidmd.core.state import RigidState

__all__ = ["rigid_maxwell_boltzmann", "rigid_temperature", "rigid_velocities",
           "rigid_stationary", "rigid_zero_rotation"]


def rigid_maxwell_boltzmann(atoms, temperature_K, bodies=None, rng=None, stationary=False):
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
    stationary : bool, default False
        Then zero the total momentum (:func:`rigid_stationary`) and scale the
        kinetic energy to the drawn temperature counted over the :math:`N_f - 3`
        degrees of freedom left, as LAMMPS's ``velocity create ... mom yes``
        does: the temperature a thermostat holding the momentum (``fixcm``)
        reads.  (Scaling back to the drawn kinetic energy started such a run
        hot by :math:`N_f/(N_f - 3)`: +6.7 % for 8 waters.)  False draws as
        ASE's ``MaxwellBoltzmannDistribution`` does: the
        whole system keeps a thermal drift (about 0.3 Å/ps for 216 waters),
        which a thermostat with ``fixcm=True`` then keeps for the whole run.
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
    if stationary:
        drawn = kinetic_energy(atoms)  # N_f k T' / 2, T' the drawn temperature
        rigid_stationary(atoms, preserve_temperature=False)
        n_f = model.degrees_of_freedom
        if n_f > 3:
            _restore_kinetic_energy(atoms, drawn * (n_f - 3) / n_f)


def rigid_velocities(atoms, bodies=None):
    r"""Velocities of all atoms, massless ones included, from the bodies' rigid motion.

    Each body's centre-of-mass velocity :math:`V` and angular momentum come
    from its atoms' momenta (the projection a rigid dynamics makes); every
    body atom then gets :math:`V + \omega \times r_i`, a massless site (whose
    momentum says nothing, and whose ``atoms.get_velocities()`` is 0/0) as
    well.  Free atoms keep :math:`p/m`.

    Parameters
    ----------
    atoms : ase.Atoms
    bodies : optional
        Body specification, as for :class:`~rigidmd.RigidVerlet`.

    Returns
    -------
    numpy.ndarray, shape (n_atoms, 3)
        Å / ASE time unit.
    """
    geometry = RigidBodies.resolve(atoms, bodies).geometry(atoms)
    model, q = geometry.model, geometry.quaternions
    momenta = atoms.get_momenta()
    state = RigidState(X=geometry.com, V=np.zeros((model.n_bodies, 3)), q=q,
                       p=np.zeros((model.n_bodies, 4)), x=np.zeros((0, 3)), v=np.zeros((0, 3)),
                       cell=atoms.cell.array.copy())
    r, _ = ops.place_atoms(state, model)
    V, L_body = ops.rigid_projection(momenta[model.order], r, q, model)
    state.V, state.p = V, ops.conjugate_momentum(q, L_body)
    velocities = np.zeros((len(atoms), 3))
    velocities[model.order] = ops.atom_velocities(state, r, model)
    velocities[model.free] = momenta[model.free] / model.free_masses[:, None]
    return velocities


def _restore_kinetic_energy(atoms, kinetic0):
    """Scale all momenta so that :func:`kinetic_energy` is ``kinetic0`` again (eV)."""
    kinetic1 = kinetic_energy(atoms)
    scale = np.sqrt(kinetic0 / kinetic1) if kinetic1 > 0 else 0.0
    atoms.set_momenta(atoms.get_momenta() * scale, apply_constraint=False)


def rigid_stationary(atoms, preserve_temperature=True):
    r"""Zero the total momentum; what :func:`ase.md.velocitydistribution.Stationary` does.

    Every atom with mass loses the centre-of-mass velocity,
    :math:`p_i \leftarrow p_i - m_i P/M`; a uniform velocity is a rigid
    motion of every body, so rigid velocities stay rigid, and a massless
    site keeps its zero momentum.  With ``preserve_temperature`` the momenta
    are then scaled back to the kinetic energy they had, as ASE does.

    ASE's own ``Stationary`` reads ``atoms.get_temperature()`` first, which
    is 0/0 (NaN) when the atoms hold a massless site (four-site water), and
    then sets every momentum to zero: use this function there.

    Parameters
    ----------
    atoms : ase.Atoms
        Changed in place (momenta only).
    preserve_temperature : bool
        Scale the momenta back to the initial kinetic energy (default True).
    """
    masses = atoms.get_masses()
    kinetic0 = kinetic_energy(atoms)
    momenta = atoms.get_momenta()
    velocity = momenta.sum(axis=0) / masses.sum()
    atoms.set_momenta(momenta - masses[:, None] * velocity, apply_constraint=False)
    if preserve_temperature:
        _restore_kinetic_energy(atoms, kinetic0)


def rigid_zero_rotation(atoms, preserve_temperature=True):
    r"""Zero the total angular momentum; what :func:`ase.md.velocitydistribution.ZeroRotation` does.

    The rigid rotation :math:`\omega = I^{-1} L` of the whole system about its
    centre of mass (:math:`I` the inertia tensor of the atoms, :math:`L` their
    angular momentum) is subtracted from every atom with mass,
    :math:`p_i \leftarrow p_i - m_i\, \omega \times (x_i - X)`.  A rotation of
    the whole system is a rigid motion of each body, so rigid velocities stay
    rigid and massless sites keep zero momentum.  Positions are used as
    stored: give a cluster whose molecules are whole.  With
    ``preserve_temperature`` the momenta are scaled back to the initial
    kinetic energy, as ASE does.

    ASE's own ``ZeroRotation`` forms ``atoms.get_velocities()``, which is 0/0
    (NaN) on a massless site, and writes NaN momenta back: use this function
    on systems with massless sites.

    Parameters
    ----------
    atoms : ase.Atoms
        Changed in place (momenta only).
    preserve_temperature : bool
        Scale the momenta back to the initial kinetic energy (default True).
    """
    masses = atoms.get_masses()
    kinetic0 = kinetic_energy(atoms)
    momenta = atoms.get_momenta()
    r = atoms.get_positions() - atoms.get_center_of_mass()
    angular = np.cross(r, momenta).sum(axis=0)
    inertia = (np.einsum("i,ij,ij->", masses, r, r) * np.eye(3)
               - np.einsum("i,ij,ik->jk", masses, r, r))
    omega = np.linalg.lstsq(inertia, angular, rcond=None)[0]  # a line of atoms: no axial part
    atoms.set_momenta(momenta - masses[:, None] * np.cross(omega, r), apply_constraint=False)
    if preserve_temperature:
        _restore_kinetic_energy(atoms, kinetic0)


def rigid_temperature(frames, bodies=None):
    r"""Temperature (K) of frames read back from a file, with rigid degrees of freedom.

    ASE cannot rebuild rigidmd's constraint from a ``.traj`` file, so
    ``frame.get_temperature()`` divides by 3 degrees of freedom per atom and
    reads low (2/3 for water).  This divides the kinetic energy of the atoms
    by the rigid count:

    .. math::
        T = \frac{2 K}{N_f k_B},\qquad N_f = 6 n_\mathrm{bodies}
            - n_\mathrm{linear} + 3 n_\mathrm{free}

    (no centre-of-mass correction, as in ASE).  A dynamics that held the total
    momentum (a thermostat's ``fixcm``, ASE's ``FixCom``) counted 3 fewer in
    its log (``dyn.degrees_of_freedom``): its logged temperatures are these
    times :math:`N_f / (N_f - 3)`.

    Parameters
    ----------
    frames : ase.Atoms, sequence of ase.Atoms, str or os.PathLike
        One frame, frames, or a trajectory file (all its frames are read).
    bodies : optional
        Body specification, as for :class:`~rigidmd.RigidVerlet`.  The
        default finds the bodies rigidmd stores in the tags of every frame
        it writes.

    Returns
    -------
    float or numpy.ndarray, shape (n_frames,)
        K; a float for one Atoms.

    Examples
    --------
    >>> from rigidmd import rigid_temperature                     # doctest: +SKIP
    >>> rigid_temperature("md.traj")                              # doctest: +SKIP
    """
    import os

    from ase import Atoms
    from ase.io import read

    single = isinstance(frames, Atoms)
    if isinstance(frames, (str, os.PathLike)):
        frames = read(frames, ":")
    elif single:
        frames = [frames]
    frames = list(frames)
    if not frames:
        raise ValueError("rigid_temperature: no frames")
    for k, frame in enumerate(frames):
        if len(frame) != len(frames[0]):
            raise ValueError(f"rigid_temperature: frame {k} has {len(frame)} atoms, "
                             f"frame 0 has {len(frames[0])}")
    model = RigidBodies.resolve(frames[0], bodies).geometry(frames[0]).model
    ndof = model.degrees_of_freedom
    if ndof == 0:
        raise ValueError("rigid_temperature: the frames have no degrees of freedom")
    temperature = np.array([2.0 * kinetic_energy(frame) / (ndof * units.kB)
                            for frame in frames])
    return float(temperature[0]) if single else temperature
