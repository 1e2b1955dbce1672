"""Rotations: quaternions (x, y, z, w; Hamilton), matrices, rotation vectors, Euler.

All functions take plain numpy arrays. Quaternion functions broadcast over leading
axes (``(..., 4)``); matrix functions take ``(..., 3, 3)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

_EPS = 1e-12


def quaternion_normalize(q: ArrayLike) -> Array:
    """Unit quaternion(s) with non-negative w (the canonical hemisphere).

    Parameters
    ----------
    q : array-like, shape (..., 4)
        Quaternions x, y, z, w, not necessarily unit.
    """
    qa = np.asarray(q, dtype=float)
    n = np.linalg.norm(qa, axis=-1, keepdims=True)
    if np.any(n < _EPS):
        raise ValueError("quaternion of zero norm")
    qa = qa / n
    return np.where(qa[..., 3:4] < 0.0, -qa, qa)


def quaternion_multiply(q1: ArrayLike, q2: ArrayLike) -> Array:
    """Hamilton product ``q1 * q2`` (apply q2 first, then q1), shapes (..., 4)."""
    q1 = np.asarray(q1, dtype=float)
    q2 = np.asarray(q2, dtype=float)
    x1, y1, z1, w1 = np.moveaxis(q1, -1, 0)
    x2, y2, z2, w2 = np.moveaxis(q2, -1, 0)
    return np.stack(
        [
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ],
        axis=-1,
    )


def quaternion_conjugate(q: ArrayLike) -> Array:
    """Conjugate (the inverse of a unit quaternion), shape (..., 4)."""
    q = np.array(q, dtype=float)
    q[..., :3] *= -1.0
    return q


def matrix_from_quaternion(q: ArrayLike) -> Array:
    """Rotation matrix (..., 3, 3) from unit quaternion(s) (..., 4), x-y-z-w."""
    q = np.asarray(q, dtype=float)
    x, y, z, w = np.moveaxis(q, -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    R = np.empty((*q.shape[:-1], 3, 3))
    R[..., 0, 0] = 1.0 - 2.0 * (yy + zz)
    R[..., 0, 1] = 2.0 * (xy - wz)
    R[..., 0, 2] = 2.0 * (xz + wy)
    R[..., 1, 0] = 2.0 * (xy + wz)
    R[..., 1, 1] = 1.0 - 2.0 * (xx + zz)
    R[..., 1, 2] = 2.0 * (yz - wx)
    R[..., 2, 0] = 2.0 * (xz - wy)
    R[..., 2, 1] = 2.0 * (yz + wx)
    R[..., 2, 2] = 1.0 - 2.0 * (xx + yy)
    return R


def quaternion_from_matrix(R: ArrayLike) -> Array:
    """Unit quaternions from rotation matrices (Shepperd's method).

    Each matrix takes the branch of its largest of trace and diagonal entries, so the
    result is accurate near 180 degree rotations too.

    Parameters
    ----------
    R : array-like, shape (..., 3, 3)

    Returns
    -------
    ndarray, shape (..., 4)
        (x, y, z, w) with w >= 0.
    """
    R = np.asarray(R, dtype=float)
    shape = R.shape[:-2]
    R = R.reshape(-1, 3, 3)
    trace = R[:, 0, 0] + R[:, 1, 1] + R[:, 2, 2]
    branch = np.argmax(np.stack([trace, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=-1), axis=-1)
    q = np.empty((R.shape[0], 4))
    for b in range(4):
        idx = branch == b
        if np.any(idx):
            q[idx] = _shepperd_branch(R[idx], b)
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q = np.where(q[:, 3:4] < 0.0, -q, q)
    return q.reshape((*shape, 4))


def _shepperd_branch(r: Array, b: int) -> Array:
    """Quaternions (n, 4), not normalised, of matrices r (n, 3, 3) by Shepperd's branch b:
    0 the trace, 1-3 the diagonal entry b - 1 is the largest."""
    m = [[r[:, i, j] for j in range(3)] for i in range(3)]
    if b == 0:
        s = 2.0 * np.sqrt(1.0 + m[0][0] + m[1][1] + m[2][2])
        cols = [(m[2][1] - m[1][2]) / s, (m[0][2] - m[2][0]) / s, (m[1][0] - m[0][1]) / s, 0.25 * s]
    elif b == 1:
        s = 2.0 * np.sqrt(1.0 + m[0][0] - m[1][1] - m[2][2])
        cols = [0.25 * s, (m[0][1] + m[1][0]) / s, (m[0][2] + m[2][0]) / s, (m[2][1] - m[1][2]) / s]
    elif b == 2:
        s = 2.0 * np.sqrt(1.0 + m[1][1] - m[0][0] - m[2][2])
        cols = [(m[0][1] + m[1][0]) / s, 0.25 * s, (m[1][2] + m[2][1]) / s, (m[0][2] - m[2][0]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2][2] - m[0][0] - m[1][1])
        cols = [(m[0][2] + m[2][0]) / s, (m[1][2] + m[2][1]) / s, 0.25 * s, (m[1][0] - m[0][1]) / s]
    return np.stack(cols, axis=-1)


def matrix_from_rotvec(w: ArrayLike) -> Array:
    """Exponential map so(3) -> SO(3): rotation matrix (..., 3, 3) from rotation vector(s).

    The rotation vector is axis * angle (radians); Rodrigues' formula with a Taylor
    expansion for small angles.
    """
    w = np.asarray(w, dtype=float)
    theta2 = np.sum(w * w, axis=-1)[..., None, None]
    theta = np.sqrt(theta2)
    small = theta2 < 1e-10
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    K = hat(w)
    eye = np.broadcast_to(np.eye(3), K.shape)
    return eye + a * K + b * (K @ K)


def rotvec_from_matrix(R: ArrayLike) -> Array:
    """Logarithmic map SO(3) -> so(3): rotation vector(s) (..., 3), angle in [0, pi].

    Goes through the quaternion, which stays accurate for angles near 0 and pi.
    """
    return rotvec_from_quaternion(quaternion_from_matrix(R))


def quaternion_from_rotvec(w: ArrayLike) -> Array:
    """Unit quaternion(s) (..., 4) from rotation vector(s) (..., 3)."""
    w = np.asarray(w, dtype=float)
    theta = np.linalg.norm(w, axis=-1, keepdims=True)
    half = 0.5 * theta
    small = theta < 1e-8
    k = np.where(small, 0.5 - theta * theta / 48.0, np.sin(half) / np.where(small, 1.0, theta))
    return np.concatenate([w * k, np.cos(half)], axis=-1)


def rotvec_from_quaternion(q: ArrayLike) -> Array:
    """Rotation vector(s) (..., 3) from unit quaternion(s) (..., 4); angle in [0, pi]."""
    q = np.asarray(q, dtype=float)
    q = np.where(q[..., 3:4] < 0.0, -q, q)
    v = q[..., :3]
    s = np.linalg.norm(v, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, q[..., 3:4])
    small = s < 1e-8
    k = np.where(small, 2.0 / np.maximum(q[..., 3:4], _EPS), angle / np.where(small, 1.0, s))
    return v * k


def rotation_angle(R: ArrayLike) -> Array:
    """Rotation angle(s) in [0, pi] of rotation matrices (..., 3, 3) (eq. 4.10).

    Equals ``arccos((trace(R) - 1) / 2)`` but computed through the quaternion, which
    does not lose precision for small angles.
    """
    q = quaternion_from_matrix(R)
    return 2.0 * np.arctan2(np.linalg.norm(q[..., :3], axis=-1), np.abs(q[..., 3]))


def quaternion_angle(q1: ArrayLike, q2: ArrayLike) -> Array:
    """Angle (radians, [0, pi]) of the rotation between unit quaternions q1 and q2."""
    d = np.abs(np.sum(np.asarray(q1, float) * np.asarray(q2, float), axis=-1))
    return 2.0 * np.arccos(np.clip(d, 0.0, 1.0))


def hat(w: ArrayLike) -> Array:
    """Skew-symmetric matrix (..., 3, 3) with ``hat(w) @ v == cross(w, v)``."""
    w = np.asarray(w, dtype=float)
    K = np.zeros((*w.shape[:-1], 3, 3))
    K[..., 0, 1] = -w[..., 2]
    K[..., 0, 2] = w[..., 1]
    K[..., 1, 0] = w[..., 2]
    K[..., 1, 2] = -w[..., 0]
    K[..., 2, 0] = -w[..., 1]
    K[..., 2, 1] = w[..., 0]
    return K


def matrix_from_euler_xyz(e: ArrayLike) -> Array:
    """Rotation matrix from extrinsic x-y-z (roll, pitch, yaw) angles: Rz @ Ry @ Rx."""
    e = np.asarray(e, dtype=float)
    cx, cy, cz = np.cos(e[..., 0]), np.cos(e[..., 1]), np.cos(e[..., 2])
    sx, sy, sz = np.sin(e[..., 0]), np.sin(e[..., 1]), np.sin(e[..., 2])
    R = np.empty((*e.shape[:-1], 3, 3))
    R[..., 0, 0] = cz * cy
    R[..., 0, 1] = cz * sy * sx - sz * cx
    R[..., 0, 2] = cz * sy * cx + sz * sx
    R[..., 1, 0] = sz * cy
    R[..., 1, 1] = sz * sy * sx + cz * cx
    R[..., 1, 2] = sz * sy * cx - cz * sx
    R[..., 2, 0] = -sy
    R[..., 2, 1] = cy * sx
    R[..., 2, 2] = cy * cx
    return R


def euler_xyz_from_matrix(R: ArrayLike) -> Array:
    """Extrinsic x-y-z (roll, pitch, yaw) angles from rotation matrices (inverse of
    :func:`matrix_from_euler_xyz`); pitch in [-pi/2, pi/2].

    The thesis writes small displacements as such "Euler poses" (Ch. 4.1.1); for small
    angles they agree with the rotation vector to second order.
    """
    R = np.asarray(R, dtype=float)
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    roll = np.arctan2(R[..., 2, 1], R[..., 2, 2])
    yaw = np.arctan2(R[..., 1, 0], R[..., 0, 0])
    return np.stack([roll, pitch, yaw], axis=-1)


def rotation_between(a: ArrayLike, b: ArrayLike) -> Array:
    """Smallest rotation matrix taking unit direction ``a`` onto unit direction ``b``."""
    va = np.asarray(a, float) / np.linalg.norm(a)
    vb = np.asarray(b, float) / np.linalg.norm(b)
    c = float(np.dot(va, vb))
    axis = np.cross(va, vb)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        if c > 0.0:
            return np.eye(3)
        # Antiparallel: any axis orthogonal to a.
        helper = np.array([1.0, 0.0, 0.0]) if abs(va[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        axis = np.cross(va, helper)
        axis /= np.linalg.norm(axis)
        return matrix_from_rotvec(axis * np.pi)
    return matrix_from_rotvec(axis / s * np.arctan2(s, c))


def average_quaternion(q: ArrayLike, weights: ArrayLike | None = None) -> Array:
    """Weighted mean orientation of unit quaternions (n, 4).

    The Markley et al. (2007) mean: the eigenvector of the largest eigenvalue of
    ``sum_i w_i q_i q_i^T``; insensitive to the sign ambiguity of quaternions.
    """
    q = np.asarray(q, dtype=float)
    w = np.ones(len(q)) if weights is None else np.asarray(weights, dtype=float)
    A = (q * w[:, None]).T @ q
    _, vecs = np.linalg.eigh(A)
    return quaternion_normalize(vecs[:, -1])
