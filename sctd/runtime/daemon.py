"""``sctd run``: the fixed-rate daemon wired to Zenoh.

:class:`Daemon` composes the parts of a run and owns what it opens, all on one exit
stack:

- :class:`~.loop.TickLoop`: the tick, on the main thread, which reads its inputs itself.
  Input, state and the active skill's object poses (with a skill set, every member's:
  :mod:`.goals`) arrive in Zenoh ring channels
  (:class:`~.ingress.Ingress`; newest wins, filled by Zenoh's own threads without Python,
  so a flood of messages costs the tick nothing but the few it drains), drained and
  decoded in the spin window just ahead of each deadline; the control step runs at the
  deadline and its target is put at once (:class:`~.publisher.TargetOut`), as is a
  gripper message when the tick has one (:class:`~.publisher.GripperOut`: a new command
  or the newest one's repeat at 10 Hz, :mod:`.gripper`);
- :class:`~.swap.SkillSwap`: the skill queryables, served by a child process, the skill
  server (:mod:`sctd.runtime.skillserver`), so that no bundle's bytes are ever in this
  process; each swapped-in skill is compiled on a thread of its own, handed over through
  a one-slot mailbox and installed between two ticks;
- :class:`~.status.TickStats` and :class:`~.status.DaemonStatus`: the tick's timing and
  the status map;
- :class:`~.publisher.Publisher`: the status encoded and put by a thread of its own (and
  the ROS copy of the targets with ``--ros``).
"""

from __future__ import annotations

import gc
import json
import logging
import os
import shutil
import sys
import tempfile
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import ExitStack, contextmanager
from typing import Any

import zenoh

from ..skill import Skill
from ..timing import Ticker, set_realtime, set_timer_slack
from ..wire import Keys
from ..wire.session import MSGPACK, SessionSettings
from . import bundles
from .controller import RuntimeConfig
from .driver import TickDriver
from .goals import GoalSet
from .ingress import Ingress
from .loop import TickLoop
from .publisher import GripperOut, Publisher, TargetOut
from .skillserver import ServerOptions
from .status import DaemonStatus, TickStats
from .swap import SkillSwap

log = logging.getLogger("sctd.run")

# Messages on the runtime's input keys larger than this never reach it: Zenoh's
# low-pass filter drops them on arrival, so what the rings hold is bounded in bytes too.
# Below it, the size limits of the codec apply and are counted.
INGRESS_CEILING = 16 * 1024 * 1024
# How long another Python thread may keep the GIL from the tick (CPython's default is
# 5 ms): the tick waits at most about this when it wakes while a query is handled.
SWITCH_INTERVAL = 2e-4


def ingress_limits(robot: str) -> dict[str, Any]:
    """``size_limits`` (see :func:`~sctd.wire.session.make_config`) of a daemon's
    session: puts larger than :data:`INGRESS_CEILING` on the keys it reads are dropped on
    arrival. There is no rate limit: Zenoh's downsampling keeps the first message of an
    interval and drops the rest, which could be a release (the rings bound floods)."""
    k = Keys(robot)
    keys = (k.input("**"), k.state, k.objects("**"))
    return {"size_limits": [(key, INGRESS_CEILING) for key in keys]}


def check_no_rate_limit(conf: zenoh.Config, robot: str) -> None:
    """Refuse a session config (a ``--zenoh-config`` file's) that rate-limits what the
    daemon reads: Zenoh's downsampling keeps the first message of an interval and drops
    the rest, and the rest may be a release or a stop.

    Raises
    ------
    ValueError
        Naming the rule and the key it would limit.
    """
    try:
        rules = json.loads(conf.get_json("downsampling")) or []
    except (zenoh.ZError, ValueError):
        rules = []
    k = Keys(robot)
    read = [zenoh.KeyExpr(x) for x in (k.input("**"), k.state, k.objects("**"))]
    for r in rules:
        if "ingress" not in (r.get("flows") or ["ingress"]) or "put" not in (r.get("messages") or ["put"]):
            continue  # (no flows: both ways)
        for rule in r.get("rules") or []:
            key = zenoh.KeyExpr(rule["key_expr"])
            hit = next((x for x in read if x.intersects(key)), None)
            if hit is not None:
                raise ValueError(
                    f"downsampling: {r.get('id', '(no id)')}: rate-limits {hit} on arrival, which "
                    f"would drop a release or a stop; remove it (the runtime's rings bound floods)")


