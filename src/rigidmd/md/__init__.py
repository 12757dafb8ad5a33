"""The dynamics classes users construct, one module each as ASE's ``ase.md`` groups them.

Each is a :class:`~rigidmd.core.dynamics.RigidDynamics` with the coupling parts
(:mod:`rigidmd.couplings`) built from the arguments of the matching ASE class:
:class:`RigidVerlet` (:mod:`rigidmd.md.verlet`), :class:`RigidLangevin`
(:mod:`rigidmd.md.langevin`), :class:`RigidLangevinBAOAB`
(:mod:`rigidmd.md.langevinbaoab`), :class:`RigidBussi` (:mod:`rigidmd.md.bussi`),
:class:`RigidNoseHoover` (:mod:`rigidmd.md.nosehoover`), :class:`RigidNPT`
(:mod:`rigidmd.md.npt`), :class:`RigidCRescale` (:mod:`rigidmd.md.crescale`) and
:class:`RigidMCBarostat` (:mod:`rigidmd.md.mcbarostat`); their bases are in
:mod:`rigidmd.md.coupled`.  :func:`rigidmd.load_checkpoint` rebuilds any of them.
"""

from rigidmd.md.bussi import RigidBussi
from rigidmd.md.crescale import RigidCRescale
from rigidmd.md.langevin import RigidLangevin
from rigidmd.md.langevinbaoab import RigidLangevinBAOAB
from rigidmd.md.mcbarostat import RigidMCBarostat
from rigidmd.md.nosehoover import RigidNoseHoover
from rigidmd.md.npt import RigidNPT
from rigidmd.md.verlet import RigidVerlet

__all__ = ["RigidVerlet", "RigidLangevin", "RigidLangevinBAOAB", "RigidBussi",
           "RigidNoseHoover", "RigidNPT", "RigidCRescale", "RigidMCBarostat"]
