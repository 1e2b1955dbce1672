"""Single-transform fast paths for the real-time tick: the :class:`Flat` transform.

numpy's per-call overhead dominates on 3x3 and 4x4 arrays, so the runtime tick keeps
each pose as a :class:`Flat` (12 Python floats) and the functions here use scalar
``math`` and build at most one small array each. The vectorised functions of
:mod:`sctd.se3._rotations` and :mod:`sctd.se3._transforms` are for batches of poses
(learning, evaluation); conversions between the two forms are
:func:`flat_from_transform` and :func:`transform_from_flat`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


Flat = tuple[float, float, float, float, float, float, float, float, float, float, float, float]
"""A rigid transform as exactly 12 floats: the rotation row-major, then the translation.

``(r00, r01, r02, r10, r11, r12, r20, r21, r22, x, y, z)`` is the 4x4 matrix
``[[r00, r01, r02, x], [r10, r11, r12, y], [r20, r21, r22, z], [0, 0, 0, 1]]``:
``F[:9]`` is the rotation, ``F[9:]`` the translation. A plain tuple on purpose (the
type checker knows its length): CPython unpacks and builds exact tuples on a fast
path, and a NamedTuple with the same fields made the tick's command 10-30 % slower
(75 ns more per unpacking, 165 ns per construction, dozens of each per tick).
"""

FLAT_IDENTITY: Flat = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0)


def quaternion_from_flat(F: Flat) -> tuple[float, float, float, float]:
    """Unit quaternion of a flat transform's rotation (Shepperd's method).

    Parameters
    ----------
    F : Flat
        Only its rotation (the first nine entries) is read.

    Returns
    -------
    tuple of 4 floats
        (qx, qy, qz, qw) with qw >= 0. Every branch reads all nine entries, so a
        non-finite entry gives a non-finite quaternion.
    """
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = F[:9]
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


def flat_from_pose(p: Sequence[float]) -> Flat:
    """Flat transform of a pose.

    Parameters
    ----------
    p : sequence of 7 floats
        [x, y, z, qx, qy, qz, qw]; the quaternion is normalised here (it must not be
        zero).

    Returns
    -------
    Flat
    """
    x, y, z, qx, qy, qz, qw = p
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    qx, qy, qz, qw = qx / n, qy / n, qz / n, qw / n
    return (1 - 2 * (qy * qy + qz * qz), 2 * (qx * qy - qw * qz), 2 * (qx * qz + qw * qy),
                       2 * (qx * qy + qw * qz), 1 - 2 * (qx * qx + qz * qz), 2 * (qy * qz - qw * qx),
                       2 * (qx * qz - qw * qy), 2 * (qy * qz + qw * qx), 1 - 2 * (qx * qx + qy * qy),
                       float(x), float(y), float(z))


def pose_from_flat(F: Flat) -> list[float]:
    """Pose of a flat transform: the inverse of :func:`flat_from_pose`.

    Returns
    -------
    list of 7 floats
        [x, y, z, qx, qy, qz, qw] with qw >= 0.
    """
    qx, qy, qz, qw = quaternion_from_flat(F)
    return [F[9], F[10], F[11], qx, qy, qz, qw]


def flat_from_rotvec(w0: float, w1: float, w2: float) -> Flat:
    """Flat transform of a rotation vector's rotation (Rodrigues), without translation.

    Parameters
    ----------
    w0, w1, w2 : float
        Rotation vector (axis times angle, rad).

    Returns
    -------
    Flat
        Rotation ``exp([w])``, translation zero.
    """
    th2 = w0 * w0 + w1 * w1 + w2 * w2
    if th2 < 1e-16:
        a, b = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = math.sqrt(th2)
        a = math.sin(th) / th
        b = (1.0 - math.cos(th)) / th2
    return (1.0 - b * (w1 * w1 + w2 * w2), -a * w2 + b * w0 * w1, a * w1 + b * w0 * w2,
                       a * w2 + b * w0 * w1, 1.0 - b * (w0 * w0 + w2 * w2), -a * w0 + b * w1 * w2,
                       -a * w1 + b * w0 * w2, a * w0 + b * w1 * w2, 1.0 - b * (w0 * w0 + w1 * w1),
                       0.0, 0.0, 0.0)


def flat_from_transform(T: Array) -> Flat:
    """Flat transform of a 4x4 matrix.

    Parameters
    ----------
    T : ndarray, shape (4, 4)
        A rigid transform (its last row is not read).

    Returns
    -------
    Flat
    """
    (a, b, c, x), (d, e, f, y), (g, h, i, z), _ = T.tolist()
    return (a, b, c, d, e, f, g, h, i, x, y, z)


def transform_from_flat(F: Flat) -> Array:
    """4x4 matrix of a flat transform.

    Returns
    -------
    ndarray, shape (4, 4)
        A new array.
    """
    a, b, c, d, e, f, g, h, i, x, y, z = F
    # (from one flat tuple: a third cheaper than from nested lists)
    return np.array((a, b, c, x, d, e, f, y, g, h, i, z, 0.0, 0.0, 0.0, 1.0)).reshape(4, 4)


def compose_flat(A: Flat, B: Flat) -> Flat:
    """Product of two flat transforms: ``A @ B`` as 4x4 matrices.

    Parameters
    ----------
    A, B : Flat
        E.g. ``T_a_b`` and ``T_b_c``.

    Returns
    -------
    Flat
        ``T_a_c``.
    """
    a0, a1, a2, a3, a4, a5, a6, a7, a8, ax, ay, az = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8, bx, by, bz = B
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
                       a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
                       a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8,
                       a0 * bx + a1 * by + a2 * bz + ax, a3 * bx + a4 * by + a5 * bz + ay,
                       a6 * bx + a7 * by + a8 * bz + az)


def invert_flat(A: Flat) -> Flat:
    """Inverse of a flat rigid transform, ``[R^T, -R^T t]`` (``T_a_b`` -> ``T_b_a``)."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8, x, y, z = A
    return (a0, a3, a6, a1, a4, a7, a2, a5, a8,
                       -(a0 * x + a3 * y + a6 * z), -(a1 * x + a4 * y + a7 * z), -(a2 * x + a5 * y + a8 * z))


