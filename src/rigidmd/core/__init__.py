"""The rigid-body integrator: body model and state, operators and kernels, link, forces, step.

Nothing is re-exported here: the public names live in :mod:`rigidmd`; import a
module of this package by its full path (``from rigidmd.core.model import BodyModel``).
"""
