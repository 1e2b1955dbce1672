"""Faults of a real link, as a schedule: :class:`LinkFault` (what the link does) and
:class:`Schedule` (when each chunk of bytes or datagram comes out of it).

A wheelchair's input device, tablet and runtime reach the robot computer over Wi-Fi or a
USB-Ethernet link, which delay, jitter, stall and drop. The kernels sctd is tested on may
lack ``netem``, so :mod:`sctd.deploy.linkproxy` makes these faults in user space, between
a listening address and a target, one :class:`Schedule` per direction of each connection.
This module is the pure part: no sockets, no threads, no clock of its own; every time is
in seconds since the proxy started.

The rules, for one direction of one TCP connection (a byte stream) or one UDP flow:

- a chunk arriving at ``t`` leaves at ``t + delay``, ``delay`` drawn uniformly within
  ``delay_ms`` +- the jitter (never below 0), but never before the chunk before it: jitter
  delays chunks, it never reorders a stream;
- with a ``bandwidth`` (bytes/s) a chunk of ``n`` bytes occupies the link ``n /
  bandwidth`` s after the link is free (and not stalled), and leaves after that and its
  delay: after a stall, what it held drains at the bandwidth;
- a stall ``(at, for)`` holds whatever would leave within ``[at, at + for)`` and releases
  it, in order, at ``at + for`` (nothing is lost: TCP does not lose data);
- ``loss`` is the probability that a datagram is dropped (UDP only: a TCP stream loses
  nothing);
- ``resets`` are times at which every connection is closed, on both sides (the proxy does
  that; the schedule only lists them).

The draws come from generators seeded with ``(seed, direction, stream)``, so a seed and a
spec give the same release times and the same dropped datagrams on every run.
"""

from __future__ import annotations

import math
import random
from dataclasses import asdict, dataclass, field
from typing import Any

DIRECTIONS = ("up", "down")  # up: from the connecting side to the target; down: back


def _number(name: str, value: Any, lo: float = 0.0, hi: float = math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) \
            or not lo <= value <= hi:
        raise ValueError(f"LinkFault.{name}: expected a number in [{lo:g}, {hi:g}], got {value!r}")
    return float(value)


@dataclass(frozen=True)
class LinkFault:
    """What one direction of a link does to what passes through it.

    Parameters
    ----------
    delay_ms : float
        Added to every chunk (ms).
    jitter : float
        Half-width of the uniform spread of the delay as a fraction of ``delay_ms``
        (0.2: 20 ms +- 4 ms); at most 1.
    jitter_ms : float
        The same half-width in ms (give ``jitter`` or ``jitter_ms``, not both).
    loss : float
        Probability in [0, 1] that a datagram is dropped (UDP; a TCP stream loses nothing).
    stalls : tuple of (at, for)
        Stalls: from ``at`` s after the proxy starts, for ``for`` s, nothing leaves; what
        was held leaves in order when the stall ends.
    bandwidth : float
        Bytes per second (0: unlimited).
    resets : tuple of float
        Times (s after the proxy starts) at which every connection is reset on both sides.
    seed : int
        Seeds the jitter and the loss.
    """

    delay_ms: float = 0.0
    jitter: float = 0.0
    jitter_ms: float = 0.0
    loss: float = 0.0
    stalls: tuple[tuple[float, float], ...] = ()
    bandwidth: float = 0.0
    resets: tuple[float, ...] = ()
    seed: int = 0

    def __post_init__(self) -> None:
        _number("delay_ms", self.delay_ms)
        _number("jitter", self.jitter, 0.0, 1.0)
        _number("jitter_ms", self.jitter_ms)
        if self.jitter and self.jitter_ms:
            raise ValueError("LinkFault.jitter, jitter_ms: give one of them, not both")
        _number("loss", self.loss, 0.0, 1.0)
        _number("bandwidth", self.bandwidth)
        for k, s in enumerate(self.stalls):
            if not isinstance(s, tuple | list) or len(s) != 2:
                raise ValueError(f"LinkFault.stalls[{k}]: expected (at, for) in s, got {s!r}")
            _number(f"stalls[{k}].at", s[0])
            _number(f"stalls[{k}].for", s[1])
        object.__setattr__(self, "stalls", tuple((float(a), float(d)) for a, d in self.stalls))
        for k, t in enumerate(self.resets):
            _number(f"resets[{k}]", t)
        object.__setattr__(self, "resets", tuple(float(t) for t in self.resets))
        if type(self.seed) is not int:
            raise ValueError(f"LinkFault.seed: expected an integer, got {self.seed!r}")

    @property
    def jitter_s(self) -> float:
        """The half-width of the delay's spread (s)."""
        return (self.jitter * self.delay_ms + self.jitter_ms) / 1e3

    def to_dict(self) -> dict[str, Any]:
        """The fields as plain JSON values (what :meth:`from_dict` reads)."""
        d = asdict(self)
        d["stalls"] = [list(s) for s in self.stalls]
        d["resets"] = list(self.resets)
        return d

    @classmethod
    def from_dict(cls, d: Any) -> LinkFault:
        """A fault from a map of its fields; ValueError naming an unknown or bad field."""
        if not isinstance(d, dict):
            raise ValueError(f"LinkFault: expected a map of its fields, got {d!r}")
        known = {f for f in cls.__dataclass_fields__}
        unknown = sorted(map(str, set(d) - known))
        if unknown:
            raise ValueError(f"LinkFault.{unknown[0]}: unknown field (known: {', '.join(sorted(known))})")
        kw = dict(d)
        if "stalls" in kw:
            kw["stalls"] = tuple(tuple(s) if isinstance(s, list) else s for s in kw["stalls"])
        if "resets" in kw:
            kw["resets"] = tuple(kw["resets"])
        return cls(**kw)


