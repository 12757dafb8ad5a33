"""The checkpoint file's old path: :mod:`rigidmd.core.checkpoint` holds it now.

The dynamics writes its own checkpoints (:meth:`RigidDynamics.save_checkpoint
<rigidmd.core.dynamics.RigidDynamics.save_checkpoint>`), so the format lives in
the core; the names are re-exported here for code written for this path.
"""

from rigidmd.core.checkpoint import (
    FORMAT,
    Checkpoint,
    CheckpointError,
    atomic_write,
    check_checkpoint,
    read_checkpoint,
    remove_stale_temporaries,
    save_checkpoint,
)

__all__ = ["save_checkpoint", "read_checkpoint", "check_checkpoint", "atomic_write",
           "remove_stale_temporaries", "Checkpoint", "CheckpointError", "FORMAT"]
