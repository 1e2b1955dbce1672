"""``sctd run``: the fixed-rate daemon wired to Zenoh.

Threads: the tick runs on the main thread and reads its inputs itself. Input, state and
the active skill's object poses arrive in Zenoh ring channels (newest wins, filled by
Zenoh's own threads without Python, so a flood of messages costs the tick nothing but
the few it drains). ``DRAIN_LEAD`` before each deadline the tick thread wakes, drains
each ring, checks each message's size before copying it, decodes and validates it,
counts every malformed one, and keeps the newest valid sample; at the deadline the
control step runs on them. (Decoding costs far more after a 1 ms sleep than in a hot
loop; done ahead of the deadline it delays no tick, and one that overruns the lead
shows as lateness.) The skill queryables are served by a child process, the skill
server (:mod:`sctd.runtime.skillserver`), so that no bundle's bytes are ever in this
process: it receives, validates and hands over each swapped-in skill (its model arrays
read without long GIL holds), which is compiled here on a thread of its own, handed over
through a one-slot mailbox and installed between two ticks; the replaced skill is freed
on that thread too, and the query is answered after the swap. Targets and status are
encoded and put by a publisher thread, so the tick's own work is draining its inputs and
the control step.
"""

from __future__ import annotations

import gc
import json
import logging
import os
import queue
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from dataclasses import dataclass, field
from typing import Any

import zenoh

from ..skill import Skill, SkillEngine, SkillError, skill_summary
from ..timing import Histogram, Ticker, set_realtime, set_timer_slack
from ..wire import Keys, codec
from ..wire.session import MSGPACK, SessionSettings
from .controller import RuntimeConfig
from .driver import TickDriver
from .ingress import Ingress, Inlet
from .skillserver import ServerOptions, SkillServer
from .worker import WHERE

log = logging.getLogger("sctd.run")
RECENT = 1.0  # s: the window of the status' recent lateness and compute percentiles
DRAIN_LEAD = 2.5e-4  # s before each deadline the inputs are drained and decoded
# Messages on the runtime's input keys larger than this never reach it: Zenoh's
# low-pass filter drops them on arrival, so what the rings hold is bounded in bytes too.
# Below it, the size limits of the codec apply and are counted.
INGRESS_CEILING = 16 * 1024 * 1024
# How long another Python thread may keep the GIL from the tick (CPython's default is
# 5 ms): the tick waits at most about this when it wakes while a query is handled.
SWITCH_INTERVAL = 2e-4
SERVER_WAIT = 20.0  # s the start waits for the skill server to serve the skill queryables
# How long after a deadline the tick has published its target and sleeps until the next
# drain: a swap's longer GIL holds start then, with most of a period ahead of them.
AFTER_TICK = 3e-4


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


class _Publisher(threading.Thread):
    """Encodes and publishes targets and status off the tick thread: a Zenoh put that
    reaches a remote subscriber writes to the socket (tens of us, with a long tail),
    which would otherwise count against every tick. Runs at one FIFO priority below the
    tick. Queue items: a target's ``(seq, stamp, pose, state, skill id, in_seq, in_device,
    seed)``, a
    status map (dict), a list of samples to drop (freeing them takes time), or None to
    stop. With ``ros`` (``--ros``), each target is also
    offered to ``ros.target(stamp, pose)`` (CDR, rate-limited) after its own put."""

    def __init__(self, target: Any, status: Any, rt_priority: int, ros: Any = None):
        super().__init__(name="sctd-publisher", daemon=True)
        self.target = target
        self.status = status
        self.ros = ros
        self.rt_priority = rt_priority
        self.queue: queue.SimpleQueue[tuple | dict | list | None] = queue.SimpleQueue()
        self.put_time = Histogram()  # target puts

    def run(self) -> None:
        set_timer_slack(1)
        set_realtime(max(0, self.rt_priority - 1))
        q = self.queue
        encode = codec.encode_target
        while (item := q.get()) is not None:
            if isinstance(item, dict):
                self.status.put(codec.pack(item))
                continue
            if isinstance(item, list):  # the tick's oversized samples: dropped here
                del item
                continue
            t0 = time.monotonic()
            self.target.put(encode(*item))
            self.put_time.add(time.monotonic() - t0)
            if self.ros is not None:
                try:
                    self.ros.target(item[1], item[2])
                except Exception:  # the ROS copy must never cost the targets
                    log.exception("publishing the ROS target pose failed; ROS output stopped")
                    self.ros = None

    def close(self) -> None:
        self.queue.put(None)
        self.join(timeout=5.0)

    def __enter__(self) -> _Publisher:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass
