"""``sctd robot NAME``: a robot driver (:mod:`sctd.robots`) served on the wire.

The loop runs at the arm's pace (the driver's :meth:`~sctd.robots.RobotDriver.read`
blocks until the next state) and speaks the wire contract (docs/wire-contract.md):

- publishes every reading on ``sctd/<robot>/state`` (``pose``, ``q``, ``dq``,
  ``wrench``); while the arm is faulted and still reports, its states carry ``fault``
  (the runtime then holds); after a recovery ``seq`` starts again from 0, which the
  runtime takes as a restarted robot (it re-seeds only once the person's input was at
  zero);
- follows ``sctd/<robot>/target``: a newest-wins ring drained every cycle; the newest
  valid target goes to the driver if the robot-side guard (:mod:`sctd_sim.guard`, the
  same as the simulator's) admits it, else the arm holds where it is;
- publishes the task's objects (50 Hz) and its outcome on ``sctd/<robot>/scene``
  (10 Hz): the driver's own scene (the simulator), or the scene as an observer of the
  readings (:mod:`.observer`);
- publishes its own status on ``sctd/<robot>/robot`` (10 Hz): driver, connected, the
  arm's mode, the fault and its history, counters, and two distributions: a target's
  stamp to the driver having it (``target_latency_ms``) and the hand's distance to the
  target it follows, at every reading (``tracking_mm``);
- answers ``sctd/<robot>/robot/recover``: after a fault, the driver recovers (or
  reconnects) between two cycles; the reply says whether it worked.

    sctd robot franky --host 127.0.0.1 --task pour --connect tcp/127.0.0.1:7447
    sctd robot franky --recover --connect tcp/127.0.0.1:7447
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import signal
import sys
import threading
import time
from collections import Counter
from typing import Any

import zenoh

from sctd import se3
from sctd.app.errors import EXIT_FAILED, EXIT_OK, EXIT_USAGE, fail
from sctd.app.options import add_robot_argument, add_task_argument
from sctd.robots import Reading, RobotDriver, RobotError, RobotFault, driver_names, get_driver
from sctd.task import Task, TaskError, find_task
from sctd.timing import Histogram
from sctd.wire import Keys, codec
from sctd.wire.client import query
from sctd.wire.session import MSGPACK, add_zenoh_arguments, session_from_args
from sctd_sim.guard import TargetGuard, TargetLimits, add_limit_arguments, limits_from_args

from .observer import SceneObserver, observer_for

RECOVER_WAIT = 30.0  # s a recover request waits for the loop to run the recovery
STATUS_RATE = 10.0
OBJECT_RATE = 50.0
GRIPPER_STALE = 0.5  # s: a gripper command older than this is not carried out (its repeat is)


class _Recovery:
    """A recover request handed from the queryable's thread to the loop."""

    def __init__(self) -> None:
        self.done = threading.Event()
        self.error: str | None = None


