"""``sctd run``: the fixed-rate daemon (DESIGN §7) wired to Zenoh.

Threads: the tick runs on the main thread. Zenoh's callbacks only queue each input,
state and object message with its arrival time; a decoder thread (at one real-time
priority below the tick, so that it is never preempted while it holds the GIL) decodes
and validates them, counts every malformed one, and stores the newest valid sample in a
one-reference slot, which the tick reads without blocking or decoding. A hot-swap
bundle is decoded, validated and compiled on the query's thread, handed over through a
one-slot mailbox, and installed between two ticks; the query is answered after the
swap. Targets are encoded and put by a publisher thread, so the tick's own work is the
control step alone.
"""

from __future__ import annotations

import gc
import logging
import os
import queue
import threading
import time
from dataclasses import dataclass
from typing import Any

import msgpack
import zenoh

from .. import se3
from ..skill import Bundle, Skill, SkillEngine, SkillError, skill_from_bundle, skill_summary
from . import codec
from .controller import Controller, RuntimeConfig, Sample
from .timing import Histogram, Ticker, set_realtime, set_timer_slack

log = logging.getLogger("sctd.run")
INBOX = 4096  # messages waiting for the decoder before new ones are dropped
RECENT = 1.0  # s: the window of the status' recent lateness and compute percentiles


class _Publisher(threading.Thread):
    """Encodes and publishes targets and status off the tick thread: a Zenoh put that
    reaches a remote subscriber writes to the socket (tens of us, with a long tail),
    which would otherwise count against every tick. Runs at one FIFO priority below the
    tick. Queue items: a target's ``(seq, stamp, pose, state, skill id, in_seq)``, a
    status map (dict), or None to stop."""

    def __init__(self, target: Any, status: Any, rt_priority: int):
        super().__init__(name="sctd-publisher", daemon=True)
        self.target = target
        self.status = status
        self.rt_priority = rt_priority
        self.queue: queue.SimpleQueue[tuple | dict | None] = queue.SimpleQueue()
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
            t0 = time.monotonic()
            self.target.put(encode(*item))
            self.put_time.add(time.monotonic() - t0)

    def close(self) -> None:
        self.queue.put(None)
        self.join(timeout=5.0)


class _Decoder(threading.Thread):
    """Decodes queued messages off the tick thread: ``(handler, sample, received)``
    items, each handled as ``handler(sample, received)``; None stops it.

    ``on_error(reason)`` counts what a handler raised beyond the decoders' own
    DecodeError (which the handlers count themselves): a bug must cost one message,
    not the thread that feeds the tick.
    """

    def __init__(self, rt_priority: int, on_error):
        super().__init__(name="sctd-decoder", daemon=True)
        self.rt_priority = rt_priority
        self.on_error = on_error
        self.queue: queue.SimpleQueue[tuple | None] = queue.SimpleQueue()

    def run(self) -> None:
        set_realtime(max(0, self.rt_priority - 1))
        q = self.queue
        while (item := q.get()) is not None:
            handler, sample, received = item
            try:
                handler(sample, received)
            except Exception:
                log.exception("decoding a message on %s failed", sample.key_expr)
                self.on_error("decoder_error")

    def close(self) -> None:
        self.queue.put(None)
        self.join(timeout=5.0)


@dataclass
class _Pending:
    skill: Skill
    engine: SkillEngine
    done: threading.Event
    state: str = ""


