"""Load the arm URDF into an immutable Pinocchio model plus its limits."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

URDF_PATH = Path(__file__).with_name("edan_arm.urdf")
"""Path of the shipped URDF."""

EE_FRAME = "ee"
"""Name of the end-effector (hand tool centre point) frame."""

ARMATURE = np.array([0.20, 0.20, 0.10, 0.10, 0.05, 0.03, 0.03])
"""Reflected rotor inertia per joint, kg m^2 (motor inertia times gear ratio squared).

URDF has no field for it. Harmonic-drive joints of light-weight arms reflect 0.03 to
0.3 kg m^2; besides realism this keeps the light wrist links numerically well
conditioned at 1 kHz with explicit integration.
"""

REST_POSTURE = np.deg2rad([0.0, 30.0, 0.0, -90.0, 0.0, 60.0, 0.0])
"""Default posture, rad: elbow bent, hand in front of the base pointing down."""

FORWARD_POSTURE = np.deg2rad([0.0, 50.0, 0.0, -100.0, 0.0, -40.0, 0.0])
"""Posture with the hand in front pointing forward and down-tilted (IK seed)."""

UP_POSTURE = np.deg2rad([-56.0, 84.0, -84.0, 111.0, -82.0, 87.0, 125.0])
"""Posture with the hand in front pointing up, elbow out to the side (IK seed for the
scenes, whose hand points up; with the elbow in the vertical plane the wrist pitch
limit keeps an upward hand far from the base)."""


@dataclass(frozen=True)
class ArmModel:
    """Immutable description of the arm shared by physics, controller and drives.

    Attributes
    ----------
    model : pinocchio.Model
        Kinematic and inertial model with armature set. Never mutate after loading;
        every user keeps its own ``pinocchio.Data`` workspace (``model.createData()``).
    ee_frame_id : int
        Index of the ``ee`` frame in ``model.frames``.
    q_lower, q_upper : ndarray, shape (7,)
        Joint position limits, rad.
    dq_max : ndarray, shape (7,)
        Joint velocity limits, rad/s.
    tau_max : ndarray, shape (7,)
        Joint torque limits, N m.
    damping : ndarray, shape (7,)
        Viscous joint friction, N m s / rad.
    rest : ndarray, shape (7,)
        Rest posture, rad.
    """

    model: pin.Model
    ee_frame_id: int
    q_lower: np.ndarray
    q_upper: np.ndarray
    dq_max: np.ndarray
    tau_max: np.ndarray
    damping: np.ndarray
    rest: np.ndarray

    @property
    def nq(self) -> int:
        """Number of joints."""
        return int(self.model.nq)

    @property
    def joint_names(self) -> list[str]:
        """Names of the actuated joints, base to tip."""
        return [str(n) for n in self.model.names[1:]]


def load_arm_model(urdf_path: str | Path = URDF_PATH) -> ArmModel:
    """Build the arm model from its URDF.

    Parameters
    ----------
    urdf_path : str or Path, optional
        URDF file; defaults to the shipped ``edan_arm.urdf``.

    Returns
    -------
    ArmModel
        The model with armature (:data:`ARMATURE`) and all limits as arrays.

    Raises
    ------
    ValueError
        If the URDF does not describe a 7-DoF revolute chain with an ``ee`` frame.
    """
    model = pin.buildModelFromUrdf(str(urdf_path))
    if model.nq != 7 or model.nv != 7:
        raise ValueError(f"{urdf_path}: expected 7 revolute joints, got nq={model.nq}")
    if not model.existFrame(EE_FRAME):
        raise ValueError(f"{urdf_path}: no frame named {EE_FRAME!r}")
    model.armature = ARMATURE.copy()
    for name in ("lowerPositionLimit", "upperPositionLimit", "velocityLimit", "effortLimit"):
        arr = np.asarray(getattr(model, name))
        if not np.all(np.isfinite(arr)) or (name != "lowerPositionLimit" and np.any(arr <= 0)):
            raise ValueError(f"{urdf_path}: joint limits {name} missing or invalid: {arr}")
    return ArmModel(
        model=model,
        ee_frame_id=int(model.getFrameId(EE_FRAME)),
        q_lower=np.array(model.lowerPositionLimit),
        q_upper=np.array(model.upperPositionLimit),
        dq_max=np.array(model.velocityLimit),
        tau_max=np.array(model.effortLimit),
        damping=np.array(model.damping),
        rest=REST_POSTURE.copy(),
    )