class RobotService:
    """A driver's loop and its Zenoh declarations (module doc).

    Parameters
    ----------
    session : zenoh.Session
    driver : RobotDriver
        Connected.
    keys : Keys
    limits : TargetLimits
        What a target may ask of the arm.
    observer : SceneObserver, optional
        The task's scene beside an arm that does not simulate it.
    stamp_check : bool
        Refuse targets stamped before the service started.
    """

    def __init__(self, session: zenoh.Session, driver: RobotDriver, keys: Keys, limits: TargetLimits,
                 observer: SceneObserver | None = None, stamp_check: bool = True) -> None:
        self.session, self.driver, self.keys, self.observer = session, driver, keys, observer
        self.guard = TargetGuard(limits, 1.0 / driver.rate, time.time(), stamp_check)
        self.seq = 0  # of the states since the last (re)connection: 0 again after a recovery
        self.readings = 0
        self.silent = 0  # reads that timed out
        self.targets = 0
        self.dropped: Counter[str] = Counter()
        self.following = False  # the driver follows an admitted target (else it holds)
        self.fault: RobotFault | None = None
        self.faults: list[dict[str, Any]] = []  # every fault: kind, message, stamp
        self.recoveries = 0
        self.mode = ""
        self.last: Reading | None = None
        # the gripper: the newest command number seen (carried out, or passed over while
        # faulted: never carried out late), and what became of the commands
        self._grip_cmd: int | None = None
        self.sub_gripper: Any = None
        self.gripper = Counter[str]()  # carried_out, faulted (passed over), stale
        self.started = time.monotonic()
        self.latency = Histogram()  # s from a target's stamp to the driver having it
        self.tracking = Histogram()  # m between the admitted target and the measured hand
        self._target_p: Any = None  # the position of the target the driver follows
        self._recovery: _Recovery | None = None
        self._lock = threading.Lock()
        self._due = {"status": 0.0, "objects": 0.0, "scene": 0.0}
        self._resources = contextlib.ExitStack()

    # -- declarations ------------------------------------------------------------------
    def __enter__(self) -> RobotService:
        with contextlib.ExitStack() as stack:
            s, k, drop = self.session, self.keys, zenoh.CongestionControl.DROP

            def publisher(key: str, **kw: Any) -> zenoh.Publisher:
                return stack.enter_context(s.declare_publisher(key, congestion_control=drop,
                                                               encoding=MSGPACK, **kw))

            self.sub_target = stack.enter_context(
                s.declare_subscriber(k.target, zenoh.handlers.RingChannel(16)))
            if self.driver.has_gripper:
                self.sub_gripper = stack.enter_context(
                    s.declare_subscriber(k.gripper, zenoh.handlers.RingChannel(4)))
            self.pub_state = publisher(k.state, express=True)
            self.pub_scene = publisher(k.scene)
            self.pub_status = publisher(k.robot_status)
            names = self._objects().keys()
            self.pub_objects = {n: publisher(k.objects(n)) for n in names}
            stack.enter_context(s.declare_queryable(k.robot_recover, self._on_recover))
            self._resources = stack.pop_all()
        return self

    def __exit__(self, *exc: object) -> None:
        self._resources.close()

    # -- recovery (the queryable's thread, then the loop) ------------------------------
    def _on_recover(self, query: zenoh.Query) -> None:
        """Hand the request to the loop and reply once it ran (or say why not)."""
        rec = _Recovery()
        with self._lock:
            if self._recovery is not None:
                query.reply_err(codec.pack({"error": "a recovery is already under way"}))
                return
            self._recovery = rec
        if not rec.done.wait(RECOVER_WAIT):
            with self._lock:
                self._recovery = None
            query.reply_err(codec.pack({"error": f"the robot loop did not run the recovery within "
                                                 f"{RECOVER_WAIT:.0f} s"}))
            return
        if rec.error is not None:
            query.reply_err(codec.pack({"error": rec.error}))
        else:
            query.reply(self.keys.robot_recover, codec.pack(self.status_message()))

    def _run_recovery(self) -> None:
        with self._lock:
            rec, self._recovery = self._recovery, None
        if rec is None:
            return
        if self.fault is None:
            rec.error = f"{self.driver.name}: no fault to recover from (the arm follows targets)"
            rec.done.set()
            return
        try:
            self.driver.recover()
        except RobotError as e:
            rec.error = f"{self.driver.name}: recovery failed: {e}"
        else:
            self.recoveries += 1
            self.fault = None
            self.following = False
            self.seq = 0  # a new stream: the runtime moves nothing until the input was at zero
            self.guard = TargetGuard(self.guard.limits, self.guard.period, time.time(),
                                     self.guard.stamp_check)
        rec.done.set()

    # -- the loop ----------------------------------------------------------------------
    def run(self, stop: threading.Event, duration: float | None = None) -> None:
        """Serve until ``stop`` is set or ``duration`` s passed."""
        end = None if duration is None else time.monotonic() + duration
        while not stop.is_set() and (end is None or time.monotonic() < end):
            self._run_recovery()
            self.cycle()

    def cycle(self) -> None:
        """One reading, its publications, the newest target; status when due."""
        reading = None
        try:
            reading = self.driver.read(0.05)
        except RobotFault as f:
            self._faulted(f)
        if reading is None:
            self.silent += 1
        else:
            self._publish_reading(reading)
            if self.fault is None:
                self._follow(reading)
        if self.sub_gripper is not None:
            self._grip()
        now = time.monotonic()
        if now >= self._due["status"]:
            self._due["status"] = now + 1.0 / STATUS_RATE
            self.pub_status.put(codec.pack(self.status_message()))

    def _faulted(self, f: RobotFault) -> None:
        if self.fault is None:
            print(f"sctd robot: {self.driver.name} fault: {f} (recover with sctd robot "
                  f"{self.driver.name} --recover)", file=sys.stderr, flush=True)
        self.fault = f
        self.following = False
        self.faults.append({"kind": f.kind, "message": f.message, "stamp": time.time()})
        del self.faults[:-20]  # the newest 20

    def _publish_reading(self, r: Reading) -> None:
        self.last = r
        self.readings += 1
        self.mode = r.mode
        pose = se3.pose_from_flat(se3.flat_from_transform(r.T_world_ee))  # (the fast path: 1 kHz)
        fault = str(self.fault) if self.fault is not None else None
        self.pub_state.put(codec.encode_state(self.seq, r.stamp, pose, q=r.q, dq=r.dq, wrench=r.wrench,
                                              fault=fault, gripper=r.gripper))
        self.seq += 1
        if self.observer is not None:
            self.observer.step(r.stamp, r.T_world_ee, r.gripper)
        now = time.monotonic()
        if now >= self._due["objects"]:
            self._due["objects"] = now + 1.0 / OBJECT_RATE
            for name, T in self._objects().items():
                pub = self.pub_objects.get(name)
                if pub is not None:
                    pub.put(codec.encode_object(self.seq, r.stamp, se3.pose_from_transform(T).tolist()))
        if now >= self._due["scene"] and (self.observer is not None or self.driver.owns_scene):
            self._due["scene"] = now + 0.1
            self.pub_scene.put(codec.pack(self.scene_message()))

    def _grip(self) -> None:
        """The newest gripper command, carried out once per command number: not while the
        arm is faulted (it is passed over, never carried out late), not when it is older
        than ``GRIPPER_STALE`` s (the sender's next repeat is taken). The service never
        makes a command of its own: without one the fingers stay as they are."""
        newest = None
        while (s := self.sub_gripper.try_recv()) is not None:
            try:
                newest = codec.decode_gripper(s.payload.to_bytes())
            except codec.DecodeError as e:
                self.dropped[f"gripper_{e.reason}"] += 1
        if newest is None or newest.cmd == self._grip_cmd:
            return
        if self.fault is not None:
            self._grip_cmd = newest.cmd
            self.gripper["faulted"] += 1
            return
        if self.guard.stamp_check and abs(time.time() - newest.stamp) > GRIPPER_STALE:
            self.gripper["stale"] += 1
            return
        self._grip_cmd = newest.cmd
        try:
            self.driver.grip(newest)
        except RobotFault as f:
            self._faulted(f)
            return
        self.gripper["carried_out"] += 1

    def _follow(self, r: Reading) -> None:
        """The newest valid target to the driver when the guard admits it; refused, the
        arm holds where it is."""
        if self.following and self._target_p is not None:
            x, y, z = self._target_p
            p = r.T_world_ee[:3, 3]
            self.tracking.add(math.sqrt((p[0] - x) ** 2 + (p[1] - y) ** 2 + (p[2] - z) ** 2))
        newest = None
        while (s := self.sub_target.try_recv()) is not None:
            try:
                newest = codec.decode_target(s.payload.to_bytes())
            except codec.DecodeError as e:
                self.dropped[f"target_{e.reason}"] += 1
                continue
            self.targets += 1
        try:
            if newest is not None:
                F = se3.flat_from_transform(r.T_world_ee)
                if self.guard.admit(newest["pose"], newest["stamp"], F, self.following):
                    self.driver.command(se3.transform_from_flat(se3.flat_from_pose(newest["pose"])),
                                        newest["stamp"])
                    self.latency.add(max(0.0, time.time() - newest["stamp"]))
                    self.following = True
                    self._target_p = newest["pose"][:3]
                elif self.following:
                    self.driver.command(None)  # refused: hold where the arm is
                    self.following = False
        except RobotFault as f:
            self._faulted(f)

    # -- messages ----------------------------------------------------------------------
    def _objects(self) -> dict[str, Any]:
        if self.observer is not None:
            return self.observer.objects()
        return self.driver.objects()

    def scene_message(self) -> dict[str, Any]:
        """The task's outcome (as ``sctd sim`` publishes it) and ``t``, the task's clock."""
        if self.observer is not None:
            task = self.observer.scene
            msg: dict[str, Any] = {"stamp": time.time(), "scene": task.name, "task_object": task.task_object,
                                   "t": self.observer.t, "observer": True}
            msg.update(self.observer.outcome())
            return msg
        return {"stamp": time.time(), **self.driver.outcome()}

    def status_message(self) -> dict[str, Any]:
        """``sctd/<robot>/robot``: the driver, the link, the arm's mode and faults."""
        f = self.fault
        return {
            "stamp": time.time(), "driver": self.driver.name, "rate": self.driver.rate,
            "connected": f is None or f.kind != "connection", "mode": self.mode,
            "fault": None if f is None else {"kind": f.kind, "message": f.message},
            "faults": list(self.faults), "recoveries": self.recoveries, "seq": self.seq,
            "readings": self.readings, "silent": self.silent, "targets": self.targets,
            "following": self.following, "target_rejected": self.guard.total_rejected,
            "target_rejected_reasons": dict(self.guard.rejected), "dropped": dict(self.dropped),
            "uptime": round(time.monotonic() - self.started, 3), "driver_health": self.driver.health(),
            # (Histogram's summaries are of seconds x 1e3: of metres, they are millimetres)
            "target_latency_ms": self.latency.summary_ms(), "tracking_mm": self.tracking.summary_ms(),
            "gripper": None if self.sub_gripper is None else {**self.gripper, "cmd": self._grip_cmd},
        }