class Daemon:
    """The runtime daemon: one skill, one robot, one Zenoh session.

    Parameters
    ----------
    skill : Skill
        The skill to start with.
    session : zenoh.Session
        An open session (the caller owns and closes it).
    config : RuntimeConfig
    spin : float
        Seconds before each deadline to stop sleeping and spin.
    stop_event : threading.Event, optional
        Set to stop; pass one set by signal handlers installed before the daemon exists
        (a stop requested while starting then ends :meth:`run` at once).
    """

    def __init__(self, skill: Skill, session: zenoh.Session, config: RuntimeConfig,
                 spin: float = 1e-4, rt_priority: int = 0, cpu: int | None = None,
                 stop_event: threading.Event | None = None):
        self.config = config
        self.session = session
        self.keys = codec.Keys(config.robot)
        self.controller = Controller(skill, config)
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
        self._objects: dict[str, Sample] = {}
        self._object_drops = 0
        self._pending: _Pending | None = None
        self._lock = threading.Lock()
        self.target_seq = 0
        self._input: Sample | None = None
        self._state: Sample | None = None
        self._window_targets = 0
        self._window_compute_max = 0.0
        self._publisher: _Publisher | None = None

    # --- Zenoh edges (callbacks run on Zenoh's threads) ---------------------------------

    def _drop(self, reason: str) -> None:
        with self._lock:  # Zenoh may call back on several threads
            self.controller.counters.drop(reason)

    def _take_input(self, sample: zenoh.Sample, received: float) -> None:
        try:
            m = codec.decode_input(sample.payload.to_bytes())
        except codec.DecodeError as e:
            self._drop(f"input_{e.reason}")
            return
        self._input = Sample(m.seq, m.stamp, received, u=m.u)

    def _take_state(self, sample: zenoh.Sample, received: float) -> None:
        try:
            m = codec.decode_state(sample.payload.to_bytes())
        except codec.DecodeError as e:
            self._drop(f"state_{e.reason}")
            return
        self._state = Sample(m.seq, m.stamp, received, T=se3.matrix4_from_pose(m.pose),
                             wrench=m.wrench)

    def _take_object(self, sample: zenoh.Sample, received: float) -> None:
        name = str(sample.key_expr).rsplit("/", 1)[-1]
        try:
            m = codec.decode_object(sample.payload.to_bytes())
        except codec.DecodeError as e:
            self._drop(f"object_{e.reason}")
            return
        # A pose that has not changed keeps its transform (the same array), so that the
        # controller's object-frame caches stay valid for a still object.
        prev = self._objects.get(name)
        T = prev.T if prev is not None and prev.pose == m.pose else se3.matrix4_from_pose(m.pose)
        self._objects[name] = Sample(m.seq, m.stamp, received, T=T, pose=m.pose)

    def _on_skill_query(self, query: zenoh.Query) -> None:
        payload = query.payload
        if payload is None or len(payload.to_bytes()) == 0:
            summary = skill_summary(self.controller.skill)
            summary["state"] = self.controller.engine.state
            query.reply(self.keys.skill, msgpack.packb(summary, use_bin_type=True))
            return
        try:
            bundle = Bundle.unpack(payload.to_bytes())
            skill = skill_from_bundle(bundle)
            engine = SkillEngine(skill)
        except SkillError as e:
            log.warning("refused skill: %s", e)
            query.reply_err(msgpack.packb({"error": str(e)}, use_bin_type=True))
            return
        pending = _Pending(skill, engine, threading.Event())
        with self._lock:
            self._pending = pending
        if not pending.done.wait(timeout=5.0):
            query.reply_err(msgpack.packb({"error": "daemon did not reach a tick boundary in 5 s"}))
            return
        log.info("swapped to skill %s@%s (state %s)", skill.name, skill.id, pending.state)
        query.reply(self.keys.skill, msgpack.packb(
            {"ok": True, "id": skill.id, "name": skill.name, "state": pending.state},
            use_bin_type=True))

    # --- the loop ------------------------------------------------------------------------

    def run(self, duration: float | None = None) -> dict[str, Any]:
        """Tick until :meth:`stop` (or ``duration`` seconds); returns final statistics."""
        cfg = self.config
        keys = self.keys
        s = self.session
        # Decoded on arrival into newest-value slots: the newest valid sample wins, every
        # malformed message is counted, and the tick never waits on the network.
        decoder = _Decoder(self.rt_priority, self._drop)
        decoder.start()
        inbox = decoder.queue
        monotonic = time.monotonic

        def queue_to(handler):
            def enqueue(sample: zenoh.Sample) -> None:
                # A flood faster than the decoder is dropped here and counted, so the
                # queue (and the daemon's memory) stays bounded.
                if inbox.qsize() < INBOX:
                    inbox.put((handler, sample, monotonic()))
                else:
                    self._drop("inbox_full")
            return enqueue

        sub_in = s.declare_subscriber(keys.input(cfg.device), queue_to(self._take_input))
        sub_state = s.declare_subscriber(keys.state, queue_to(self._take_state))
        sub_obj = s.declare_subscriber(keys.objects(), queue_to(self._take_object))
        pub_target = s.declare_publisher(keys.target, express=True,
                                         congestion_control=zenoh.CongestionControl.DROP)
        pub_status = s.declare_publisher(keys.status, congestion_control=zenoh.CongestionControl.DROP)
        queryable = s.declare_queryable(keys.skill, self._on_skill_query)
        publisher = _Publisher(pub_target, pub_status, self.rt_priority)
        publisher.start()
        self._publisher = publisher
        send = publisher.queue.put
        set_timer_slack(1)
        self.realtime = set_realtime(self.rt_priority)
        if self.cpu is not None:
            os.sched_setaffinity(0, {self.cpu})  # this (the tick) thread only
        if self.rt_priority and not self.realtime:
            log.warning("could not get SCHED_FIFO priority %d (needs CAP_SYS_NICE or an rtprio "
                        "limit); ticking at normal priority", self.rt_priority)
        gc.collect()
        gc.freeze()  # long-lived objects out of the collector's way; ticks allocate little
        ticker = Ticker(cfg.period, spin=self.spin)
        status_period = 1.0 / cfg.status_rate
        next_status = time.monotonic()
        window_start = recent_start = time.monotonic()
        end = None if duration is None else time.monotonic() + duration
        last_state = self.controller.engine.state
        log.info("running skill %s@%s for robot %s at %.0f Hz", self.controller.skill.name,
                 self.controller.skill.id, cfg.robot, cfg.rate)
        try:
            while not self.stop_event.is_set():
                now, lateness = ticker.wait()
                if end is not None and now >= end:
                    break
                wall = time.time()
                pending = self._pending
                if pending is not None:
                    with self._lock:
                        self._pending = None
                    self.controller.swap(pending.skill, now, pending.engine)
                    pending.state = self.controller.engine.state
                    pending.done.set()
                ctl = self.controller
                res = ctl.tick(now, wall, self._input, self._state,
                               self._objects.get(ctl.skill.object))
                if res.pose is not None:
                    self.target_seq += 1
                    send((self.target_seq, wall, res.pose, res.state, ctl.skill.id, res.in_seq))
                    self._window_targets += 1
                done = time.monotonic()
                compute = done - now
                self.lateness.add(lateness)
                self.compute.add(compute)
                self._recent_lateness.add(lateness)
                self._recent_compute.add(compute)
                if compute > self._window_compute_max:
                    self._window_compute_max = compute
                if res.state != last_state:
                    log.info("state %s -> %s", last_state, res.state)
                    last_state = res.state
                if done >= next_status:
                    if done - recent_start >= RECENT:
                        self._recent = {"lateness": self._recent_lateness.summary_ms(),
                                        "compute": self._recent_compute.summary_ms()}
                        self._recent_lateness.clear()
                        self._recent_compute.clear()
                        recent_start = done
                    send(self.status(ticker, done, done - window_start))
                    window_start = done
                    self._window_targets = 0
                    self._window_compute_max = 0.0
                    next_status = done + status_period
        finally:
            publisher.close()
            gc.unfreeze()
            for d in (queryable, sub_in, sub_state, sub_obj, pub_target, pub_status):
                d.undeclare()
            decoder.close()
        return self.status(ticker, time.monotonic(), 0.0)

    def stop(self) -> None:
        self.stop_event.set()

    def status(self, ticker: Ticker, now: float, window: float) -> dict[str, Any]:
        ctl = self.controller
        c = ctl.counters
        obj = self._objects.get(ctl.skill.object)

        def age(sample: Sample | None) -> float | None:
            return None if sample is None else round(now - sample.received, 6)

        return {
            "stamp": time.time(),
            "skill": ctl.skill.id,
            "skill_name": ctl.skill.name,
            "state": ctl.engine.state,
            "finished": ctl.engine.finished,
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
            "input_age": age(self._input),
            "state_age": age(self._state),
            "object_age": age(obj),
            "in_seq": self._input.seq if self._input is not None else -1,
            "vf_scale": ctl.engine.last_scale,
            "dropped": dict(c.drops),
            "counters": {
                "nonfinite_input": c.nonfinite_input,
                "stale_input": c.stale_input,
                "nonfinite_output": c.nonfinite_output,
                "offset_limited": c.offset_limited,
                "transitions": c.transitions,
                "swaps": c.swaps,
            },
        }
