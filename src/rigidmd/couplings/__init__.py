"""Coupling parts: thermostats, barostats and the Monte Carlo barostat, on the base in ``base``.

Nothing is re-exported here: the public names live in :mod:`rigidmd`; import a
module of this package by its full path (``from rigidmd.couplings.base import Coupling``).
"""