# -- the command line ------------------------------------------------------------------------

def _tracking_line(t: dict[str, Any]) -> str:
    """The hand's distance to its targets while following, for the last line."""
    if not t.get("n"):
        return ""
    return f"; hand to target p50 {t['p50']:.1f} mm, p99 {t['p99']:.1f} mm"


def add_arguments(p: argparse.ArgumentParser) -> None:
    """``sctd robot [--list] NAME [flags of the service and of the driver NAME]``."""
    p.add_argument("--list", action="store_true", help="list the robot drivers (built-in and registered)")
    p.add_argument("driver", nargs="?", metavar="NAME",
                   help="the driver: " + ", ".join(driver_names()) + " (sctd robot NAME --help: its flags)")
    p.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)


def driver_parser(cls: type[RobotDriver]) -> argparse.ArgumentParser:
    """The flags of ``sctd robot NAME``: the service's, then the driver's own."""
    p = argparse.ArgumentParser(prog=f"sctd robot {cls.name}", description=cls.description)
    add_task_argument(p, None, help="the task whose scene to serve: objects published and the outcome "
                                    "judged from the arm's readings (a simulator driver simulates it)")
    add_robot_argument(p)
    p.add_argument("--trial-seed", type=int, default=None, metavar="N",
                   help="with --task: the seeded random start N of an evaluation trial (objects and hand "
                        "moved within what the task file's vary fields say)")
    p.add_argument("--move-to-start", action="store_true",
                   help="with --task: before serving, bring the hand to the task's (trial's) start with the "
                        "arm's own planner (an operator's step: the arm moves without the person's input)")
    p.add_argument("--recover", action="store_true",
                   help="do not serve: ask the running robot service to recover from its fault "
                        "(reconnect after a lost link), print its reply")
    p.add_argument("--timeout", type=float, default=RECOVER_WAIT + 5.0,
                   help="with --recover: s to wait for the reply (default %(default)s)")
    p.add_argument("--no-stamp-check", action="store_true",
                   help="do not refuse targets stamped before the service started")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--json", action="store_true", help="print the final status as JSON on stdout")
    add_limit_arguments(p)
    cls.add_arguments(p.add_argument_group(f"driver {cls.name}"))  # type: ignore[arg-type]
    add_zenoh_arguments(p)
    return p


