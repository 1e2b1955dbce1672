"""The robot's own defence against discontinuous targets, as real arms have it
(libfranka refuses a command that jumps): whatever the runtime does, the simulated arm
follows a target only when it is near where the arm is and implies a speed it could
take, and never one stamped before the simulator started.

Pure Python on flat poses (:mod:`sctd.se3`); the ``sctd sim`` service and the kinematic
stand-in robot both use it. Its distance and angle between poses are its own, written
apart from the daemon's safety code (:mod:`sctd.runtime.safety`) and pinned by tests of
their own: a check on the runtime that shared the runtime's code would not be
independent of it. ``make lint`` forbids the simulator to import the runtime.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass, field

from sctd import se3
from sctd.app.options import add_arguments, check_ranges, from_namespace


def distance_and_angle(F_a: se3.Flat, F_b: se3.Flat) -> tuple[float, float]:
    """Distance (m) between the origins of two flat poses (row-major rotation, then
    translation) and the angle (rad, in [0, pi]) of the rotation between them.

    The angle of ``M = R_a^T R_b`` is ``atan2(|vee(M - M^T)| / 2, (tr M - 1) / 2)``:
    sine and cosine together, accurate near 0 and near pi alike.
    """
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = F_a[:9]
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = F_b[:9]
    # M[i][j] = sum_k R_a[k][i] R_b[k][j]: its trace and skew part, written out (the
    # guard runs on every target the robot receives)
    trace = a0 * b0 + a3 * b3 + a6 * b6 + a1 * b1 + a4 * b4 + a7 * b7 + a2 * b2 + a5 * b5 + a8 * b8
    sx = (a2 * b1 + a5 * b4 + a8 * b7) - (a1 * b2 + a4 * b5 + a7 * b8)  # M[2][1] - M[1][2]
    sy = (a0 * b2 + a3 * b5 + a6 * b8) - (a2 * b0 + a5 * b3 + a8 * b6)  # M[0][2] - M[2][0]
    sz = (a1 * b0 + a4 * b3 + a7 * b6) - (a0 * b1 + a3 * b4 + a6 * b7)  # M[1][0] - M[0][1]
    angle = math.atan2(0.5 * math.sqrt(sx * sx + sy * sy + sz * sz), 0.5 * (trace - 1.0))
    dx, dy, dz = F_b[9] - F_a[9], F_b[10] - F_a[10], F_b[11] - F_a[11]
    return math.sqrt(dx * dx + dy * dy + dz * dz), angle


def _limit(default: float, help: str):
    return field(default=default, metadata={"help": help})


@dataclass(frozen=True)
class TargetLimits:
    """What a target may ask of the arm. Each field is a ``sctd sim`` flag of the same
    name (``--max-target-offset``)."""

    max_target_offset: float = _limit(0.10, "m a target may be from the arm's pose")
    max_target_offset_rotation: float = _limit(0.5, "rad a target's orientation may be from the "
                                                    "arm's")
    max_target_speed: float = _limit(1.5, "m/s a target may imply from the previous one (above "
                                          "what teaching by hand needs)")
    max_target_angular_speed: float = _limit(4.0, "rad/s a target may imply from the previous one")


def add_limit_arguments(parser) -> None:
    """``--max-target-offset`` etc., from :class:`TargetLimits`."""
    add_arguments(parser, TargetLimits, show_default=True)


def limits_from_args(args) -> TargetLimits:
    """The TargetLimits of parsed flags; ValueError for a non-positive one."""
    limits = from_namespace(TargetLimits, args)
    check_ranges(limits)
    return limits


class TargetGuard:
    """Admits or refuses each target the robot receives.

    A target is refused (and the arm should hold where it is) when it is stamped before
    ``started`` or the last :meth:`restart` (``before_start``, unless ``stamp_check`` is
    off: a target sent before the arm was put back in a known posture, and delivered
    late, must not pull it away again), further from the
    measured pose than the offset limits (``offset``), or, while the arm is following
    targets, stamped no later than the previous accepted one (``out_of_order``) or
    further from it than the speed limits allow over the time between their stamps,
    at least one ``period`` (``speed``). :attr:`rejected` counts refusals by reason.

    Parameters
    ----------
    limits : TargetLimits
    period : float
        The robot's cycle, s: the shortest time a step is judged over (a late sender
        that catches up sends targets closer together than its period).
    started : float
        Unix time the robot started.
    stamp_check : bool
        Refuse targets stamped before ``started`` (needs synchronised clocks).
    """

    def __init__(self, limits: TargetLimits, period: float, started: float, stamp_check: bool = True):
        self.limits = limits
        self.period = period
        self.started = started
        self.stamp_check = stamp_check
        self.rejected: Counter[str] = Counter()
        self._last: tuple[se3.Flat, float] | None = None  # the last accepted target and stamp

    def restart(self, at: float) -> None:
        """The arm was put somewhere by other means at Unix time ``at``: refuse targets
        stamped before it, and judge the next one by its offset alone."""
        self.started = max(self.started, at)
        self._last = None

    def admit(self, pose: list[float], stamp: float, F_measured: se3.Flat, following: bool) -> bool:
        """Whether to follow the target ``pose`` (world) stamped ``stamp``, for the arm
        at ``F_measured`` (flat, world); ``following``: the arm tracks the previous
        accepted target (it is not holding)."""
        lim = self.limits
        F = se3.flat_from_pose(pose)
        reason = None
        if self.stamp_check and stamp < self.started:
            reason = "before_start"
        elif _beyond(distance_and_angle(F, F_measured), lim.max_target_offset,
                     lim.max_target_offset_rotation):
            reason = "offset"
        elif following and self._last is not None:
            F_prev, stamp_prev = self._last
            if stamp <= stamp_prev:
                reason = "out_of_order"
            else:
                dt = max(stamp - stamp_prev, self.period)
                if _beyond(distance_and_angle(F_prev, F), lim.max_target_speed * dt,
                           lim.max_target_angular_speed * dt):
                    reason = "speed"
        if reason is not None:
            self.rejected[reason] += 1
            self._last = None  # the arm holds: the next target is judged by its offset alone
            return False
        self._last = (F, stamp)
        return True

    @property
    def total_rejected(self) -> int:
        return sum(self.rejected.values())


def _beyond(d_angle: tuple[float, float], max_distance: float, max_angle: float) -> bool:
    return d_angle[0] > max_distance or d_angle[1] > max_angle
