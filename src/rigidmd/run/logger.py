"""The MD log's old path: :mod:`rigidmd.core.logger` holds it now.

The dynamics opens its own log (``logfile=``), so the logger lives in the core;
the names are re-exported here for code written for this path.
"""

from rigidmd.core.logger import LOG_COLUMNS, RigidLogger

__all__ = ["RigidLogger", "LOG_COLUMNS"]
