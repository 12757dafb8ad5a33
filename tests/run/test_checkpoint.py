"""The checkpoint's old import path (rigidmd.run.checkpoint) names the core's objects."""

import rigidmd.core.checkpoint as core
import rigidmd.run.checkpoint as old


def test_every_name_is_the_cores():
    assert old.__all__ == ["save_checkpoint", "read_checkpoint", "check_checkpoint",
                           "atomic_write", "remove_stale_temporaries", "Checkpoint",
                           "CheckpointError", "FORMAT"]
    for name in old.__all__:
        assert getattr(old, name) is getattr(core, name), name