def run(args: argparse.Namespace) -> int:
    """``sctd robot``: list the drivers, ask for a recovery, or serve one."""
    if args.list:
        return _list()
    if not args.driver:
        return fail("robot", "name a driver (sctd robot --list lists them)", EXIT_USAGE)
    try:
        cls = get_driver(args.driver)
    except RobotError as e:
        return fail("robot", str(e), EXIT_USAGE)
    a = driver_parser(cls).parse_args(args.rest)
    if a.recover:
        return _ask_recovery(cls, a)
    return _serve(cls, a)


def _list() -> int:
    for name in driver_names():
        try:
            cls = get_driver(name)
            print(f"{name:12s} {cls.description}")
        except (RobotError, ModuleNotFoundError) as e:
            print(f"{name:12s} (does not load here: {e})")
    return EXIT_OK


def _ask_recovery(cls: type[RobotDriver], a: argparse.Namespace) -> int:
    keys = Keys(a.robot)
    with session_from_args(a) as s:
        answer = query(s, keys.robot_recover, timeout=a.timeout)
    if answer is None:
        return fail(f"robot {cls.name}", f"no robot service answered on {keys.robot_recover} (is sctd "
                                         "robot running, on this --robot and --connect?)", EXIT_FAILED)
    ok, msg = answer
    if not ok:
        return fail(f"robot {cls.name}", str(msg.get("error", msg)), EXIT_FAILED)
    print(f"sctd robot {cls.name}: recovered ({msg['recoveries']} so far); nothing moves until the "
          "person's input was at zero")
    return EXIT_OK


