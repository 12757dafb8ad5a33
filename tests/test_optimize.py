"""Rigid relaxation's old import path (rigidmd.optimize) names rigidmd.relax.filter's objects."""

import rigidmd.optimize as old
import rigidmd.relax.filter as filter_module


def test_every_name_is_the_filters():
    assert set(old.__all__) == {"RigidFilter", "relax", "Relaxation", "OPTIMIZERS",
                                "optimizer_class", "ANCHOR_ANGLE", "rotation_quaternion",
                                "right_jacobian_transpose"}
    for name in old.__all__:
        assert getattr(old, name) is getattr(filter_module, name), name
