"""``sctd sim``: the Pinocchio simulator as a real-time Zenoh service.

Runs :class:`~sctd_sim.simulation.Simulation` on absolute deadlines (one cycle per
period of the monotonic clock) and speaks the wire contract (docs/wire-contract.md):

- follows ``sctd/<robot>/target``: a newest-wins ring drained every cycle, so every
  message is decoded and a malformed one is dropped and counted by reason; the newest
  valid target goes to the impedance controller, which holds the pose when targets
  stop (stale-target hold), if the arm's own guard (:mod:`sctd_sim.guard`) admits it:
  a target too far from the arm, implying too high a speed, or stamped before the
  simulator started is refused, the arm holds where it is, and ``target_rejected``
  counts it;
- publishes ``sctd/<robot>/state`` (``pose``, ``q``, ``dq``, ``wrench``; every cycle by
  default), the scene's objects on ``sctd/<robot>/objects/<name>`` (50 Hz) and the task
  outcome with the service's own health on ``sctd/<robot>/scene`` (10 Hz, see
  :meth:`SimService.scene_message`);
- mirrors every joint-bus cycle on ``sctd/<robot>/can`` while anyone listens, and puts
  frames received there on the bus (:mod:`sctd_sim.canbus.zenoh_interface`);
- answers the simulator-only queryable ``sctd/<robot>/sim/reset``: the scene's task state
  back to its start (bottle refilled, drawer closed and released) between two cycles,
  the arm left where it is (:meth:`SimService._on_reset_query`).

Real time: a cycle that starts more than half a period late counts as an overrun;
short hiccups are caught up (the ticker runs the missed cycles back to back), but when
the loop falls more than 5 periods behind it skips ahead, so simulated time falls
behind wall time. Both are counted in the scene message (``overruns``, ``skipped``,
``behind_s``, ``rtf``), and the first time the simulator cannot keep up a warning
goes to stderr: it never drifts silently.

    python -m sctd_sim.service --task pour --connect tcp/127.0.0.1:7447
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import json
import os
import signal
import sys
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, NamedTuple

import can
import numpy as np
import zenoh

from sctd import se3
from sctd.app.defaults import DefaultsError
from sctd.app.errors import fail
from sctd.task import Task, TaskError, find_task
from sctd.task.compose import compose
from sctd.timing import Histogram, Ticker, set_timer_slack
from sctd.wire import DEFAULT_ROBOT, Keys, codec
from sctd.wire.ros_options import check_ros_arguments
from sctd.wire.session import MSGPACK, session_from_args

from .canbus import FastVirtualBus, FaultConfig
from .canbus.zenoh_interface import FrameDecodeError, can_key, decode_frames, encode_frames
from .guard import TargetGuard, TargetLimits, limits_from_args
from .options import SimSettings, add_service_arguments, arm_from_args

if TYPE_CHECKING:
    from .robot import ArmModel
    from .scenes import Scene

_FAULT_NAMES = {
    "drop": "drop_rate", "drop_rate": "drop_rate",
    "duplicate": "duplicate_rate", "dup": "duplicate_rate", "duplicate_rate": "duplicate_rate",
    "corrupt": "corrupt_rate", "corrupt_rate": "corrupt_rate",
    "delay": "delay", "delay_rate": "delay_rate",
    "bus_off": "bus_off", "tx": "tx", "rx": "rx", "seed": "seed",
}


def parse_faults(text: str) -> FaultConfig:
    """``drop=0.01,delay=0.002,...`` -> :class:`~sctd_sim.canbus.FaultConfig`.

    Names: ``drop``, ``duplicate``, ``corrupt`` (probabilities per frame), ``delay``
    (s; every frame unless ``delay_rate`` is given), ``delay_rate``, ``bus_off``
    (flag), ``tx``/``rx`` (0/1: which direction of the controller's end), ``seed``.

    Raises
    ------
    ValueError
        Unknown name or bad value, naming it.
    """
    types = {f.name: f.type for f in fields(FaultConfig)}
    kw: dict[str, Any] = {}
    for item in filter(None, (s.strip() for s in text.split(","))):
        name, eq, value = item.partition("=")
        key = _FAULT_NAMES.get(name.strip())
        if key is None:
            raise ValueError(f"--faults: unknown fault {name!r} (known: {', '.join(sorted(_FAULT_NAMES))})")
        value = value.strip()
        try:
            if types[key] in (bool, "bool"):
                kw[key] = (value or "1").lower() in ("1", "true", "yes", "on") if eq else True
            elif types[key] in (int, "int"):
                kw[key] = int(value)
            else:
                kw[key] = float(value)
        except ValueError:
            raise ValueError(f"--faults: {name}: not a number: {value!r}") from None
    if kw.get("delay", 0.0) > 0.0 and "delay_rate" not in kw:
        kw["delay_rate"] = 1.0
    return FaultConfig(**kw)


MAX_RESET_BYTES = 4096  # a reset request is a small map; a larger one is refused uncopied
RESET_WAIT = 5.0  # s a reset request waits for the loop to reach a cycle boundary


@dataclass
class _PendingReset:
    """A reset handed from a Zenoh thread to the loop; ``done`` set once it happened, at
    simulated time ``t``."""

    done: threading.Event
    t: float = 0.0
    home: bool = False  # also put the arm back in its start posture


def reset_request_error(payload: bytes, scene: str) -> str | None:
    """What is wrong with a ``sim/reset`` request for a simulator running ``scene``, or
    None when it may be carried out.

    The request is empty or a msgpack map whose optional field ``scene`` (str) names
    the scene the asker expects (a reset meant for another scene is refused) and whose
    optional ``arm`` (bool) puts the arm back in its start posture as well; fields it
    does not know are ignored (wire contract v1). Its size is checked before (the
    queryable refuses one over MAX_RESET_BYTES uncopied).
    """
    if not payload:
        return None
    try:
        msg = codec.unpack_map(payload)
    except codec.DecodeError as e:
        return f"<request>: not an empty payload nor a msgpack map ({e})"
    expected = msg.get("scene")
    if expected is not None and not isinstance(expected, str):
        return f"scene: must be a string, got {type(expected).__name__}"
    if not isinstance(msg.get("arm", False), bool):
        return f"arm: must be true or false, got {type(msg['arm']).__name__}"
    if expected is not None and expected != scene:
        return f"scene: the simulator runs scene {scene!r}, not {expected!r}"
    return None


class SimService:
    """The simulator's real-time loop and its Zenoh declarations.

    Parameters
    ----------
    session : zenoh.Session
    sim : Simulation
    robot : str
    rate, state_rate, object_rate, scene_rate : float
        Hz; the publication rates are rounded to whole numbers of cycles.
    viewer : object, optional
        Anything with ``update(sim)``, called at about 30 Hz.
    limits : TargetLimits, optional
        What a target may ask of the arm (default: the safe defaults).
    stamp_check : bool
        Refuse targets stamped before the service started.
    """

    def __init__(self, session: zenoh.Session, sim, robot: str = DEFAULT_ROBOT,
                 state_rate: float = SimSettings.state_rate, object_rate: float = SimSettings.object_rate,
                 scene_rate: float = SimSettings.scene_rate,
                 viewer=None, limits: TargetLimits | None = None, stamp_check: bool = True,
                 ros=None) -> None:
        self.session = session
        self.ros = ros  # sctd.wire.ros.SimRos (--ros): ee(stamp, pose), rate-limited
        self.sim = sim
        self.keys = Keys(robot)
        self.rate = 1.0 / sim.dt
        self.every_state = max(1, round(self.rate / state_rate))
        self.every_object = max(1, round(self.rate / object_rate))
        self.every_scene = max(1, round(self.rate / scene_rate))
        self.every_view = max(1, round(self.rate / 30.0))
        self.viewer = viewer
        self.dropped: Counter[str] = Counter()
        self.targets = 0
        self.gripper_commands = 0
        self.homes = 0  # resets that put the arm back in its start posture
        self.injected = 0
        self.seq = 0
        self.cycles = 0
        self.ticker: Ticker | None = None
        self.cycle_time = Histogram()
        self.warned = False
        self._can_watched = False
        self._inject_bus: FastVirtualBus | None = None
        self._t0_wall = 0.0
        self._window = (0.0, 0.0)  # (wall, sim t) at the last scene message
        self.rtf = 1.0
        self.guard = TargetGuard(limits or TargetLimits(), sim.dt, time.time(), stamp_check)
        self._F_measured = se3.flat_from_pose(sim.state_message()["pose"])
        self.can_key = can_key(robot)
        self.resets = 0
        self._reset: _PendingReset | None = None  # handed to the loop by the reset queryable
        self._reset_serial = threading.Lock()  # one reset request at a time
        self._reset_lock = threading.Lock()  # the handover of self._reset
        self._ended = threading.Event()  # the loop has run and returned
        self._resources = contextlib.ExitStack()  # the declarations, while entered

    # -- declarations ------------------------------------------------------------------
    def __enter__(self) -> SimService:
        """Declare the subscribers and publishers (a failure midway undeclares the ones
        made) and hook the bus mirror; :meth:`__exit__` undoes it all."""
        with contextlib.ExitStack() as stack:
            self._declare(stack)
            self._resources = stack.pop_all()
        return self

    def _declare(self, stack: contextlib.ExitStack) -> None:
        session, k, drop = self.session, self.keys, zenoh.CongestionControl.DROP

        def publisher(key: str, **kw: Any) -> zenoh.Publisher:
            return stack.enter_context(session.declare_publisher(key, congestion_control=drop,
                                                                 encoding=MSGPACK, **kw))

        self.sub_target = stack.enter_context(
            session.declare_subscriber(k.target, zenoh.handlers.RingChannel(16)))
        self.sub_gripper = stack.enter_context(
            session.declare_subscriber(k.gripper, zenoh.handlers.RingChannel(16)))
        self.pub_state = publisher(k.state, express=True)
        self.pub_objects = {n: publisher(k.objects(n)) for n in self.sim.objects()}
        self.pub_scene = publisher(k.scene)
        # (remote listeners only: the service's own subscriber below, which takes remote
        # frames only, would otherwise count as a listener and keep the mirror running)
        self.pub_can = publisher(self.can_key, allowed_destination=zenoh.Locality.REMOTE)
        stack.enter_context(self.pub_can.declare_matching_listener(self._on_can_matching))
        self._can_watched = self.pub_can.matching_status.matching  # type: ignore[attr-defined]
        self.sub_can = stack.enter_context(session.declare_subscriber(
            self.can_key, zenoh.handlers.RingChannel(256), allowed_origin=zenoh.Locality.REMOTE))
        self.sim.arm.on_frames.append(self._mirror)
        stack.callback(self.sim.arm.on_frames.remove, self._mirror)
        stack.enter_context(session.declare_queryable(k.sim_reset, self._on_reset_query))

    def __exit__(self, *exc: object) -> None:
        """Undeclare everything, close the injection bus (the session stays open)."""
        self._resources.close()
        self._inject_bus = None

    # -- callbacks (Zenoh threads / the sim's bus) -------------------------------------
    def _on_can_matching(self, status: zenoh.MatchingStatus) -> None:
        self._can_watched = status.matching

    def _mirror(self, frames: list) -> None:
        if self._can_watched:
            self.pub_can.put(encode_frames(frames))

    def _on_reset_query(self, query: zenoh.Query) -> None:
        """``sim/reset``: check the request, hand the reset to the loop, reply once it
        happened: ``{ok: true, scene, t}`` (``t`` the simulated time of the reset), or
        ``{error}`` with nothing changed (malformed request, the loop not cycling)."""
        with query:  # the asker stops waiting when the query is dropped, on leaving this
            payload = query.payload
            size = 0 if payload is None else len(payload)
            scene = self.sim.scene.name
            if size > MAX_RESET_BYTES:  # refused before it is copied
                error: str | None = f"<request>: {size} bytes exceeds {MAX_RESET_BYTES}"
            else:
                error = reset_request_error(payload.to_bytes() if payload else b"", scene)
            t = None
            if error is None:
                home = payload is not None and size > 0 and \
                    bool(codec.unpack_map(payload.to_bytes()).get("arm", False))
                with self._reset_serial:
                    t = self._reset_on_loop(home)
                if t is None:
                    error = f"the simulation loop did not reach a cycle boundary in {RESET_WAIT:g} s"
            if error is not None:
                query.reply_err(codec.pack({"error": error}), encoding=MSGPACK)
                return
            query.reply(self.keys.sim_reset, codec.pack({"ok": True, "scene": scene, "t": t}),
                        encoding=MSGPACK)

    def _reset_on_loop(self, home: bool = False) -> float | None:
        """Hand a reset to the loop (with ``home``, the arm's start posture too) and wait
        for it: its simulated time, or None (the request withdrawn, nothing reset) when the
        loop did not take it in RESET_WAIT s."""
        pending = _PendingReset(threading.Event(), home=home)
        with self._reset_lock:
            self._reset = pending
        deadline = time.monotonic() + RESET_WAIT
        while not pending.done.wait(0.02):
            if time.monotonic() < deadline and not self._ended.is_set():
                continue
            with self._reset_lock:
                if self._reset is pending:  # not taken: withdraw it
                    self._reset = None
                    return None
            pending.done.wait()  # taken by the loop this very moment: it sets done next
            break
        return pending.t

    def _apply_reset(self) -> None:
        """On the loop thread, between two cycles: the scene's task state back to its
        start; the arm untouched, or with ``home`` back at rest in its start posture."""
        with self._reset_lock:
            pending, self._reset = self._reset, None
            if pending is None:
                return
            self.sim.scene.reset()
            if pending.home:
                self.sim.home()
                self.guard.restart(time.time())  # a late target from before must not pull it away
                self.homes += 1
            self.resets += 1
            pending.t = self.sim.t
            pending.done.set()

    # -- per cycle ---------------------------------------------------------------------
    def _take_targets(self) -> None:
        newest = None
        sub = self.sub_target
        while (s := sub.try_recv()) is not None:
            try:
                newest = codec.decode_target(s.payload.to_bytes())
            except codec.DecodeError as e:
                self.dropped[f"target_{e.reason}"] += 1
                continue
            self.targets += 1
        if newest is not None:
            ctl = self.sim.arm.controller
            if self.guard.admit(newest["pose"], newest["stamp"], self._F_measured, not ctl.holding):
                self.sim.set_target(newest["pose"], newest["stamp"])
            elif not ctl.holding:
                ctl.hold()  # refused: stay where the arm is (once: holding again and again
                # would re-take the pose the load has pushed it to, and let it sink)

    def _take_gripper(self) -> None:
        """The newest gripper command, carried out once per number (a malformed one is
        dropped and counted; the fingers stay as they are)."""
        newest = None
        while (s := self.sub_gripper.try_recv()) is not None:
            try:
                newest = codec.decode_gripper(s.payload.to_bytes())
            except codec.DecodeError as e:
                self.dropped[f"gripper_{e.reason}"] += 1
        if newest is not None and self.sim.scene.grip(newest):
            self.gripper_commands += 1

    def _take_can(self) -> None:
        bus = self._inject_bus
        if bus is not None:
            bus.drain()  # it hears the whole bus; only its sending matters
        while (s := self.sub_can.try_recv()) is not None:
            try:
                frames = decode_frames(s.payload.to_bytes())
            except FrameDecodeError:
                self.dropped["can_bad_sample"] += 1
                continue
            if bus is None:
                bus = self._inject_bus = self._resources.enter_context(
                    FastVirtualBus(channel=self.sim.channel))
            bus.send_batch(frames)
            self.injected += len(frames)

    def cycle(self) -> None:
        """One cycle: inputs, one simulation step, the publications that are due."""
        sim = self.sim
        if self._reset is not None:
            self._apply_reset()
        self._take_targets()
        self._take_gripper()
        self._take_can()
        sim.step()
        n = self.cycles
        self.cycles = n + 1
        if n % self.every_state == 0:
            m = sim.state_message()
            self._F_measured = se3.flat_from_pose(m["pose"])
            now = time.time()
            self.pub_state.put(codec.encode_state(self.seq, now, m["pose"], q=m["q"], dq=m["dq"],
                                                  wrench=m["wrench"], gripper=m["gripper"]))
            self.seq += 1
            if self.ros is not None:
                self.ros.ee(now, m["pose"])
        if n % self.every_object == 0:
            now = time.time()
            for name, pose in sim.objects().items():
                self.pub_objects[name].put(codec.encode_object(n, now, pose))
        if n % self.every_scene == 0:
            self.pub_scene.put(codec.pack(self.scene_message()))
        if self.viewer is not None and n % self.every_view == 0:
            self.viewer.update(sim)

    def scene_message(self) -> dict[str, Any]:
        """Task outcome (see the scene) and the service's health.

        Fields: ``stamp``, ``scene``, ``task_object``, the scene's outcome fields, ``t``
        (simulated s), ``holding`` (the controller holds: no fresh target), ``rate``,
        ``cycles``, ``rtf`` (simulated / wall time since the last message), ``behind_s``
        (how far simulated time trails wall time), ``overruns`` (cycles started more than
        half a period late), ``skipped`` (cycles given up to resynchronise),
        ``cycle_ms`` (compute per cycle), ``targets`` (valid targets received),
        ``target_rejected`` (valid targets the arm's guard refused) and
        ``target_rejected_reasons`` (reason -> count: ``offset``, ``speed``,
        ``out_of_order``, ``before_start``),
        ``dropped`` (reason -> count), ``can_injected`` (frames put on the bus from
        Zenoh), ``link`` (joint-bus counters of both ends, brakes, injected faults),
        ``resets`` (scene resets done through ``sim/reset``), ``homes`` (those of them that
        put the arm back in its start posture), ``gripper_commands`` (gripper commands
        carried out: each number once).
        """
        sim = self.sim
        now = time.monotonic()
        w0, s0 = self._window
        if now - w0 > 1e-3 and w0 > 0.0:
            self.rtf = (sim.t - s0) / (now - w0)
        self._window = (now, sim.t)
        tk = self.ticker
        msg: dict[str, Any] = {"stamp": time.time(), "scene": sim.scene.name,
                               "task_object": sim.scene.task_object}
        msg.update(sim.scene_outcome())
        msg.update(
            rate=self.rate, cycles=self.cycles, rtf=round(self.rtf, 4),
            behind_s=round(max(0.0, (now - self._t0_wall) - sim.t), 6) if self._t0_wall else 0.0,
            overruns=tk.late if tk else 0, skipped=tk.skipped if tk else 0,
            cycle_ms=self.cycle_time.summary_ms(), targets=self.targets,
            target_rejected=self.guard.total_rejected,
            target_rejected_reasons=dict(self.guard.rejected),
            dropped=dict(self.dropped), can_injected=self.injected, link=sim.link_stats(),
            resets=self.resets, homes=self.homes, gripper_commands=self.gripper_commands,
        )
        return msg

    # -- the loop ----------------------------------------------------------------------
    def run(self, stop: threading.Event, duration: float | None = None) -> None:
        """Cycle on absolute deadlines until ``stop`` is set or ``duration`` s passed."""
        set_timer_slack(1)
        period = self.sim.dt
        tk = self.ticker = Ticker(period, spin=0.0)
        self._t0_wall = tk.due - period
        end = None if duration is None else self._t0_wall + duration
        try:  # start-up (first messages, caches) is not judged: a grace of 1 s
            self._loop(tk, stop, end, grace=self._t0_wall + 1.0)
        finally:
            self._ended.set()  # a reset request waiting for the loop gives up

    def _loop(self, tk: Ticker, stop: threading.Event, end: float | None, grace: float) -> None:
        hist, clock, period = self.cycle_time, time.monotonic, self.sim.dt
        while not stop.is_set():
            now, _late = tk.wait()
            if end is not None and now >= end:
                break
            self.cycle()
            hist.add(clock() - now)
            if not self.warned and now > grace and (tk.skipped or (now - self._t0_wall) - self.sim.t
                                                     > 20 * period):
                self.warned = True
                print(f"sctd sim: cannot keep real time at {self.rate:.0f} Hz: {tk.late} cycles late, "
                      f"{tk.skipped} skipped, simulated time {now - self._t0_wall - self.sim.t:.3f} s "
                      f"behind wall time (median cycle {hist.percentile(50) * 1e3:.3f} ms); "
                      "see rtf/overruns/skipped on the scene key", file=sys.stderr, flush=True)

    def summary(self) -> dict[str, Any]:
        """Final figures (also the last scene message's health fields)."""
        m = self.scene_message()
        wall = time.monotonic() - self._t0_wall if self._t0_wall else 0.0
        keep = ("scene", "t", "cycles", "overruns", "skipped", "behind_s", "cycle_ms", "targets",
                "target_rejected", "target_rejected_reasons", "dropped", "can_injected", "success")
        out = {k: m[k] for k in keep if k in m}
        out["rtf_total"] = round(self.sim.t / wall, 4) if wall > 0 else None
        out["state_messages"] = self.seq
        return out


class _Settings(NamedTuple):
    """What :func:`run` takes from the flags, checked."""

    task: Task
    arm: ArmModel
    faults: FaultConfig | None
    limits: TargetLimits
    channel: str | None
    bus_factory: Callable[[str], can.BusABC] | None


def _settings_from_args(args: argparse.Namespace) -> _Settings:
    """Check the flags (in the order the errors are reported).

    Raises
    ------
    ValueError
        A bad flag, with the message ``sctd sim`` prints.
    """
    faults = parse_faults(args.faults) if args.faults else None
    refs = args.task if isinstance(args.task, list) else [args.task]
    try:
        task = compose([find_task(r) for r in refs])  # one task: itself
    except TaskError as e:
        raise ValueError(f"--task: {e}") from None
    arm = arm_from_args(args)
    Keys(args.robot)
    check_ros_arguments(args)
    if args.rate <= 0 or args.state_rate <= 0 or args.object_rate <= 0 or args.scene_rate <= 0:
        raise ValueError("rates must be positive")
    limits = limits_from_args(args)
    if not 0 <= args.view_port <= 65535:
        raise ValueError(f"--view-port: not a TCP port: {args.view_port}")
    channel, bus_factory = can_bus_choice(args.can_interface, args.can_channel)
    return _Settings(task, arm, faults, limits, channel, bus_factory)


def _start(settings: _Settings, args: argparse.Namespace) -> tuple[Scene, np.ndarray]:
    """The scene to run and the arm's start posture in it: the task's start, or with
    ``--trial-seed`` that trial's seeded start. The task's start is checked first, so an
    arm that cannot reach it is told at once, not after every draw of a trial's start.

    Raises
    ------
    ValueError
        The arm cannot reach the task's start (``--urdf: FILE: task NAME: ...``, or
        ``--task: task NAME: ...`` with the shipped arm; the pose and the arm named), or
        what the task has the hand take cannot be taken (too wide for the fingers, out
        of reach: :func:`~sctd_sim.handreach.hand_problems`), or no draw of the trial's
        start (``--trial-seed:``).
    """
    from .handreach import hand_problems
    from .scenes import make_scene
    from .simulation import start_posture, trial_scene

    scene = make_scene(settings.task)
    where = f"--urdf: {args.urdf}" if args.urdf else "--task"
    try:
        q0 = start_posture(settings.arm, scene.start_pose())
    except RuntimeError as e:
        raise ValueError(f"{where}: task {settings.task.name}: {e}") from None
    problems = hand_problems(settings.task, settings.arm)
    if problems:
        raise ValueError(f"{where}: task {settings.task.name}: {'; '.join(problems)}")
    if args.trial_seed is None:
        return scene, q0
    try:
        return trial_scene(settings.task, args.trial_seed, settings.arm)
    except RuntimeError as e:
        raise ValueError(f"--trial-seed: {e}") from None


def run(args: argparse.Namespace) -> int:
    """``sctd sim`` with parsed arguments (:func:`~sctd_sim.options.add_service_arguments`);
    returns the exit code (2: bad flags)."""
    try:
        settings = _settings_from_args(args)
        scene, q0 = _start(settings, args)
    except ValueError as e:
        return fail("sim", str(e))
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    # the view closes last (server stopped, port free), after the loop and the service
    with contextlib.ExitStack() as stack:
        viewer = None
        if args.view:
            from .view import ViewerUnavailable, open_viewer

            try:
                viewer = stack.enter_context(open_viewer(args.view_port))
            except ViewerUnavailable as e:
                return fail("sim", f"--view: {e}")
            print(f"sctd sim: view at {viewer.url}", file=sys.stderr, flush=True)
        summary = _serve(stack, args, settings, (scene, q0), viewer, stop)
    print(f"sctd sim: stopped after {summary['t']:.2f} s simulated (real-time factor "
          f"{summary['rtf_total']}, {summary['overruns']} overruns, {summary['skipped']} skipped "
          f"cycles, {summary['targets']} targets, {summary['target_rejected']} refused, dropped "
          f"{summary['dropped'] or 'none'})",
          file=sys.stderr, flush=True)
    if args.json:
        print(json.dumps(summary), flush=True)
    return 0


def _serve(stack: contextlib.ExitStack, args: argparse.Namespace, settings: _Settings,
           start: tuple[Scene, np.ndarray], viewer: Any, stop: threading.Event) -> dict[str, Any]:
    """Build the simulation of the arm in ``start`` (the scene and the start posture,
    :func:`_start`), the session and the service (entered on ``stack``), run until
    ``stop`` or ``--duration``; the service's summary."""
    from .simulation import Simulation

    scene, q0 = start
    sim = stack.enter_context(Simulation(
        scene=scene, q0=q0, rate=args.rate, faults=settings.faults, channel=settings.channel,
        bus_factory=settings.bus_factory, drive_timeout=args.drive_timeout, arm=settings.arm))
    session = stack.enter_context(session_from_args(args))
    ros = None
    if args.ros:
        from sctd.wire.ros import SimRos

        ros = stack.enter_context(SimRos(session, args.ros_namespace, args.ros_domain,
                                         args.ros_rate))
    service = stack.enter_context(SimService(
        session, sim, args.robot, args.state_rate, args.object_rate, args.scene_rate, viewer,
        settings.limits, not args.no_stamp_check, ros))
    if viewer is not None:
        viewer.setup(sim)
    # Everything alive now lives as long as the loop (Pinocchio, Zenoh, and with
    # --view viser and trimesh); frozen, a full collection in the loop no longer
    # scans it (with the view, ~40 ms and the cycles skipped otherwise).
    gc.collect()
    gc.freeze()
    arm = settings.arm
    print(f"sctd sim: scene {scene.name} at {args.rate:.0f} Hz on sctd/{args.robot}/ "
          f"(objects: {', '.join(sim.objects())}; bus mirror {service.can_key}; arm "
          f"{arm.urdf_path.name}, frame {arm.ee_frame})",
          file=sys.stderr, flush=True)
    service.run(stop, args.duration)
    return service.summary()


def can_bus_choice(interface: str, channel: str | None
                   ) -> tuple[str | None, Callable[[str], can.BusABC] | None]:
    """(channel, bus_factory) for ``--can-interface``: ``virtual`` is python-can's
    in-process bus (no kernel needed); ``socketcan`` opens two sockets on a kernel
    interface (e.g. ``vcan0``, which ``candump`` can then watch); ``auto`` takes
    socketcan when that interface exists and the virtual bus otherwise."""
    if interface == "virtual":
        return channel, None
    name = channel or "vcan0"
    exists = os.path.exists(f"/sys/class/net/{name}")
    if interface == "auto" and not exists:
        return None, None
    if not exists:
        raise ValueError(f"--can-interface socketcan: no network interface {name!r} on this machine "
                         f"(create one with: ip link add dev {name} type vcan && ip link set up {name})")

    def factory(ch: str) -> can.BusABC:
        return can.Bus(interface="socketcan", channel=ch, receive_own_messages=False)

    return name, factory


def main(argv: list[str] | None = None) -> int:
    """``python -m sctd_sim.service``: parse the flags (the same as ``sctd sim``) and run."""
    p = argparse.ArgumentParser(prog="sctd-sim", description=__doc__.split("\n\n")[0])
    try:
        add_service_arguments(p)  # --task's default is in sctd/app/defaults.yaml
    except DefaultsError as e:
        return fail("sim", str(e))
    return run(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