def translate_flat(F: Flat, dx: float, dy: float, dz: float) -> Flat:
    """A flat transform moved by (dx, dy, dz) (m, in its parent's axes), its rotation
    unchanged: ``Trans(d) @ F``."""
    return (*F[:9], F[9] + dx, F[10] + dy, F[11] + dz)


def flat_rotation_about(R: Sequence[float], px: float, py: float, pz: float) -> Flat:
    """The rotation ``R`` about the point p, ``[R, p - R p]``.

    Parameters
    ----------
    R : sequence of at least 9 floats
        The rotation, row-major (a Flat's translation, if given, is ignored).
    px, py, pz : float
        The point that stays where it is.
    """
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = R[:9]
    return (r00, r01, r02, r10, r11, r12, r20, r21, r22,
                       px - (r00 * px + r01 * py + r02 * pz), py - (r10 * px + r11 * py + r12 * pz),
                       pz - (r20 * px + r21 * py + r22 * pz))


def compose_quaternions(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float, float]:
    """Hamilton product ``a * b`` of two quaternions (rotation b, then a), on floats.

    Parameters
    ----------
    a, b : sequence of 4 floats
        Quaternions (x, y, z, w).

    Returns
    -------
    tuple of 4 floats
        (x, y, z, w), not normalised and not sign-canonicalised.
    """
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def relative_quaternion_flat(F_a: Flat, F_b: Flat) -> tuple[float, float, float, float]:
    """The unit quaternion (x, y, z, w; w >= 0) of ``R_a^T R_b``: the rotation from F_a's
    orientation to F_b's, in F_a's axes (translations ignored)."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = F_a[:9]
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = F_b[:9]
    return quaternion_from_flat((
        a0 * b0 + a3 * b3 + a6 * b6, a0 * b1 + a3 * b4 + a6 * b7, a0 * b2 + a3 * b5 + a6 * b8,
        a1 * b0 + a4 * b3 + a7 * b6, a1 * b1 + a4 * b4 + a7 * b7, a1 * b2 + a4 * b5 + a7 * b8,
        a2 * b0 + a5 * b3 + a8 * b6, a2 * b1 + a5 * b4 + a8 * b7, a2 * b2 + a5 * b5 + a8 * b8,
        0.0, 0.0, 0.0))


def interpolate_flat(F_a: Flat, F_b: Flat, s: float, q_ab: Sequence[float]) -> Flat:
    """The pose a fraction ``s`` of the way from F_a to F_b: the origin on the straight
    line, the rotation ``R_a exp(s log(R_a^T R_b))`` (the geodesic about the frame's own
    origin).

    Parameters
    ----------
    F_a, F_b : Flat
    s : float
        In [0, 1].
    q_ab : sequence of 4 floats
        :func:`relative_quaternion_flat` of F_a and F_b.
    """
    x, y, z, w = q_ab
    n = math.sqrt(x * x + y * y + z * z)  # the rotation vector of q_ab, as rotvec_from_matrix3
    k = 2.0 / w if n < 1e-12 else 2.0 * math.atan2(n, w) / n
    a0, a1, a2, a3, a4, a5, a6, a7, a8, ax, ay, az = F_a
    b0, b1, b2, b3, b4, b5, b6, b7, b8, _, _, _ = flat_from_rotvec(s * (x * k), s * (y * k), s * (z * k))
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
            a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8,
            ax + s * (F_b[9] - ax), ay + s * (F_b[10] - ay), az + s * (F_b[11] - az))


def _flat_from_matrix3(R: Array) -> Flat:
    (a, b, c), (d, e, f), (g, h, i) = R.tolist()
    return (a, b, c, d, e, f, g, h, i, 0.0, 0.0, 0.0)


def rotvec_from_matrix3(R: Array) -> tuple[float, float, float]:
    """Rotation vector of one rotation matrix, on floats.

    Parameters
    ----------
    R : ndarray, shape (3, 3)

    Returns
    -------
    tuple of 3 floats
        Axis times angle, angle in [0, pi].
    """
    x, y, z, w = quaternion_from_flat(_flat_from_matrix3(R))
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        k = 2.0 / w
    else:
        k = 2.0 * math.atan2(s, w) / s
    return x * k, y * k, z * k


def matrix3_from_rotvec(w0: float, w1: float, w2: float) -> Array:
    """Rotation matrix of one rotation vector (Rodrigues).

    Parameters
    ----------
    w0, w1, w2 : float
        Rotation vector (axis times angle, rad).

    Returns
    -------
    ndarray, shape (3, 3)
    """
    r = flat_from_rotvec(w0, w1, w2)
    return np.array([r[0:3], r[3:6], r[6:9]])


def angle_between3(R_a: Array, R_b: Array) -> float:
    """Angle between two orientations, accurate for small and large angles.

    Parameters
    ----------
    R_a, R_b : ndarray, shape (3, 3)
        Rotation matrices.

    Returns
    -------
    float
        The angle (rad, in [0, pi]) of ``R_a^T R_b``.
    """
    x, y, z, _ = quaternion_from_flat(_flat_from_matrix3(R_a.T @ R_b))
    return 2.0 * math.asin(min(1.0, math.sqrt(x * x + y * y + z * z)))