def _setup(cls: type[RobotDriver], a: argparse.Namespace) -> tuple[RobotDriver, SceneObserver | None,
                                                                     TargetLimits]:
    """The driver, the scene observer and the limits of the flags; ValueError/RobotError."""
    task: Task | None = None
    if a.task is not None:
        try:
            task = find_task(a.task)
        except TaskError as e:
            raise ValueError(f"--task: {e}") from None
    Keys(a.robot)
    limits = limits_from_args(a)
    driver = cls.from_args(a, task)
    observer = observer_for(task, a.trial_seed) if task is not None and not cls.owns_scene else None
    if (a.move_to_start or a.trial_seed is not None) and task is None:
        raise ValueError("--move-to-start and --trial-seed need --task")
    return driver, observer, limits


def _serve(cls: type[RobotDriver], a: argparse.Namespace) -> int:
    name = f"robot {cls.name}"
    try:
        driver, observer, limits = _setup(cls, a)
    except (ValueError, RobotError) as e:
        return fail(name, str(e), EXIT_USAGE)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *x: stop.set())
    signal.signal(signal.SIGTERM, lambda *x: stop.set())
    with contextlib.ExitStack() as stack:
        stack.enter_context(driver)
        try:
            driver.connect()
        except RobotError as e:
            return fail(name, f"cannot connect: {e}", EXIT_FAILED)
        if a.move_to_start and observer is not None:
            try:
                driver.move_to(observer.scene.start_pose())
            except RobotError as e:
                return fail(name, f"--move-to-start: {e}", EXIT_FAILED)
        session = stack.enter_context(session_from_args(a))
        service = stack.enter_context(RobotService(session, driver, Keys(a.robot), limits, observer,
                                                   not a.no_stamp_check))
        print(f"sctd robot: {cls.name} at {driver.rate:.0f} Hz on sctd/{a.robot}/"
              + (f" (task {a.task}{', observed' if observer else ''})" if a.task else ""),
              file=sys.stderr, flush=True)
        service.run(stop, a.duration)
        final = service.status_message()
    print(f"sctd robot: stopped after {final['readings']} readings, {final['targets']} targets "
          f"({final['target_rejected']} refused), {len(final['faults'])} faults, "
          f"{final['recoveries']} recoveries" + _tracking_line(final["tracking_mm"]),
          file=sys.stderr, flush=True)
    if a.json:
        print(json.dumps(final), flush=True)
    return EXIT_OK


def main(argv: list[str] | None = None) -> int:
    """``python -m sctd_services.robots.service``: the same as ``sctd robot``."""
    p = argparse.ArgumentParser(prog="sctd robot", description=__doc__.split("\n\n")[0])
    add_arguments(p)
    return run(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
