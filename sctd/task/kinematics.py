"""Where a joint has moved its handle (pure numpy): one answer for the scene, the
simulated user and the demonstrator.

A joint's handle body has its default pose ``T_world_handle0`` (the joint at 0, the
frame the scene publishes). A prismatic joint moves it along that frame's own x axis by
its position (m); a revolute joint turns it about its hinge line (a point and a unit
axis in that frame) by its position (rad, right-hand rule):

    T_world_handle(q) = T_world_handle0 @ [[R(q), p - R(q) p], [0, 1]],
    R(q) = exp(q [a]x)

with ``p`` and ``a`` the hinge's point and axis in the handle's frame.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from sctd import se3

if TYPE_CHECKING:  # (the joint's kind draws itself with these functions)
    from .kinds.joint import Joint

Array = NDArray[np.float64]


def handle_pose(joint: Joint, T_world_handle0: Array, position: float) -> Array:
    """The handle's pose with ``joint`` at ``position``.

    Parameters
    ----------
    joint : Joint
    T_world_handle0 : ndarray, shape (4, 4)
        The handle body's pose at 0.
    position : float
        The joint's position, m (prismatic) or rad (revolute).

    Returns
    -------
    T_world_handle : ndarray, shape (4, 4)
        A new array; the handle's origin is where the hand grasps it.
    """
    T = T_world_handle0.copy()
    if joint.hinge is None:  # along the handle's x
        T[:3, 3] += position * T[:3, 0]
        return T
    R = _turn(joint, position)
    T_handle0_handle = np.eye(4)
    T_handle0_handle[:3, :3] = R
    T_handle0_handle[:3, 3] = joint.hinge.point - R @ joint.hinge.point
    return T_world_handle0 @ T_handle0_handle


def handle_jacobian(joint: Joint, T_world_handle0: Array, position: float) -> Array:
    """How the handle's origin moves per unit of joint speed at ``position`` (world).

    Returns
    -------
    ndarray, shape (3,)
        ``d p_world_handle / d q``: the handle's x axis at 0 (a unit vector) for a
        prismatic joint; ``a x (p_handle - p_hinge)`` for a revolute one, the arc's
        tangent, of length the handle's lever (m/rad).
    """
    if joint.hinge is None:
        return T_world_handle0[:3, 0].copy()
    # in the handle's frame at 0 the handle is at p - R p, the hinge's point at p
    arm = -(_turn(joint, position) @ joint.hinge.point)
    return T_world_handle0[:3, :3] @ np.cross(joint.hinge.axis, arm)


def _turn(joint: Joint, position: float) -> Array:
    """``R(q)``: a revolute joint's rotation at ``position``, in the handle's frame at 0."""
    assert joint.hinge is not None
    a0, a1, a2 = (joint.hinge.axis * position).tolist()
    return se3.matrix3_from_rotvec(a0, a1, a2)
