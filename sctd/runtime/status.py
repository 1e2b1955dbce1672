"""The daemon's statistics and the status map it publishes (``docs/wire-contract.md``,
``status``).

:class:`TickStats` is what the loop measures on every tick (lateness, compute time, the
FSM state) and the status windows it closes; :class:`DaemonStatus` puts the status map
together from it and from the daemon's parts (the driver, the ticker, the target's puts, the
swap, ROS). Only :meth:`TickStats.account` runs on every tick.
"""

from __future__ import annotations

import logging
import time
from typing import Any

from ..skill import WORLD_OBJECT
from ..timing import Histogram, Ticker
from .driver import TickDriver
from .publisher import TargetOut
from .swap import SkillSwap

log = logging.getLogger("sctd.run")
RECENT = 1.0  # s: the window of the status' recent lateness and compute percentiles


class TickStats:
    """The tick loop's timing statistics: tick lateness and compute time since the start
    and over the last whole :data:`RECENT`-second window, and per status window its
    start, its largest compute time and the targets before it; the FSM state last seen
    (a change is logged).

    Parameters
    ----------
    now : float
        Monotonic time of the start (the first status is due then).
    state : str
        The FSM state at the start.
    status_period : float
        Seconds between status maps.
    targets : int
        Targets published before the start.
    """

    def __init__(self, now: float, state: str, status_period: float, targets: int = 0):
        self.lateness = Histogram()  # since start
        self.compute = Histogram()
        self.recent: dict[str, Any] | None = None  # summaries of the last whole RECENT window
        self.state = state
        self.status_period = status_period
        self.window_start = now
        self.window_targets = targets  # targets published before the status window
        self.compute_max = 0.0  # the status window's
        self.long_drains = 0  # drains over their allowance (:data:`~.loop.LONG_DRAIN`) since start
        self.next_status = now
        self._recent_lateness = Histogram()  # the current RECENT-second window
        self._recent_compute = Histogram()
        self._recent_start = now

    def account(self, lateness: float, compute: float, state: str) -> None:
        """One tick: its lateness and compute time (s) and the FSM state after it."""
        self.lateness.add(lateness)
        self.compute.add(compute)
        self._recent_lateness.add(lateness)
        self._recent_compute.add(compute)
        if compute > self.compute_max:
            self.compute_max = compute
        if state != self.state:
            log.info("state %s -> %s", self.state, state)
            self.state = state

    def roll_recent(self, now: float) -> None:
        """At a status window's close: the recent percentiles, once every :data:`RECENT` s."""
        if now - self._recent_start >= RECENT:
            self.recent = {"lateness": self._recent_lateness.summary_ms(),
                           "compute": self._recent_compute.summary_ms()}
            self._recent_lateness.clear()
            self._recent_compute.clear()
            self._recent_start = now

    def next_window(self, now: float, targets: int) -> None:
        """Start the next status window at ``now``, ``targets`` published before it."""
        self.window_start = now
        self.next_status = now + self.status_period
        self.window_targets = targets
        self.compute_max = 0.0


