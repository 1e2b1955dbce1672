"""Safety limits applied last in every tick. Pure numpy.

These are the daemon's own guarantees, independent of what a skill asks for: per-tick
steps bounded by the maximum speeds (scaled by how far the user pushes), steps that
would take the target too far from the measured pose refused, and a robot state stream
that jumps or restarts detected (:class:`StateWatch`). (The controller refuses a
non-finite target, so the output is always finite.)
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from .. import se3

Array = NDArray[np.float64]


def interpolate(T_a: Array, T_b: Array, s: float) -> Array:
    """Pose a fraction ``s`` in [0, 1] of the way from T_a to T_b (translation linear,
    rotation along the geodesic about the frame's own origin)."""
    F_a, F_b = se3.flat_from_transform(T_a), se3.flat_from_transform(T_b)
    return se3.transform_from_flat(se3.interpolate_flat(F_a, F_b, s, se3.relative_quaternion_flat(F_a, F_b)))


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
    q = se3.relative_quaternion_flat(F_prev, F_new)
    dr = 2.0 * math.asin(min(1.0, math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2])))
    s = 1.0
    if dt > max_translation:
        s = max_translation / dt if dt > 0 else 0.0
    if dr > max_rotation:
        s = min(s, max_rotation / dr if dr > 0 else 0.0)
    if s >= 1.0:
        return F_new
    if s <= 0.0:
        return F_prev
    return se3.interpolate_flat(F_prev, F_new, s, q)


def grows_offset(F_prev: Flat, F_new: Flat, F_measured: Flat, max_translation: float,
                 max_rotation: float) -> bool:
    """Whether the step F_prev -> F_new (flat poses) takes the target's offset to the
    measured pose past ``max_translation`` (m) or ``max_rotation`` (rad) and further
    than it was: such a step is refused, so a blocked or lagging arm never winds up an
    unbounded target. A step that keeps or shrinks an offset already beyond a bound is
    allowed (the user can always back off), and the target is never dragged towards the
    measured pose: it moves only on input.

    All three poses may be given in any one frame: distance and angle do not depend on it.
    """
    d_new, cos_new = _separation(F_measured, F_new)
    far = d_new > max_translation
    turned = cos_new < math.cos(max_rotation)
    if not (far or turned):
        return False
    d_prev, cos_prev = _separation(F_measured, F_prev)
    return (far and d_new > d_prev) or (turned and cos_new < cos_prev)


def separation(F_a: Flat, F_b: Flat) -> tuple[float, float]:
    """Distance (m) between the origins of two flat poses and the angle (rad) between
    their orientations."""
    d, cos_r = _separation(F_a, F_b)
    return d, math.acos(max(-1.0, min(1.0, cos_r)))


def separated(F_a: Flat, F_b: Flat, max_translation: float, max_rotation: float) -> bool:
    """Whether two flat poses are further apart than ``max_translation`` (m) or
    ``max_rotation`` (rad)."""
    d, cos_r = _separation(F_a, F_b)
    return d > max_translation or cos_r < math.cos(max_rotation)


class StateWatch:
    """Continuity of the robot's state stream, judged message by message.

    Two consecutive states further apart than ``max_jump`` (m) or ``max_jump_rotation``
    (rad), or a ``seq`` that goes backwards (a restarted robot), are a discontinuity:
    :attr:`epoch` counts them, and :attr:`since` is the arrival time of the first state
    of the current continuous run. The runtime stops publishing targets at a new epoch
    and re-seeds at the measured pose once the run has lasted long enough.
    """

    def __init__(self, max_jump: float, max_jump_rotation: float):
        self.max_jump = max_jump
        self.max_jump_rotation = max_jump_rotation
        self.epoch = 0
        self.since = 0.0
        self._seq: int | None = None
        self._F: Flat | None = None

    def observe(self, seq: int, F: Flat, received: float) -> bool:
        """Take one valid state (flat ee pose F, world); True when it is discontinuous
        with the previous one."""
        prev_seq, prev_F = self._seq, self._F
        self._seq, self._F = seq, F
        if prev_F is None:
            self.since = received
            return False
        if seq < prev_seq or separated(prev_F, F, self.max_jump, self.max_jump_rotation):  # type: ignore[operator]
            self.epoch += 1
            self.since = received
            return True
        return False


def sanitize_input(u: tuple[float, ...] | list[float], deadband: float) -> tuple[tuple[float, ...], bool]:
    """User input -> (clipped command, ok). Non-finite input is a zero command (not ok);
    each axis is clipped to [-1, 1] and zeroed inside the dead band."""
    if not math.isfinite(sum(u)):  # NaN and inf propagate through the sum
        return (0.0,) * len(u), False
    return tuple([0.0 if abs(x) < deadband else (1.0 if x > 1.0 else -1.0 if x < -1.0 else x)
                  for x in u]), True
