"""Rigid relaxation: bodies and cell at the calculator's minimum, with ASE's optimizers.

* :func:`relax` and :class:`RigidFilter` (:mod:`rigidmd.relax.filter`): the centres
  of mass, orientations (and the cell) as the rows an ASE optimizer moves;
  :class:`RigidLBFGS` (:mod:`rigidmd.relax.lbfgs`) with :class:`RigidPrecon`
  (:mod:`rigidmd.relax.precon`) is the default, needing no tuning;
* the cell's part (:mod:`rigidmd.relax.cell`);
* :func:`relax_bodies` (:mod:`rigidmd.relax.relaxbodies`): each kind of molecule in
  the internal geometry a calculator prefers, before it is made rigid (its
  result is a :class:`BodyRelaxation`; :func:`relax`'s is a
  :class:`rigidmd.relax.filter.Relaxation`);

This package is a library: it imports only the core.  The ``relax:`` section of a
run and ``rigidmd relax`` are the application's (:mod:`rigidmd.run.relaxstructure`,
:mod:`rigidmd.run.relaxcommand`).
"""

from rigidmd.relax.cell import CELL_MODES
from rigidmd.relax.filter import OPTIMIZERS, RigidFilter, optimizer_class, relax
from rigidmd.relax.lbfgs import RigidLBFGS
from rigidmd.relax.precon import RigidPrecon
from rigidmd.relax.relaxbodies import BodyRelaxation, relax_bodies

__all__ = ["relax", "RigidFilter", "RigidLBFGS", "RigidPrecon", "OPTIMIZERS", "optimizer_class",
           "CELL_MODES", "relax_bodies", "BodyRelaxation"]