class DaemonStatus:
    """The daemon's status map (``docs/wire-contract.md``), from its parts.

    Parameters
    ----------
    driver : TickDriver
    stats : TickStats
    swap : SkillSwap
        Its refusals are ``counters.swaps_refused``.
    target : TargetOut, optional
        Its put times are ``publish_ms``.
    ros : optional
        ``sctd.wire.ros.RuntimeRos`` (``--ros``): its ``stats()`` are ``ros``.
    realtime : bool
        Whether the tick thread was granted SCHED_FIFO.
    io_nice : int
        The nice value the Zenoh session's own threads run at.
    """

    def __init__(self, driver: TickDriver, stats: TickStats, swap: SkillSwap,
                 target: TargetOut | None = None, ros: Any = None, realtime: bool = False,
                 io_nice: int = 0):
        self.driver, self.stats, self.swap = driver, stats, swap
        self.target, self.ros, self.realtime, self.io_nice = target, ros, realtime, io_nice
        # the engine's activity count when the last window closed: (engine, entries,
        # commands, acted); a window's activity is the count since
        self._activity_base: tuple[object, int, int, list[int]] | None = None

    def close_window(self, ticker: Ticker, now: float) -> dict[str, Any]:
        """The status map that closes a status window (and, each :data:`RECENT` s, the
        recent percentiles); the next window starts."""
        stats = self.stats
        stats.roll_recent(now)
        status = self.map(ticker, now, now - stats.window_start)
        stats.next_window(now, self.driver.target_seq)
        eng = self.driver.controller.engine
        self._activity_base = (eng, eng.entries, eng.commands, list(eng.acted))
        return status

    def activity(self) -> dict[str, Any]:
        """``status.constraints``: in the status window, the commands computed in the
        active state (since it was entered, if that was in the window) and, for each of
        its active constraints (the skill file's order), how many of them it changed:
        the constraint held the hand against the person's push."""
        eng = self.driver.controller.engine
        base = self._activity_base
        if base is not None and base[0] is eng and base[1] == eng.entries:
            commands = eng.commands - base[2]
            acted = [a - b for a, b in zip(eng.acted, base[3], strict=True)]
        else:
            commands, acted = eng.commands, list(eng.acted)
        return {"state": eng.state, "commands": commands, "acted": acted}

    def map(self, ticker: Ticker, now: float, window: float) -> dict[str, Any]:
        """The status map at ``now`` (monotonic), over a status window of ``window`` s
        (0: no target rate)."""
        drv = self.driver
        ctl = drv.controller
        c = ctl.counters
        obj = drv.objects.get(ctl.engine.object)
        last = drv.inputs.last

        def age(received: float | None) -> float | None:
            return None if received is None else round(now - received, 6)

        wall, state = time.time(), drv.state
        status: dict[str, Any] = {
            "stamp": wall,
            "skill": ctl.skill.id,
            "skill_name": ctl.skill.name,
            "state": ctl.engine.state,
            "finished": ctl.engine.finished,
            "stuck": ctl.stuck(now),
            "region": drv.region(),
            "mode": ctl.mode,
            "mode_button": ctl.engine.leads_to(),
            "rate": ctl.config.rate,
            "realtime": self.realtime,
            "io_nice": self.io_nice,
            **self._timing(ticker, window),
            "input_age": age(last.received if last is not None else None),
            "state_age": age(drv.state.received if drv.state is not None else None),
            "state_delay_ms": None if state is None else _delay_ms(wall, now, state.stamp, state.received),
            "input_delay_ms": _delay_ms(wall, now, last.msg.stamp, last.received)
            if last is not None and last.msg is not None else None,
            "robot_fault": drv.state.fault if drv.state is not None else None,
            "object": ctl.engine.object,
            "object_age": age(obj.received if obj is not None else None),
            "objects": {n: age(o.received) if (o := drv.objects.get(n)) is not None else None
                        for n in ctl.skill.objects() if n != WORLD_OBJECT},
            "in_seq": last.msg.seq if last is not None and last.msg is not None else -1,
            "input": drv.inputs.summary(),
            "gripper": drv.gripper.status(now, drv.inputs.ignored_grasps),
            "vf_scale": ctl.engine.last_scale,
            "constraints": self.activity(),
            "dropped": dict(c.drops),
            "counters": {**c.as_dict(), "swaps_refused": self.swap.refused},
        }
        if drv.goals is not None:  # a skill set (docs/wire-contract.md, status.goals)
            status["goals"] = {"name": self.swap.set_name, **drv.goals.status()}
        if self.ros is not None:
            status["ros"] = self.ros.stats()
        return status


    def _timing(self, ticker: Ticker, window: float) -> dict[str, Any]:
        """The status map's tick counts and timing statistics (:meth:`map`)."""
        stats, seq = self.stats, self.driver.target_seq
        return {
            "ticks": ticker.ticks,
            "late_ticks": ticker.late,
            "skipped_ticks": ticker.skipped,
            "long_drains": stats.long_drains,
            "targets": seq,
            "target_rate": round((seq - stats.window_targets) / window, 1) if window > 0 else None,
            "lateness_ms": stats.lateness.summary_ms(),
            "compute_ms": stats.compute.summary_ms(),
            "publish_ms": self.target.put_time.summary_ms() if self.target is not None else None,
            "compute_max_window_ms": round(stats.compute_max * 1e3, 4),
            "recent_ms": stats.recent,
        }


def _delay_ms(wall: float, now: float, stamp: float, received: float) -> float:
    """ms from a message's ``stamp`` (its sender's clock) to its arrival (``received``, on
    the monotonic clock whose ``now`` is Unix time ``wall``): the link's delay, where the
    clocks agree."""
    return round(1e3 * ((wall - stamp) - (now - received)), 1)
