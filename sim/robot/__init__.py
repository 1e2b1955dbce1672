"""The simulated arm's description: URDF next to this file and its Pinocchio loader.

The URDF (``edan_arm.urdf``) is a 7-DoF light-weight arm written from the published
kinematic parameters of the KUKA LBR iiwa 7 R800; see the comment at its top. Another
arm's URDF loads with :func:`load_arm_model` too (``docs/sim-urdf.md``).
"""

from ._ik import inverse_kinematics
from ._load import (
    ARMATURE,
    EE_FRAME,
    FORWARD_POSTURE,
    REST_POSTURE,
    UP_POSTURE,
    URDF_PATH,
    ArmModel,
    ArmModelError,
    load_arm_model,
)

__all__ = ["ARMATURE", "EE_FRAME", "FORWARD_POSTURE", "REST_POSTURE", "UP_POSTURE", "URDF_PATH", "ArmModel",
           "ArmModelError", "inverse_kinematics", "load_arm_model"]