class _Pending:
    skill: Skill
    engine: SkillEngine
    objects: dict[str, Inlet]
    done: threading.Event
    state: str = ""
    retired: list[Inlet] = field(default_factory=list)  # object rings the new skill does not use
    replaced: tuple[Skill, SkillEngine] | None = None  # freed off the tick thread


@dataclass
class _Window:
    """The loop's status window: when it started, when the next status is due, when the
    recent-percentile window started, and the last FSM state seen (for the log)."""

    start: float
    state: str
    next_status: float
    recent_start: float


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
    """The runtime daemon: one skill, one robot, one Zenoh session.

    Parameters
    ----------
    skill : Skill
        The skill to start with.
    session : zenoh.Session
        An open session (the caller owns and closes it); open it with
        ``**ingress_limits(robot)`` to bound what the rings can hold and how fast they
        fill.
    config : RuntimeConfig
    spin : float
        Seconds before each deadline to stop sleeping and spin.
    stop_event : threading.Event, optional
        Set to stop; pass one set by signal handlers installed before the daemon exists
        (a stop requested while starting then ends :meth:`run` at once).
    settings : SessionSettings
        What ``session`` was opened from: the skill server's session is opened from
        them (:func:`~sctd.wire.session.outbound_config`).
    """

    def __init__(self, skill: Skill, session: zenoh.Session, config: RuntimeConfig,
                 spin: float = 1e-4, rt_priority: int = 0, cpu: int | None = None,
                 stop_event: threading.Event | None = None, swap_on_skill_key: bool = True,
                 ros: Any = None, settings: SessionSettings | None = None):
        self.config = config
        self.ros = ros  # sctd.wire.ros.RuntimeRos (--ros): target poses out, its status
        self.swap_on_skill_key = swap_on_skill_key
        self.session = session
        self.settings = settings if settings is not None else SessionSettings()
        self.keys = Keys(config.robot)
        self.driver = TickDriver(skill, config)
        self.controller = self.driver.controller
        self.spin = spin
        self.rt_priority = rt_priority
        self.cpu = cpu
        self.realtime = False
        self.stop_event = stop_event if stop_event is not None else threading.Event()
        self.lateness = Histogram()  # since start
        self.compute = Histogram()
        self._recent_lateness = Histogram()  # the current RECENT-second window
        self._recent_compute = Histogram()
        self._recent: dict[str, Any] | None = None  # summaries of the last whole window
        self._pending: _Pending | None = None
        self._lock = threading.Lock()
        self._swap_lock = threading.Lock()
        self._refused = 0  # bundles refused by the skill queryable
        self._window_targets = 0
        self._window_compute_max = 0.0
        self._publisher: _Publisher | None = None
        self.skill_server: SkillServer | None = None
        self.ingress: Ingress | None = None
        self._ticker: Ticker | None = None  # the running loop's (the swap times its work by it)

    @property
    def target_seq(self) -> int:
        return self.driver.target_seq

    # --- the skill queryables (served by the skill server; answered on its threads) -----

    def _summary(self) -> dict[str, Any]:
        """The active skill's summary and FSM state (the ``skill`` queryable's answer)."""
        summary = skill_summary(self.controller.skill)
        summary["state"] = self.controller.engine.state
        return summary

    def _count_refusal(self, error: str) -> None:
        """Every refusal of the skill queryables, whatever its cause, is counted."""
        log.warning("refused skill: %s", error)
        self._refused += 1

    def _between_ticks(self) -> None:
        """Return just after the next tick has published its target, when the tick thread
        sleeps for most of a period: the swap's steps that hold the GIL for a while
        (unpickling the skill, a KD-tree build's start, freeing the replaced skill) begin
        there, so that they end before the tick wakes again. At once when not ticking."""
        ticker = self._ticker
        if ticker is None or self.stop_event.is_set():
            return
        wait = ticker.due + AFTER_TICK - time.monotonic()
        if wait > 0.0:
            time.sleep(min(wait, ticker.period + AFTER_TICK))

    def _swap(self, skill: Skill) -> str:
        """Install a validated skill at a tick boundary: its engine (KD-trees release the
        GIL) and object rings are made here, off the tick thread, and so is the replaced
        skill freed, each step begun between two ticks. Returns the FSM state the swap
        landed in.

        Raises
        ------
        SkillError
            The daemon is not running, or did not reach a tick boundary in 5 s.
        """
        with self._swap_lock:  # one swap at a time
            ingress = self.ingress
            if ingress is None or self.stop_event.is_set():
                raise SkillError(WHERE, "", "the daemon is not running")
            self._between_ticks()
            engine = SkillEngine(skill)
            self._between_ticks()
            objects = ingress.object_inlets(skill.object)
            pending = _Pending(skill, engine, objects, threading.Event())
            with self._lock:
                self._pending = pending
            deadline = time.monotonic() + 5.0
            while not pending.done.wait(0.05) and time.monotonic() < deadline \
                    and not self.stop_event.is_set():
                pass
            if not pending.done.is_set():
                with self._lock:
                    if self._pending is pending:
                        self._pending = None
                for name, inlet in objects.items():
                    if ingress.objects.get(name) is not inlet:
                        inlet.close()
                raise SkillError(WHERE, "", "the daemon stopped or did not reach a tick boundary in 5 s")
            self._between_ticks()
            for inlet in pending.retired:  # the tick no longer drains these
                inlet.close()
            pending.replaced = None
        log.info("swapped to skill %s@%s (state %s)", skill.name, skill.id, pending.state)
        return pending.state

    def _install(self, pending: _Pending, now: float) -> None:
        """On the tick thread, between two ticks: the new skill and its object rings. The
        replaced skill and engine are kept for the swapping thread to free."""
        pending.replaced = (self.controller.skill, self.controller.engine)
        self.driver.swap(pending.skill, now, pending.engine)
        assert self.ingress is not None
        pending.retired = self.ingress.use_objects(pending.objects)
        pending.state = self.controller.engine.state
        pending.done.set()

    # --- the loop ------------------------------------------------------------------------

    def run(self, duration: float | None = None) -> dict[str, Any]:
        """Tick until :meth:`stop` (or ``duration`` seconds); returns final statistics.

        Everything the run opens (the skill server, the subscriptions and publishers, the
        publisher thread, the process' real-time settings) is entered on one exit stack,
        so a failure at any point releases what was opened before it.
        """
        with ExitStack() as stack:
            self._open(stack)
            ticker = self._ticker = Ticker(self.config.period, spin=self.spin)
            log.info("running skill %s@%s for robot %s at %.0f Hz", self.controller.skill.name,
                     self.controller.skill.id, self.config.robot, self.config.rate)
            self._loop(ticker, None if duration is None else time.monotonic() + duration)
        return self.status(ticker, time.monotonic(), 0.0)

    def _open(self, stack: ExitStack) -> None:
        """Declare and start what a run needs; each is closed by ``stack`` (in reverse)."""
        keys, s = self.keys, self.session
        # Started before the tick thread's own settings (its threads set theirs); a swap
        # it hands over waits for the loop (and the ingress) to start.
        self.skill_server = stack.enter_context(SkillServer(
            ServerOptions(self.config.robot, self.settings, self.swap_on_skill_key, str(s.zid())),
            self._summary, self._swap, self._count_refusal, self.stop_event, self._between_ticks,
            self.rt_priority))
        # Only the objects the active skill needs, by name: a wildcard would let any number
        # of names cost memory, and a ring per wildcard would lose the task object's
        # updates whenever another object publishes.
        self.ingress = Ingress(s, keys, self.driver, self.config.device)
        stack.callback(self.ingress.close)
        pub_target = stack.enter_context(s.declare_publisher(
            keys.target, express=True, congestion_control=zenoh.CongestionControl.DROP,
            encoding=MSGPACK))
        pub_status = stack.enter_context(s.declare_publisher(
            keys.status, congestion_control=zenoh.CongestionControl.DROP, encoding=MSGPACK))
        self._publisher = stack.enter_context(_Publisher(pub_target, pub_status, self.rt_priority,
                                                         self.ros))
        self.realtime = stack.enter_context(_tick_thread_settings(self.rt_priority, self.cpu))
        # no new swaps once the loop ends; one under way fails its wait and is refused
        stack.callback(self.stop_event.set)
        self._wait_for_skill_server()

    def _wait_for_skill_server(self) -> None:
        """Until the skill server serves the skill queryables, a stop is asked for, or
        :data:`SERVER_WAIT` s have passed (then the loop ticks without them for now)."""
        assert self.skill_server is not None
        give_up = time.monotonic() + SERVER_WAIT
        while not self.skill_server.wait_ready(0.05) and not self.stop_event.is_set():
            if time.monotonic() > give_up:
                log.warning("the skill queryables are not served yet (%g s); ticking anyway",
                            SERVER_WAIT)
                return

    def _loop(self, ticker: Ticker, end: float | None) -> None:
        """The tick loop: drain ahead of each deadline, step at it, account after it."""
        assert self._publisher is not None and self.ingress is not None
        send = self._publisher.queue.put
        t0 = time.monotonic()
        window = _Window(t0, self.controller.engine.state, next_status=t0, recent_start=t0)
        while not self.stop_event.is_set():
            ahead = ticker.due - DRAIN_LEAD - time.monotonic()
            if ahead > 0.0:
                time.sleep(ahead)
            self._before_tick(time.monotonic())
            now, lateness = ticker.wait()
            if end is not None and now >= end:
                break
            state = self._step(now, time.time(), send)
            done = time.monotonic()
            self._account(window, lateness, done - now, state)
            if done >= window.next_status:
                send(self._window_status(window, ticker, done))
            self._after_tick()

    def _before_tick(self, now: float) -> None:
        """Ahead of a deadline (``now``: monotonic): install a swapped-in skill, then
        drain the inputs."""
        pending = self._pending
        if pending is not None:
            with self._lock:
                self._pending = None
            self._install(pending, now)
        assert self.ingress is not None
        self.ingress.drain(now)

    def _step(self, now: float, wall: float, send: Any) -> str:
        """The control step at the deadline ``now`` (monotonic; ``wall``: Unix time);
        queues the target, returns the state."""
        res = self.driver.tick(now, wall)
        if res.pose is not None:
            send((self.driver.target_seq, wall, res.pose, res.state, self.controller.skill.id,
                  res.in_seq, res.device, res.seed))
            self._window_targets += 1
        return res.state

    def _after_tick(self) -> None:
        """After the target is out: the work the next tick would otherwise do itself
        (vector-field neighbour answers), new devices' rings, freeing big samples."""
        assert self.ingress is not None
        self.driver.after_tick()
        self.ingress.after_tick()
        if self.ingress.trash:
            trash = self.ingress.take_trash()
            if self._publisher is not None:  # oversized samples, dropped on its thread
                self._publisher.queue.put(trash)

    def _account(self, window: _Window, lateness: float, compute: float, state: str) -> None:
        self.lateness.add(lateness)
        self.compute.add(compute)
        self._recent_lateness.add(lateness)
        self._recent_compute.add(compute)
        if compute > self._window_compute_max:
            self._window_compute_max = compute
        if state != window.state:
            log.info("state %s -> %s", window.state, state)
            window.state = state

    def _window_status(self, window: _Window, ticker: Ticker, done: float) -> dict[str, Any]:
        """The status map that closes a status window (and, each RECENT s, the recent
        percentiles); resets the window's counts."""
        if done - window.recent_start >= RECENT:
            self._recent = {"lateness": self._recent_lateness.summary_ms(),
                            "compute": self._recent_compute.summary_ms()}
            self._recent_lateness.clear()
            self._recent_compute.clear()
            window.recent_start = done
        status = self.status(ticker, done, done - window.start)
        window.start = done
        window.next_status = done + 1.0 / self.config.status_rate
        self._window_targets = 0
        self._window_compute_max = 0.0
        return status

    def stop(self) -> None:
        self.stop_event.set()

    def status(self, ticker: Ticker, now: float, window: float) -> dict[str, Any]:
        ctl = self.controller
        c = ctl.counters
        drv = self.driver
        obj = drv.objects.get(ctl.skill.object)
        last = drv.inputs.last

        def age(received: float | None) -> float | None:
            return None if received is None else round(now - received, 6)

        status: dict[str, Any] = {
            "stamp": time.time(),
            "skill": ctl.skill.id,
            "skill_name": ctl.skill.name,
            "state": ctl.engine.state,
            "finished": ctl.engine.finished,
            "stuck": ctl.stuck(now),
            "mode": ctl.mode,
            "rate": ctl.config.rate,
            "realtime": self.realtime,
            "ticks": ticker.ticks,
            "late_ticks": ticker.late,
            "skipped_ticks": ticker.skipped,
            "targets": self.target_seq,
            "target_rate": round(self._window_targets / window, 1) if window > 0 else None,
            "lateness_ms": self.lateness.summary_ms(),
            "compute_ms": self.compute.summary_ms(),
            "publish_ms": self._publisher.put_time.summary_ms() if self._publisher else None,
            "compute_max_window_ms": round(self._window_compute_max * 1e3, 4),
            "recent_ms": self._recent,
            "input_age": age(last.received if last is not None else None),
            "state_age": age(drv.state.received if drv.state is not None else None),
            "object_age": age(obj.received if obj is not None else None),
            "in_seq": last.msg.seq if last is not None and last.msg is not None else -1,
            "input": drv.inputs.summary(),
            "vf_scale": ctl.engine.last_scale,
            "dropped": dict(c.drops),
            "counters": {**c.as_dict(), "swaps_refused": self._refused},
        }
        if self.ros is not None:
            status["ros"] = self.ros.stats()
        return status
