"""rigidmd: rigid-body molecular dynamics for ASE.

Molecules move as rigid bodies (quaternion velocity Verlet, NO_SQUISH as in
LAMMPS ``fix rigid/nve``) with forces from any ASE calculator; atoms in no
body move as point particles in the same step.
"""

from rigidmd.core.bodies import RigidBodies
from rigidmd.core.dof import RigidBodyDOF, kinetic_energy, temperature
from rigidmd.core.dynamics import NonFiniteForceError, RigidDynamics
from rigidmd.core.model import BodyGeometry, BodyModel
from rigidmd.core.split import MultipleTimeStep
from rigidmd.core.velocities import (
    rigid_maxwell_boltzmann,
    rigid_stationary,
    rigid_temperature,
    rigid_zero_rotation,
)
from rigidmd.md import (
    RigidBussi,
    RigidCRescale,
    RigidLangevin,
    RigidLangevinBAOAB,
    RigidMCBarostat,
    RigidNoseHoover,
    RigidNPT,
    RigidVerlet,
)
from rigidmd.run.restart import load_checkpoint

__all__ = [
    "RigidDynamics",
    "RigidVerlet",
    "RigidLangevin",
    "RigidLangevinBAOAB",
    "RigidBussi",
    "RigidNoseHoover",
    "RigidNPT",
    "RigidCRescale",
    "RigidMCBarostat",
    "MultipleTimeStep",
    "RigidBodies",
    "BodyModel",
    "BodyGeometry",
    "RigidBodyDOF",
    "NonFiniteForceError",
    "rigid_maxwell_boltzmann",
    "kinetic_energy",
    "temperature",
    "rigid_temperature",
    "rigid_stationary",
    "rigid_zero_rotation",
    "load_checkpoint",
]

__version__ = "0.1.0"
