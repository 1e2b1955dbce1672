"""Rigid transforms: poses [x, y, z, qx, qy, qz, qw] <-> 4x4 matrices, the tf-norm,
and the displacement convention shared by the runtime and the learner.

Displacement convention (docs/skill-format.md)
---------------------------------------------
The thesis writes a displacement once right-multiplied (eq. 4.2, in the moving frame)
and once left-multiplied (eqs. 4.3-4.4, in the fixed frame); Algorithm 2 applies the
translation in the parent's axes and the rotation relative to the frame itself. sctd
uses the Algorithm 2 form everywhere, so that what the learner identifies is exactly
what the runtime applies:

    T_next = Trans(d) @ T @ Rot(exp(r))

with ``d`` (3,) the translation of the frame's origin expressed in the parent frame
(the task object's frame) and ``r`` (3,) the rotation vector of the rotation about the
frame's own origin and axes. The 6-vector ``[d, r]`` is what a linear input mapping
``M @ u`` produces (rows tx, ty, tz, rx, ry, rz). Its inverse is
:func:`displacement_from_transforms`: ``d = t_next - t`` and ``r = log(R^T R_next)``.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ._fast import flat_from_pose, transform_from_flat
from ._rotations import (
    matrix_from_quaternion,
    matrix_from_rotvec,
    quaternion_from_matrix,
    rotation_angle,
    rotvec_from_matrix,
)

Array = NDArray[np.float64]


def transform_from_pose(pose: ArrayLike, check: bool = True) -> Array:
    """4x4 homogeneous matrices from poses.

    Parameters
    ----------
    pose : array-like, shape (..., 7)
        [x, y, z, qx, qy, qz, qw]; the quaternion is normalised here.
    check : bool
        Refuse a quaternion of zero norm (ValueError); without the check it gives NaNs.

    Returns
    -------
    ndarray, shape (..., 4, 4)
    """
    one = _one_pose(pose)
    if one is not None:
        _, _, _, qx, qy, qz, qw = one
        if math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) >= 1e-12:
            # One pose on floats: the same numbers, without the vectorised path's cost.
            return transform_from_flat(flat_from_pose(one))
    pose = np.asarray(pose, dtype=float)
    q = pose[..., 3:]
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if check and np.any(n < 1e-12):
        raise ValueError("pose quaternion of zero norm")
    T = np.zeros((*pose.shape[:-1], 4, 4))
    T[..., :3, :3] = matrix_from_quaternion(q / n)
    T[..., :3, 3] = pose[..., :3]
    T[..., 3, 3] = 1.0
    return T


def _one_pose(pose: ArrayLike) -> list[float] | None:
    """``pose`` as a list of 7 numbers when it is a single pose, else None."""
    if isinstance(pose, np.ndarray):
        return pose.tolist() if pose.shape == (7,) else None
    if isinstance(pose, list | tuple) and len(pose) == 7 and all(
            isinstance(v, int | float) for v in pose):
        return list(pose)
    return None


def pose_from_transform(T: ArrayLike) -> Array:
    """Pose(s) [x, y, z, qx, qy, qz, qw] (..., 7) from 4x4 matrices; qw >= 0."""
    T = np.asarray(T, dtype=float)
    return np.concatenate([T[..., :3, 3], quaternion_from_matrix(T[..., :3, :3])], axis=-1)


def transform_from_rt(R: ArrayLike, t: ArrayLike) -> Array:
    """4x4 matrix from rotation (3, 3) and translation (3,)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def invert_transform(T: ArrayLike) -> Array:
    """Inverse of rigid transform(s) (..., 4, 4) without a general matrix inverse."""
    T = np.asarray(T, dtype=float)
    R = T[..., :3, :3]
    Rt = np.swapaxes(R, -1, -2)
    out = np.zeros_like(T)
    out[..., :3, :3] = Rt
    out[..., :3, 3] = -(Rt @ T[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def tf_norm(T: ArrayLike, alpha: float = 0.4) -> Array:
    """Transform norm ``||t||_2 + alpha * angle(R)`` of transform(s) (eqs. 4.9-4.10).

    Parameters
    ----------
    T : array-like, shape (..., 4, 4)
    alpha : float
        Metres per radian trading rotation against translation (thesis: 0.3-0.5).
    """
    T = np.asarray(T, dtype=float)
    return np.linalg.norm(T[..., :3, 3], axis=-1) + alpha * rotation_angle(T[..., :3, :3])


def tf_norm_of_displacement(d6: ArrayLike, alpha: float = 0.4) -> Array:
    """tf-norm of displacement 6-vector(s) [d, r] (..., 6): ``||d|| + alpha * ||r||``.

    Equals :func:`tf_norm` of the transform the displacement makes, because the angle
    of ``exp(r)`` is ``||r||`` for ``||r|| <= pi``.
    """
    d6 = np.asarray(d6, dtype=float)
    return np.linalg.norm(d6[..., :3], axis=-1) + alpha * np.linalg.norm(d6[..., 3:], axis=-1)


def displacement_from_transforms(T_a: ArrayLike, T_b: ArrayLike) -> Array:
    """Displacement 6-vector(s) [d, r] taking frame pose T_a to T_b (see module doc).

    Parameters
    ----------
    T_a, T_b : array-like, shape (..., 4, 4)
        Poses of the same frame in a common parent frame.

    Returns
    -------
    ndarray, shape (..., 6)
        ``d = t_b - t_a`` in the parent's axes, ``r = log(R_a^T R_b)`` in the frame's.
    """
    T_a = np.asarray(T_a, dtype=float)
    T_b = np.asarray(T_b, dtype=float)
    d = T_b[..., :3, 3] - T_a[..., :3, 3]
    R_rel = np.swapaxes(T_a[..., :3, :3], -1, -2) @ T_b[..., :3, :3]
    return np.concatenate([d, rotvec_from_matrix(R_rel)], axis=-1)


def apply_displacement(T: ArrayLike, d6: ArrayLike) -> Array:
    """Apply displacement [d, r] to frame pose(s) T: ``Trans(d) @ T @ Rot(exp(r))``."""
    T = np.asarray(T, dtype=float)
    d6 = np.asarray(d6, dtype=float)
    out = T.copy()
    out[..., :3, :3] = T[..., :3, :3] @ matrix_from_rotvec(d6[..., 3:])
    out[..., :3, 3] = T[..., :3, 3] + d6[..., :3]
    return out


def exp_se3(xi: ArrayLike) -> Array:
    """Exponential map of a twist [v, w] (6,) in body coordinates to a 4x4 transform."""
    xi = np.asarray(xi, dtype=float)
    v, w = xi[:3], xi[3:]
    theta = float(np.linalg.norm(w))
    R = matrix_from_rotvec(w)
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if theta < 1e-8:
        V = np.eye(3) + 0.5 * K
    else:
        V = (
            np.eye(3)
            + (1.0 - np.cos(theta)) / theta**2 * K
            + (theta - np.sin(theta)) / theta**3 * (K @ K)
        )
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = V @ v
    return T


def log_se3(T: ArrayLike) -> Array:
    """Logarithmic map of a 4x4 transform to a twist [v, w] (6,); inverse of exp_se3."""
    T = np.asarray(T, dtype=float)
    w = rotvec_from_matrix(T[:3, :3])
    theta = float(np.linalg.norm(w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    if theta < 1e-8:
        V_inv = np.eye(3) - 0.5 * K
    else:
        half = 0.5 * theta
        V_inv = (
            np.eye(3)
            - 0.5 * K
            + (1.0 - half * np.cos(half) / np.sin(half)) / theta**2 * (K @ K)
        )
    return np.concatenate([V_inv @ T[:3, 3], w])


def transform_from_displacement(d6: ArrayLike) -> Array:
    """The transform ``Trans(d) Rot(exp(r))`` of a displacement applied at the identity."""
    d6 = np.asarray(d6, dtype=float)
    T = np.eye(4)
    T[:3, :3] = matrix_from_rotvec(d6[3:])
    T[:3, 3] = d6[:3]
    return T
