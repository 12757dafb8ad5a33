"""NVE rigid-body dynamics: :class:`RigidVerlet` (ASE's ``VelocityVerlet``)."""

from rigidmd.core.dynamics import RigidDynamics

__all__ = ["RigidVerlet"]


class RigidVerlet(RigidDynamics):
    r"""NVE rigid-body molecular dynamics (NO_SQUISH quaternion velocity Verlet by default).

    One step of ``timestep`` with the default integrator is (Miller et al.
    2002; LAMMPS ``fix rigid/nve``)

    1. :math:`V \mathrel{+}= \tfrac{\Delta t}{2} F/M`, :math:`X \mathrel{+}= \Delta t\,V`,
       :math:`p \mathrel{+}= \Delta t\; q \otimes (0, R(q)^\mathsf{T}\tau)`;
    2. free rotation :math:`R_3(\tfrac{\Delta t}{2}) R_2(\tfrac{\Delta t}{2})
       R_1(\Delta t) R_2(\tfrac{\Delta t}{2}) R_3(\tfrac{\Delta t}{2})`;
    3. atoms placed at :math:`x_i = X + R(q)\,d_i`, one force call;
    4. :math:`V \mathrel{+}= \tfrac{\Delta t}{2} F/M`,
       :math:`p \mathrel{+}= \Delta t\; q \otimes (0, R(q)^\mathsf{T}\tau)`;
    5. atom momenta :math:`m_i (V + \omega \times (x_i - X))`.

    It is symplectic, time reversible and second order, with one force
    evaluation per step.  Parameters as :class:`RigidDynamics`, without
    ``couplings``.
    """

    part_types = ()

    def __init__(self, atoms, timestep, bodies=None, trajectory=None, logfile=None,
                 loginterval=1, integrator="no_squish", integrator_options=None, backend=None,
                 **kwargs):
        if "couplings" in kwargs:
            raise TypeError("RigidVerlet is NVE and takes no couplings; use RigidDynamics "
                            "or a thermostat class")
        super().__init__(atoms, timestep, bodies=bodies, trajectory=trajectory,
                         logfile=logfile, loginterval=loginterval, integrator=integrator,
                         integrator_options=integrator_options, backend=backend, **kwargs)
