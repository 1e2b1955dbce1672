"""The simulated user as a Zenoh input client (the same person ``sctd eval --lockstep``
steps in one process; see :mod:`sctd_services.user`).

It watches what a person in the chair sees: the robot state (the hand), the task's
objects, the scene's progress and the mode the display shows (the ``state`` field of
the targets), and publishes its stick and buttons on ``sctd/<robot>/input/<device>``
at a fixed rate. When the daemon's status says its device must centre the stick before
the arm moves again (``status.input.rearm``: its push went stale over a stalled link, a
stop), it does, as a person reading that on the display would: zero on the stick until
the status no longer says so. It also measures the input -> target latency: the time from sending
input ``seq`` to receiving the first target whose ``in_seq`` is ``seq``.

    python -m sctd_services.simulated_user --task pour --connect tcp/127.0.0.1:7447

It exits 0 after its ``--duration``, 1 when no target arrived in that time, and 2 on
bad flags (a ``--task`` that is no task, or whose file does not validate).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import threading
import time
from contextlib import ExitStack
from typing import Any

import zenoh

from sctd import se3
from sctd.app.errors import EXIT_USAGE
from sctd.app.options import TASK_HELP, add_robot_argument
from sctd.task import Task, TaskError, find_task
from sctd.timing import RoundTrips, Ticker, set_timer_slack
from sctd.wire import Keys, codec
from sctd.wire.session import MSGPACK, add_zenoh_arguments, session_from_args

from .user import DEFAULT_MODEL, PROFILES, USER_MODELS, Observation, SimulatedUser


def task_frames(task: Task) -> tuple[str, ...]:
    """The frames the task's scene publishes (its bodies', then the held object's): what
    a person in the chair sees."""
    return tuple(task.scene.frames())


class UserClient:
    """The Zenoh edge of a :class:`SimulatedUser`: subscriptions that keep the newest
    observation, and one :meth:`step` per input message. A context manager owning its
    subscriptions and publisher."""

    def __init__(self, session: zenoh.Session, user: SimulatedUser, robot: str = "edan",
                 device: str = "simuser", warmup: float = 0.5):
        self.user = user
        self.keys = Keys(robot)
        self.lock = threading.Lock()
        self.latency = RoundTrips()
        self.warmup = warmup
        self.t_start = time.monotonic()
        self.info: dict[str, Any] = {"mode": None, "targets": 0, "changes": [], "T_world_ee": None,
                                     "scene": {}, "first_target": None}
        self.objects: dict[str, Any] = {}
        self.device = device
        self.rearm: dict[str, Any] = {}  # status.input.rearm: device -> why it must send a zero
        self.idle_button: str | None = None  # the state the status says the mode button does nothing in
        self.centred = 0  # times the user centred the stick because the status said so
        self._centring = False
        k = self.keys
        self._stack = ExitStack()
        for key, callback in ((k.target, self._on_target), (k.state, self._on_state),
                              (k.scene, self._on_scene), (k.status, self._on_status)):
            self._stack.enter_context(session.declare_subscriber(key, callback))
        self.frames = tuple(user.task.scene.frames())
        for name in self.frames:
            self._stack.enter_context(session.declare_subscriber(k.objects(name), self._on_object))
        self.pub = self._stack.enter_context(session.declare_publisher(k.input(device), express=True,
                                                                                    encoding=MSGPACK))
        self.seq = 0

    def __enter__(self) -> UserClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _on_target(self, sample: zenoh.Sample) -> None:
        now = time.monotonic()
        try:
            msg = codec.decode_target(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        self.latency.counting = now - self.t_start > self.warmup
        self.latency.answered(msg["in_seq"], now)
        with self.lock:
            info = self.info
            info["targets"] += 1
            if info["first_target"] is None:
                info["first_target"] = now
            if msg["state"] != info["mode"]:
                info["changes"].append((round(now - self.t_start, 3), info["mode"], msg["state"]))
                info["mode"] = msg["state"]

    def _on_state(self, sample: zenoh.Sample) -> None:
        try:
            m = codec.decode_state(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        self.info["T_world_ee"] = se3.transform_from_pose(m.pose)

    def _on_object(self, sample: zenoh.Sample) -> None:
        try:
            pose = codec.decode_object(sample.payload.to_bytes()).pose
        except codec.DecodeError:
            return
        self.objects[str(sample.key_expr).rsplit("/", 1)[-1]] = se3.transform_from_pose(pose)

    def _on_scene(self, sample: zenoh.Sample) -> None:
        try:
            self.info["scene"] = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            pass

    def _on_status(self, sample: zenoh.Sample) -> None:
        try:
            status = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        inp = status.get("input")
        rearm = inp.get("rearm") if isinstance(inp, dict) else None
        self.rearm = rearm if isinstance(rearm, dict) else {}
        # what the display shows of the mode button: nothing to switch in the status' state
        idle = "mode_button" in status and status["mode_button"] is None
        self.idle_button = status.get("state") if idle else None

    def told_to_centre(self, device: str | None = None) -> bool:
        """Whether the newest status says ``device`` (default: this client's) must send
        a zero before it can move the arm; counts each time the user starts centring."""
        told = (self.device if device is None else device) in self.rearm
        if told and not self._centring:
            self.centred += 1
        self._centring = told
        return told

    def observation(self) -> Observation | None:
        info = self.info
        if info["T_world_ee"] is None or info["mode"] is None or \
                any(n not in self.objects for n in self.frames):
            return None
        return Observation(time.monotonic(), info["T_world_ee"], dict(self.objects), info["scene"],
                           info["mode"], switches=self.idle_button != info["mode"])

    def step(self) -> None:
        """Decide and publish one input message (zero until everything is seen)."""
        obs = self.observation()
        u: tuple[float, ...] = (0.0,) * self.user.n
        buttons: tuple[int, ...] = (0, 1, 0)
        if obs is not None:
            u, buttons = self.user.step(obs.t, obs)
            if self.told_to_centre():
                u = (0.0,) * self.user.n
        self.send(u, buttons)

    def send(self, u: tuple[float, ...], buttons: tuple[int, ...]) -> None:
        self.latency.sent(self.seq)
        self.pub.put(codec.encode_input(self.seq, time.time(), u, buttons))
        self.seq += 1

    def let_go(self) -> None:
        """Release the stick (zero input, deadman held) for a few messages."""
        for _ in range(5):
            self.send((0.0,) * self.user.n, (0, 1, 0))
            time.sleep(0.01)

    def close(self) -> None:
        self._stack.close()


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sctd-simulated-user", description=__doc__.split("\n\n")[0])
    p.add_argument("--task", required=True, metavar="NAME|FILE", help=TASK_HELP)
    p.add_argument("--profile", default="steady", choices=sorted(PROFILES))
    p.add_argument("--user-model", default=DEFAULT_MODEL, choices=sorted(USER_MODELS),
                   help="how the user learns the device (default %(default)s)")
    p.add_argument("--axes", type=int, default=3, help="input axes of the device (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="the user's noise seed")
    add_robot_argument(p)
    p.add_argument("--device", default="simuser")
    p.add_argument("--rate", type=float, default=100.0, help="input rate, Hz (default %(default)s)")
    p.add_argument("--duration", type=float, default=10.0, help="s to drive (default %(default)s)")
    p.add_argument("--until-done", action="store_true",
                   help="stop early when the user considers the task done")
    p.add_argument("--warmup", type=float, default=0.5, help="s of latency samples to discard")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    add_zenoh_arguments(p)
    return p


def _drive(client: UserClient, args: argparse.Namespace, stop: threading.Event) -> float:
    """Step the user at ``--rate`` until the duration, a stop or (``--until-done``) the
    task is done; returns the seconds since the first target."""
    set_timer_slack(1)
    ticker = Ticker(1.0 / args.rate, spin=0.0)
    end = time.monotonic() + args.duration
    while not stop.is_set() and time.monotonic() < end:
        ticker.wait()
        client.step()
        if args.until_done and client.user.done:
            break
    client.let_go()
    return time.monotonic() - (client.info["first_target"] or time.monotonic())


def _report(client: UserClient, args: argparse.Namespace, elapsed: float) -> dict[str, Any]:
    info = client.info
    return {
        "task": args.task,
        "profile": args.profile,
        "user_model": args.user_model,
        "inputs_sent": client.seq,
        "targets_received": info["targets"],
        "target_rate": round(info["targets"] / elapsed, 1) if elapsed > 0 else 0.0,
        "elapsed_s": round(elapsed, 3),
        "state_changes": info["changes"],
        "final_state": info["mode"],
        "mode_switches": client.user.switches,
        "centred": client.centred,
        "done": client.user.done,
        "latency_ms": client.latency.histogram.summary_ms(),
    }


def _print_report(report: dict[str, Any]) -> None:
    for t, a, b in report["state_changes"]:
        print(f"  t={t:6.2f}s  state {a} -> {b}")
    lat = report["latency_ms"]
    print(f"  targets: {report['targets_received']} ({report['target_rate']} /s); "
          f"input->target latency p50 {lat['p50']} ms, p99 {lat['p99']} ms, max {lat['max']} ms")


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    try:
        task = find_task(args.task)
    except TaskError as e:
        print(f"sctd-simulated-user: --task: {e}", file=sys.stderr)
        return EXIT_USAGE
    user = SimulatedUser(task, args.axes, args.profile, seed=args.seed, model=args.user_model)
    # The hand's pose at 250 Hz is plenty for a person deciding at 100 Hz: Zenoh drops the
    # rest of the state's 1 kHz on arrival, leaving the CPU to the simulator and the daemon
    # (the targets, whose in_seq the latency measurement needs, all arrive).
    with session_from_args(args, rate_limits=[(Keys(args.robot).state, 250.0)]) as session, \
            UserClient(session, user, args.robot, args.device, args.warmup) as client:
        elapsed = _drive(client, args, stop)
    report = _report(client, args, elapsed)
    if args.json:
        print(json.dumps(report))
    else:
        _print_report(report)
    if not report["targets_received"]:
        print("sctd-simulated-user: no target arrived (is the daemon running, on the same Zenoh?)",
              file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
