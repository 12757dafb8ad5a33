"""Ready-made systems: water molecules, clusters, boxes, ice, CO2 mixtures (as ASE Atoms).

The builders live in :mod:`rigidmd.systems.builders`; they are re-exported here, so
``from rigidmd.systems import water_box`` is the way to reach them.
"""

from rigidmd.systems.builders import (
    R_CO,
    co2_molecule,
    co2_water_mixture,
    ice_ih,
    random_quaternions,
    water_box,
    water_cluster,
    water_molecule,
)

__all__ = ["water_molecule", "co2_molecule", "water_cluster", "water_box",
           "co2_water_mixture", "random_quaternions", "ice_ih", "R_CO"]
