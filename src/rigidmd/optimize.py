"""The path of rigid relaxation before :mod:`rigidmd.relax` became a package.

Kept so that scripts written for it still run: every name is
:mod:`rigidmd.relax.filter`'s (``from rigidmd.relax import RigidFilter, relax``
is the path to use).
"""

from rigidmd.relax.filter import (
    ANCHOR_ANGLE,
    OPTIMIZERS,
    Relaxation,
    RigidFilter,
    optimizer_class,
    relax,
    right_jacobian_transpose,
    rotation_quaternion,
)

__all__ = ["RigidFilter", "relax", "Relaxation", "OPTIMIZERS", "optimizer_class", "ANCHOR_ANGLE",
           "rotation_quaternion", "right_jacobian_transpose"]
