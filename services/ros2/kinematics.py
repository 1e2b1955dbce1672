"""The hand's pose from a ``sensor_msgs/JointState``: forward kinematics of the user's
URDF by Pinocchio, to one frame of it (the end effector sctd moves).

The URDF's root is taken to be the world frame the bridge is configured with (a robot
whose base is elsewhere puts a fixed joint from ``world`` to its base in its URDF, as
MoveIt's configurations do); there is no tf2 here to ask.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sctd import se3


class KinematicsError(ValueError):
    """The URDF or the frame cannot be used (the message names which and why)."""


class ForwardKinematics:
    """``fk(q) -> [x, y, z, qx, qy, qz, qw]`` of frame ``ee_frame`` of ``urdf``.

    Attributes
    ----------
    joint_names : tuple of str
        The joints ``q`` is in (the model's order; a JointState is read by name).
    """

    def __init__(self, urdf: str | Path, ee_frame: str):
        import pinocchio as pin

        try:
            self.model = pin.buildModelFromUrdf(str(urdf))
        except (ValueError, RuntimeError, OSError) as e:
            raise KinematicsError(f"{urdf}: not a URDF Pinocchio reads: {e}") from None
        if not self.model.existFrame(ee_frame):
            names = ", ".join(f.name for f in self.model.frames)
            raise KinematicsError(f"{urdf}: no frame {ee_frame!r} (frames: {names[:400]})")
        if any(j.nq != 1 for j in self.model.joints[1:]):
            raise KinematicsError(f"{urdf}: only one-degree-of-freedom joints (revolute, prismatic) are read "
                                  "from a JointState")
        self.frame = self.model.getFrameId(ee_frame)
        self.data = self.model.createData()
        self.joint_names = tuple(self.model.names[1:])
        self._pin = pin

    def __call__(self, q: list[float]) -> list[float]:
        pin = self._pin
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        M = self.data.oMf[self.frame]
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = M.rotation, M.translation
        return [float(v) for v in se3.pose_from_transform(T)]
