"""The robot's own defence against discontinuous targets, as real arms have it
(libfranka refuses a command that jumps): whatever the runtime does, the simulated arm
follows a target only when it is near where the arm is and implies a speed it could
take, and never one stamped before the simulator started.

Pure Python on flat poses (:mod:`sctd.se3`); the ``sctd sim`` service and the kinematic
stand-in robot both use it.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, fields

from sctd import se3
from sctd.runtime.safety import separated, separation


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
    for f in fields(TargetLimits):
        parser.add_argument(f"--{f.name.replace('_', '-')}", type=float, default=f.default,
                            help=f"{f.metadata['help']} (default %(default)s)")


def limits_from_args(args) -> TargetLimits:
    """The TargetLimits of parsed flags; ValueError for a non-positive one."""
    kw = {f.name: getattr(args, f.name) for f in fields(TargetLimits)}
    for name, value in kw.items():
        if not value > 0:
            raise ValueError(f"--{name.replace('_', '-')} must be > 0")
    return TargetLimits(**kw)


class TargetGuard:
    """Admits or refuses each target the robot receives.

    A target is refused (and the arm should hold where it is) when it is stamped before
    ``started`` (``before_start``, unless ``stamp_check`` is off), further from the
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

    def admit(self, pose: list[float], stamp: float, F_measured: se3.Flat, following: bool) -> bool:
        """Whether to follow the target ``pose`` (world) stamped ``stamp``, for the arm
        at ``F_measured`` (flat, world); ``following``: the arm tracks the previous
        accepted target (it is not holding)."""
        lim = self.limits
        F = se3.flat_from_pose(pose)
        reason = None
        if self.stamp_check and stamp < self.started:
            reason = "before_start"
        elif separated(F, F_measured, lim.max_target_offset, lim.max_target_offset_rotation):
            reason = "offset"
        elif following and self._last is not None:
            F_prev, stamp_prev = self._last
            if stamp <= stamp_prev:
                reason = "out_of_order"
            else:
                dt = max(stamp - stamp_prev, self.period)
                d, angle = separation(F_prev, F)
                if d > lim.max_target_speed * dt or angle > lim.max_target_angular_speed * dt:
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
