"""Safety limits applied last in every tick (DESIGN §7 step 6). Pure numpy.

These are the daemon's own guarantees, independent of what a skill asks for: per-tick
steps bounded by the maximum speeds (scaled by how far the user pushes), the target kept
within a bounded offset of the measured pose, and the output always finite.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .. import se3

Array = NDArray[np.float64]


def rotation_angle_between(R_a: Array, R_b: Array) -> float:
    """Angle (rad) of the rotation ``R_a^T R_b``; cheap and clamped."""
    c = (float(np.sum(R_a * R_b)) - 1.0) * 0.5  # trace(R_a^T R_b) = sum of elementwise products
    if c > 0.99999:
        # Small angles: the trace loses precision; use the skew part instead.
        S = R_a.T @ R_b
        s = 0.5 * math.sqrt((S[2, 1] - S[1, 2]) ** 2 + (S[0, 2] - S[2, 0]) ** 2 + (S[1, 0] - S[0, 1]) ** 2)
        return math.asin(min(1.0, s))
    return math.acos(max(-1.0, c))


def interpolate(T_a: Array, T_b: Array, s: float) -> Array:
    """Pose a fraction ``s`` in [0, 1] of the way from T_a to T_b (translation linear,
    rotation along the geodesic about the frame's own origin)."""
    out = T_a.copy()
    out[:3, 3] = T_a[:3, 3] + s * (T_b[:3, 3] - T_a[:3, 3])
    w = se3.rotvec_from_matrix(T_a[:3, :3].T @ T_b[:3, :3])
    out[:3, :3] = T_a[:3, :3] @ se3.matrix_from_rotvec(s * w)
    return out


def limit_step(T_prev: Array, T_new: Array, max_translation: float, max_rotation: float) -> Array:
    """Scale the step T_prev -> T_new uniformly so that the translation is at most
    ``max_translation`` (m) and the rotation at most ``max_rotation`` (rad).

    Scaling both parts by one factor keeps the direction of motion (an orbit about a
    feature frame stays an orbit), where clipping each separately would bend it.
    """
    dt = float(np.linalg.norm(T_new[:3, 3] - T_prev[:3, 3]))
    dr = rotation_angle_between(T_prev[:3, :3], T_new[:3, :3])
    s = 1.0
    if dt > max_translation:
        s = max_translation / dt if dt > 0 else 0.0
    if dr > max_rotation:
        s = min(s, max_rotation / dr if dr > 0 else 0.0)
    if s >= 1.0:
        return T_new
    if s <= 0.0:
        return T_prev.copy()
    return interpolate(T_prev, T_new, s)


def limit_offset(T_target: Array, T_measured: Array, max_translation: float,
                 max_rotation: float) -> Array:
    """Keep the target within ``max_translation`` (m) and ``max_rotation`` (rad) of the
    measured pose, so a blocked or lagging arm never winds up an unbounded target."""
    d = T_target[:3, 3] - T_measured[:3, 3]
    n = float(np.linalg.norm(d))
    ang = rotation_angle_between(T_measured[:3, :3], T_target[:3, :3])
    if n <= max_translation and ang <= max_rotation:
        return T_target
    out = T_target.copy()
    if n > max_translation:
        out[:3, 3] = T_measured[:3, 3] + d * (max_translation / n)
    if ang > max_rotation:
        w = se3.rotvec_from_matrix(T_measured[:3, :3].T @ T_target[:3, :3])
        out[:3, :3] = T_measured[:3, :3] @ se3.matrix_from_rotvec(w * (max_rotation / ang))
    return out


def is_finite_transform(T: Array) -> bool:
    """True when every entry is finite and the rotation part is orthonormal."""
    if not np.all(np.isfinite(T)):
        return False
    R = T[:3, :3]
    return bool(np.allclose(R.T @ R, np.eye(3), atol=1e-6))


def sanitize_input(u: tuple[float, ...] | list[float], deadband: float) -> tuple[Array, bool]:
    """User input -> (clipped command, ok). Non-finite input is a zero command (not ok);
    each axis is clipped to [-1, 1] and zeroed inside the dead band."""
    a = np.array(u, dtype=float)
    if not np.all(np.isfinite(a)):
        return np.zeros(len(a)), False
    np.clip(a, -1.0, 1.0, out=a)
    a[np.abs(a) < deadband] = 0.0
    return a, True
