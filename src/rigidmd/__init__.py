"""rigidmd: rigid-body molecular dynamics for ASE.

Molecules move as rigid bodies (quaternion velocity Verlet, NO_SQUISH as in
LAMMPS ``fix rigid/nve``) with forces from any ASE calculator; atoms in no
body move as point particles in the same step.
"""

from rigidmd.barostats import RigidCRescale, RigidNPT
from rigidmd.bodies import RigidBodies
from rigidmd.dof import RigidBodyDOF, kinetic_energy, temperature
from rigidmd.dynamics import NonFiniteForceError, RigidDynamics, RigidVerlet
from rigidmd.model import BodyGeometry, BodyModel
from rigidmd.montecarlo import RigidMCBarostat
from rigidmd.restart import load_checkpoint
from rigidmd.thermostats import RigidBussi, RigidLangevin, RigidNoseHoover
from rigidmd.velocities import (
    rigid_maxwell_boltzmann,
    rigid_stationary,
    rigid_temperature,
    rigid_zero_rotation,
)

__all__ = [
    "RigidDynamics",
    "RigidVerlet",
    "RigidLangevin",
    "RigidBussi",
    "RigidNoseHoover",
    "RigidNPT",
    "RigidCRescale",
    "RigidMCBarostat",
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
