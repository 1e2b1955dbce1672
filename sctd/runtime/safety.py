"""Safety limits applied last in every tick (DESIGN §7 step 6). Pure numpy.

These are the daemon's own guarantees, independent of what a skill asks for: per-tick
steps bounded by the maximum speeds (scaled by how far the user pushes), the target kept
within a bounded offset of the measured pose. (The controller refuses a non-finite
target, so the output is always finite.)
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .. import se3

Array = NDArray[np.float64]


def rotation_angle_between(R_a: Array, R_b: Array) -> float:
    """Angle (rad) of the rotation ``R_a^T R_b``."""
    return se3.angle_between3(R_a, R_b)


def interpolate(T_a: Array, T_b: Array, s: float) -> Array:
    """Pose a fraction ``s`` in [0, 1] of the way from T_a to T_b (translation linear,
    rotation along the geodesic about the frame's own origin)."""
    out = T_a.copy()
    out[:3, 3] = T_a[:3, 3] + s * (T_b[:3, 3] - T_a[:3, 3])
    w0, w1, w2 = se3.rotvec_from_matrix3(T_a[:3, :3].T @ T_b[:3, :3])
    out[:3, :3] = T_a[:3, :3] @ se3.matrix3_from_rotvec(s * w0, s * w1, s * w2)
    return out


Flat = se3.Flat


def _separation(A: Flat, B: Flat) -> tuple[float, float]:
    """Distance between the origins of two flat poses and the cosine of the angle of
    ``R_a^T R_b`` (from its trace: cos = (trace - 1) / 2)."""
    a0, a1, a2, a3, a4, a5, a6, a7, a8, ax, ay, az = A
    b0, b1, b2, b3, b4, b5, b6, b7, b8, bx, by, bz = B
    dx, dy, dz = bx - ax, by - ay, bz - az
    trace = (a0 * b0 + a1 * b1 + a2 * b2 + a3 * b3 + a4 * b4 + a5 * b5
             + a6 * b6 + a7 * b7 + a8 * b8)
    return math.sqrt(dx * dx + dy * dy + dz * dz), (trace - 1.0) * 0.5


def limit_step(F_prev: Flat, F_new: Flat, max_translation: float, max_rotation: float) -> Flat:
    """Scale the step F_prev -> F_new (flat poses) uniformly so that the translation is
    at most ``max_translation`` (m) and the rotation at most ``max_rotation`` (rad).
    Returns F_new itself when it is within the bounds.

    Scaling both parts by one factor keeps the direction of motion (an orbit about a
    feature frame stays an orbit), where clipping each separately would bend it.
    """
    dt, cos_r = _separation(F_prev, F_new)
    # A mapped step that equals the bound exactly must not lose to it by an ulp.
    if dt <= max_translation * (1.0 + 1e-9) and cos_r >= math.cos(max_rotation * (1.0 + 1e-9)):
        return F_new
    T_prev, T_new = se3.matrix4_from_flat(F_prev), se3.matrix4_from_flat(F_new)
    dr = rotation_angle_between(T_prev[:3, :3], T_new[:3, :3])
    s = 1.0
    if dt > max_translation:
        s = max_translation / dt if dt > 0 else 0.0
    if dr > max_rotation:
        s = min(s, max_rotation / dr if dr > 0 else 0.0)
    if s >= 1.0:
        return F_new
    if s <= 0.0:
        return F_prev
    return se3.flat_from_matrix4(interpolate(T_prev, T_new, s))


def limit_offset(F_target: Flat, F_measured: Flat, max_translation: float,
                 max_rotation: float) -> Flat:
    """Keep the target within ``max_translation`` (m) and ``max_rotation`` (rad) of the
    measured pose (flat poses), so a blocked or lagging arm never winds up an unbounded
    target. Returns F_target itself when it is within the bounds.

    Both poses may be given in any one frame: distance and angle do not depend on it."""
    n, cos_r = _separation(F_measured, F_target)
    if n <= max_translation and cos_r >= math.cos(max_rotation):
        return F_target
    T_target, T_measured = se3.matrix4_from_flat(F_target), se3.matrix4_from_flat(F_measured)
    ang = rotation_angle_between(T_measured[:3, :3], T_target[:3, :3])
    out = T_target.copy()
    if n > max_translation:
        d = T_target[:3, 3] - T_measured[:3, 3]
        out[:3, 3] = T_measured[:3, 3] + d * (max_translation / n)
    if ang > max_rotation:
        w0, w1, w2 = se3.rotvec_from_matrix3(T_measured[:3, :3].T @ T_target[:3, :3])
        k = max_rotation / ang
        out[:3, :3] = T_measured[:3, :3] @ se3.matrix3_from_rotvec(k * w0, k * w1, k * w2)
    return se3.flat_from_matrix4(out)


def sanitize_input(u: tuple[float, ...] | list[float], deadband: float) -> tuple[tuple[float, ...], bool]:
    """User input -> (clipped command, ok). Non-finite input is a zero command (not ok);
    each axis is clipped to [-1, 1] and zeroed inside the dead band."""
    if not math.isfinite(sum(u)):  # NaN and inf propagate through the sum
        return (0.0,) * len(u), False
    return tuple([0.0 if abs(x) < deadband else (1.0 if x > 1.0 else -1.0 if x < -1.0 else x)
                  for x in u]), True