@dataclass
class Direction:
    """One direction of a proxy: its current fault (replaced while running) and the
    stalls started while running (``(at, for)``, beside the fault's own)."""

    fault: LinkFault = field(default_factory=LinkFault)
    stalls: list[tuple[float, float]] = field(default_factory=list)

    def stall_end(self, t: float) -> float:
        """When the stall covering ``t`` ends (``t`` itself when none does); stalls that
        touch are crossed together."""
        intervals = sorted((*self.fault.stalls, *self.stalls))
        moved = True
        while moved:
            moved = False
            for at, dur in intervals:
                if at <= t < at + dur:
                    t, moved = at + dur, True
        return t

    def stalled_within(self, t0: float, t1: float) -> bool:
        """Whether a stall overlaps ``[t0, t1)``."""
        return any(at < t1 and at + dur > t0 for at, dur in (*self.fault.stalls, *self.stalls))

    def stalls_begun(self, t: float) -> int:
        """How many stalls have begun by ``t``."""
        return sum(1 for at, _ in (*self.fault.stalls, *self.stalls) if at <= t)


class Schedule:
    """Release times of the chunks of one direction of one stream, in arrival order.

    Parameters
    ----------
    direction : Direction
        Shared by every stream of the proxy in that direction (a change of its fault or
        a stall started applies to the next chunk of each).
    name : str
        ``up`` or ``down``; with ``stream`` (the connection's or flow's number, from 0)
        and the fault's seed it seeds the draws.
    """

    def __init__(self, direction: Direction, name: str = "up", stream: int = 0):
        seed = direction.fault.seed
        self.direction = direction
        self._jitter = random.Random(f"{seed}/{name}/{stream}/jitter")
        self._loss = random.Random(f"{seed}/{name}/{stream}/loss")
        self._last = -math.inf  # release of the chunk before
        self._free = -math.inf  # when the link has sent the chunk before (bandwidth)
        self.held = False  # whether a stall held the last chunk (or one it waited behind)

    def release(self, t: float, nbytes: int) -> float:
        """When a chunk of ``nbytes`` arriving at ``t`` leaves (s, not before ``t``, not
        before the chunk before it, outside every stall)."""
        f = self.direction.fault
        delay = f.delay_ms / 1e3
        if f.jitter_s > 0:
            delay = max(0.0, delay + self._jitter.uniform(-f.jitter_s, f.jitter_s))
        # a stalled link sends nothing: what it held goes out at its bandwidth after the stall
        start = self.direction.stall_end(max(t, self._free)) if f.bandwidth > 0 else t
        self._free = start + (nbytes / f.bandwidth if f.bandwidth > 0 else 0.0)
        out = self.direction.stall_end(max(self._free + delay, self._last))
        # held: it waited longer than its own delay and sending take, and a stall fell
        # within its wait (not a chunk that only waited behind others)
        alone = t + delay + (nbytes / f.bandwidth if f.bandwidth > 0 else 0.0)
        self.held = out > alone + 1e-9 and self.direction.stalled_within(t, out)
        self._last = out
        return out

    def drops(self) -> bool:
        """Whether the next datagram is lost (one draw per datagram)."""
        loss = self.direction.fault.loss
        return loss > 0 and self._loss.random() < loss
