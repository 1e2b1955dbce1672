"""Damped least-squares inverse kinematics (for start postures and tests, not per tick)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from ._load import ArmModel

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


def inverse_kinematics(
    arm: ArmModel,
    T_world_ee: np.ndarray,
    q_init: np.ndarray | None = None,
    tol: float = 1e-6,
    max_iter: int = 500,
    damping: float = 1e-3,
    null_gain: float = 0.05,
) -> tuple[np.ndarray, bool]:
    """Joint positions putting the ee at ``T_world_ee``.

    Damped least squares on the error ``[p_t - p, log(R_t R^T)]`` (world axes), with a
    small null-space pull towards the rest posture and clamping to the joint limits.

    Parameters
    ----------
    arm : ArmModel
    T_world_ee : ndarray, shape (4, 4)
    q_init : ndarray, shape (7,), optional
        Start of the iteration; default the rest posture.
    tol : float, optional
        Stop when the error norm (m and rad) is below this.
    max_iter : int, optional
    damping : float, optional
        Levenberg-Marquardt damping.
    null_gain : float, optional
        Step towards the rest posture in the null space, per iteration.

    Returns
    -------
    q : ndarray, shape (7,)
    converged : bool
    """
    model, data = arm.model, arm.model.createData()
    q = np.array(arm.rest if q_init is None else q_init, dtype=float)
    T_t = np.asarray(T_world_ee, dtype=float)
    eye = np.eye(model.nv)
    for _ in range(max_iter):
        pin.framesForwardKinematics(model, data, q)
        T = data.oMf[arm.ee_frame_id]
        e = np.concatenate([T_t[:3, 3] - T.translation, pin.log3(T_t[:3, :3] @ T.rotation.T)])
        if np.linalg.norm(e) < tol:
            return q, True
        J = pin.computeFrameJacobian(model, data, q, arm.ee_frame_id, _LWA)
        JJt = J @ J.T + damping**2 * np.eye(6)
        J_pinv = J.T @ np.linalg.inv(JJt)
        dq = J_pinv @ e + (eye - J_pinv @ J) @ (null_gain * (arm.rest - q))
        q = np.clip(q + dq, arm.q_lower, arm.q_upper)
    return q, False