@contextmanager
def _tick_thread_settings(rt_priority: int, cpu: int | None) -> Iterator[bool]:
    """The calling (tick) thread's real-time settings for the ``with`` block: a short
    GIL switch interval, 1 us timer slack, SCHED_FIFO ``rt_priority`` (0: off), pinned
    to ``cpu``, and the collector frozen. Yields whether SCHED_FIFO was granted; the
    switch interval and the collector are restored on exit."""
    switch_interval = sys.getswitchinterval()
    sys.setswitchinterval(SWITCH_INTERVAL)
    try:
        set_timer_slack(1)
        realtime = set_realtime(rt_priority)
        if cpu is not None:
            os.sched_setaffinity(0, {cpu})  # this (the tick) thread only
        if rt_priority and not realtime:
            log.warning("could not get SCHED_FIFO priority %d (needs CAP_SYS_NICE or an rtprio "
                        "limit); ticking at normal priority", rt_priority)
        gc.collect()
        gc.freeze()  # long-lived objects out of the collector's way; ticks allocate little
        try:
            yield realtime
        finally:
            gc.unfreeze()
    finally:
        sys.setswitchinterval(switch_interval)


class Daemon:
    """The runtime daemon: one skill (or one skill set), one robot, one Zenoh session
    (module doc).

    Parameters
    ----------
    skill : Skill or None
        The skill to start with (None with ``goals``).
    session : zenoh.Session
        An open session (the caller owns and closes it); open it with
        ``**ingress_limits(robot)`` to bound what the rings can hold and how fast they
        fill.
    config : RuntimeConfig
    spin : float
        Seconds before each deadline to stop sleeping and spin.
    io_nice : int
        The nice value ``session``'s own threads were started at (``status.io_nice``;
        :func:`~sctd.timing.threads_niced`).
    stop_event : threading.Event, optional
        Set to stop; pass one set by signal handlers installed before the daemon exists
        (a stop requested while starting then ends :meth:`run` at once).
    settings : SessionSettings
        What ``session`` was opened from: the skill server's session is opened from
        them (:func:`~sctd.wire.session.helper_config`).
    bundle : bytes, optional
        The packed bundle ``skill`` was read from (:meth:`~sctd.skill.Bundle.pack`):
        kept on disk before the first tick for ``skill/bundle`` (:mod:`.bundles`).
    goals : GoalSet, optional
        A skill set to run instead of ``skill`` (:mod:`.goals`, :mod:`.sets`):
        teleoperation until a member engages; every member's object is read.
    set_name : str
        The skill set's name (``status.goals.name``, the summary's ``set.name``).
    set_bundles : mapping of str to bytes, optional
        The packed bundles of the set's skills (members and teleoperation) by skill id,
        all kept for ``skill/bundle``.
    """

    def __init__(self, skill: Skill | None, session: zenoh.Session, config: RuntimeConfig,
                 spin: float = 1e-4, rt_priority: int = 0, cpu: int | None = None, io_nice: int = 0,
                 stop_event: threading.Event | None = None, swap_on_skill_key: bool = True,
                 ros: Any = None, settings: SessionSettings | None = None,
                 bundle: bytes | None = None, goals: GoalSet | None = None, set_name: str = "",
                 set_bundles: Mapping[str, bytes] | None = None):
        self.config = config
        # the packed bundles the run starts with (by skill id): kept for ``skill/bundle``
        self.bundles: dict[str, bytes] = dict(set_bundles or {})
        if bundle is not None and skill is not None:
            self.bundles[skill.id] = bundle
        self.session = session
        self.settings = settings if settings is not None else SessionSettings()
        self.swap_on_skill_key = swap_on_skill_key
        self.ros = ros  # sctd.wire.ros.RuntimeRos (--ros): target poses out, its status
        self.spin, self.rt_priority, self.cpu, self.io_nice = spin, rt_priority, cpu, io_nice
        self.stop_event = stop_event if stop_event is not None else threading.Event()
        # the run's first gripper command number: its start in ms, so that a restarted
        # daemon's commands are never taken for repeats of the last run's (sctd.runtime.gripper)
        self.driver = TickDriver(skill, config, goals=goals, gripper_start=time.time_ns() // 1_000_000)
        self.swap = SkillSwap(self.driver, self.stop_event, set_name)
        self.realtime = False  # SCHED_FIFO granted to the tick thread
        self.status: DaemonStatus | None = None  # the running loop's (and the last run's)

    def run(self, duration: float | None = None) -> dict[str, Any]:
        """Tick until :meth:`stop` (or ``duration`` seconds); returns final statistics.

        Everything the run opens (the skill server, the subscriptions and publishers, the
        publisher thread, the process' real-time settings) is entered on one exit stack,
        so a failure at any point releases what was opened before it.
        """
        with ExitStack() as stack:
            ingress, publisher, target, gripper = self._open(stack)
            ticker = self.swap.ticker = Ticker(self.config.period, spin=self.spin)
            skill, goals = self.driver.skill, self.driver.goals
            if goals is None:
                log.info("running skill %s@%s for robot %s at %.0f Hz", skill.name, skill.id,
                         self.config.robot, self.config.rate)
            else:
                log.info("running skill set %s (%s; teleoperation %s@%s) for robot %s at %.0f Hz",
                         self.swap.set_name, ", ".join(f"{m.name}@{m.skill.id}" for m in goals.members),
                         skill.name, skill.id, self.config.robot, self.config.rate)
            end = None if duration is None else time.monotonic() + duration
            stats = TickStats(time.monotonic(), self.driver.engine.state, 1.0 / self.config.status_rate,
                              self.driver.target_seq)
            status = self.status = DaemonStatus(self.driver, stats, self.swap, target, self.ros,
                                                self.realtime, self.io_nice)
            TickLoop(self.driver, ingress, self.swap, publisher.queue.put, target, gripper).run(
                ticker, status, self.stop_event, end)
        return status.map(ticker, time.monotonic(), 0.0)

    def _open(self, stack: ExitStack) -> tuple[Ingress, Publisher, TargetOut, GripperOut]:
        """Declare and start what a run needs; each is closed by ``stack`` (in reverse)."""
        keys, s = Keys(self.config.robot), self.session
        # Started before the tick thread's own settings (its threads set theirs); a swap
        # it hands over waits for the loop (and the ingress) to start.
        folder = tempfile.mkdtemp(prefix="sctd-bundles-")  # mode 0700: the daemon's alone
        stack.callback(shutil.rmtree, folder, ignore_errors=True)
        for skill_id, data in self.bundles.items():  # a set's: all of them (pinned)
            bundles.keep(folder, skill_id, data, pinned=self.bundles)
        self.bundles = {}  # on disk now: not held by the process that ticks
        stack.enter_context(self.swap.serve(
            ServerOptions(self.config.robot, self.settings, self.swap_on_skill_key, str(s.zid()), folder),
            self.rt_priority))
        # Only the objects the active skill (or the set's members) need, by name: a
        # wildcard would let any number of names cost memory, and a ring per wildcard
        # would lose the task object's updates whenever another object publishes.
        ingress = self.swap.ingress = Ingress(s, keys, self.driver, self.config.device)
        stack.callback(ingress.close)
        pub_target = stack.enter_context(s.declare_publisher(
            keys.target, express=True, congestion_control=zenoh.CongestionControl.DROP,
            encoding=MSGPACK))
        pub_gripper = stack.enter_context(s.declare_publisher(
            keys.gripper, express=True, congestion_control=zenoh.CongestionControl.DROP,
            encoding=MSGPACK))
        pub_status = stack.enter_context(s.declare_publisher(
            keys.status, congestion_control=zenoh.CongestionControl.DROP, encoding=MSGPACK))
        publisher = stack.enter_context(Publisher(pub_status, self.rt_priority, self.ros))
        target = TargetOut(pub_target, publisher if self.ros is not None else None)
        self.realtime = stack.enter_context(_tick_thread_settings(self.rt_priority, self.cpu))
        # no new swaps once the loop ends; one under way fails its wait and is refused
        stack.callback(self.stop_event.set)
        self.swap.wait_served()
        return ingress, publisher, target, GripperOut(pub_gripper)

    def stop(self) -> None:
        self.stop_event.set()
