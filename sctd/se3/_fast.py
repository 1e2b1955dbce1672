"""Single-transform fast paths for the real-time tick.

numpy's per-call overhead dominates on 3x3 and 4x4 arrays, so the per-tick functions
here use scalar ``math`` and build at most one small array each. They compute the same
as their vectorised counterparts (tests check the agreement); use those everywhere
outside hot loops.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]
Flat = tuple  # a rigid transform as 12 floats: rotation row-major (9), then translation (3)


def quaternion_from_matrix3(R: Array) -> tuple[float, float, float, float]:
    """(qx, qy, qz, qw), qw >= 0, of one rotation matrix (Shepperd's method)."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = R.tolist()
    return quaternion_from_rows(m00, m01, m02, m10, m11, m12, m20, m21, m22)


def quaternion_from_rows(m00: float, m01: float, m02: float, m10: float, m11: float, m12: float,
                         m20: float, m21: float, m22: float) -> tuple[float, float, float, float]:
    """(qx, qy, qz, qw), qw >= 0, of the rotation matrix with these entries (row-major).

    Shepperd's method; every branch reads all nine entries, so a non-finite entry gives a
    non-finite quaternion."""
    tr = m00 + m11 + m22
    if tr >= m00 and tr >= m11 and tr >= m22:
        s = 2.0 * math.sqrt(1.0 + tr)
        x, y, z, w = (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s
    elif m00 >= m11 and m00 >= m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        x, y, z, w = 0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s
    elif m11 >= m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        x, y, z, w = (m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        x, y, z, w = (m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0.0:
        n = -n
    return x / n, y / n, z / n, w / n


def rows_from_quaternion(qx: float, qy: float, qz: float, qw: float) -> tuple[float, ...]:
    """The 9 entries (row-major) of the rotation of a quaternion (normalised here)."""
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    return (1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy),
            2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx),
            2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy))


def compose_quaternions(a: tuple[float, ...], b: tuple[float, ...]) -> tuple[float, float, float, float]:
    """Hamilton product a * b of two (x, y, z, w) quaternions (rotation b, then a)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def rotvec_from_matrix3(R: Array) -> tuple[float, float, float]:
    """Rotation vector of one rotation matrix, angle in [0, pi]."""
    x, y, z, w = quaternion_from_matrix3(R)
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        k = 2.0 / w
    else:
        k = 2.0 * math.atan2(s, w) / s
    return x * k, y * k, z * k


def matrix3_from_rotvec(w0: float, w1: float, w2: float) -> Array:
    """Rotation matrix of one rotation vector (Rodrigues)."""
    r = rows_from_rotvec(w0, w1, w2)
    return np.array([r[0:3], r[3:6], r[6:9]])


def flat_from_pose(p) -> tuple[float, ...]:
    """The 12 floats of [x, y, z, qx, qy, qz, qw] (quaternion normalised here)."""
    x, y, z, qx, qy, qz, qw = p
    return (*rows_from_quaternion(qx, qy, qz, qw), float(x), float(y), float(z))


def matrix4_from_pose(p) -> Array:
    """4x4 transform from [x, y, z, qx, qy, qz, qw] (quaternion normalised here)."""
    x, y, z, qx, qy, qz, qw = p
    r = rows_from_quaternion(qx, qy, qz, qw)
    return np.array([[r[0], r[1], r[2], x], [r[3], r[4], r[5], y], [r[6], r[7], r[8], z],
                     [0.0, 0.0, 0.0, 1.0]])


def pose_from_matrix4(T: Array) -> list[float]:
    """[x, y, z, qx, qy, qz, qw] (Python floats) of a 4x4 transform."""
    q = quaternion_from_matrix3(T[:3, :3])
    t = T[:3, 3].tolist()
    return [t[0], t[1], t[2], q[0], q[1], q[2], q[3]]


def angle_between3(R_a: Array, R_b: Array) -> float:
    """Angle (rad) of R_a^T R_b, accurate for small and large angles."""
    return 2.0 * math.asin(min(1.0, _half_sin(R_a.T @ R_b)))


def _half_sin(R: Array) -> float:
    x, y, z, _ = quaternion_from_matrix3(R)
    return math.sqrt(x * x + y * y + z * z)


def rows_from_rotvec(w0: float, w1: float, w2: float) -> tuple[float, ...]:
    """The 9 entries (row-major) of the rotation matrix of a rotation vector, as floats."""
    th2 = w0 * w0 + w1 * w1 + w2 * w2
    if th2 < 1e-16:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = math.sqrt(th2)
        a = math.sin(th) / th
        b = (1.0 - math.cos(th)) / th2
    return (1.0 - b * (w1 * w1 + w2 * w2), -a * w2 + b * w0 * w1, a * w1 + b * w0 * w2,
            a * w2 + b * w0 * w1, 1.0 - b * (w0 * w0 + w2 * w2), -a * w0 + b * w1 * w2,
            -a * w1 + b * w0 * w2, a * w0 + b * w1 * w2, 1.0 - b * (w0 * w0 + w1 * w1))


# --- flat transforms (Flat): 12 floats, rotation row-major then translation ---------
# The runtime tick keeps poses in this form: Python float arithmetic on 12 numbers costs
# less than numpy's per-call overhead on 4x4 arrays.


def flat_from_matrix4(T: Array) -> tuple[float, ...]:
    """The 12 floats of a 4x4 rigid transform."""
    (a, b, c, x), (d, e, f, y), (g, h, i, z), _ = T.tolist()
    return (a, b, c, d, e, f, g, h, i, x, y, z)


def matrix4_from_flat(F: tuple[float, ...]) -> Array:
    """The 4x4 transform of 12 floats."""
    a, b, c, d, e, f, g, h, i, x, y, z = F
    return np.array([[a, b, c, x], [d, e, f, y], [g, h, i, z], [0.0, 0.0, 0.0, 1.0]])


def compose_flat(A: tuple[float, ...], B: tuple[float, ...]) -> tuple[float, ...]:
    """A * B of two flat transforms."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8, ax, ay, az = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8, bx, by, bz = B
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
            a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8,
            a0 * bx + a1 * by + a2 * bz + ax, a3 * bx + a4 * by + a5 * bz + ay,
            a6 * bx + a7 * by + a8 * bz + az)


def invert_flat(A: tuple[float, ...]) -> tuple[float, ...]:
    """Inverse of a flat rigid transform (R^T, -R^T t)."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8, x, y, z = A
    return (a0, a3, a6, a1, a4, a7, a2, a5, a8,
            -(a0 * x + a3 * y + a6 * z), -(a1 * x + a4 * y + a7 * z), -(a2 * x + a5 * y + a8 * z))
