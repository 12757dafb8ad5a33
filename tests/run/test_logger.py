"""The MD log's old import path (rigidmd.run.logger) names the core's objects."""

import rigidmd.core.logger as core
import rigidmd.run.logger as old


def test_every_name_is_the_cores():
    assert old.__all__ == ["RigidLogger", "LOG_COLUMNS"]
    for name in old.__all__:
        assert getattr(old, name) is getattr(core, name), name
