"""``sctd demo``: the main job on one machine, end to end, on a free loopback port.

Starts ``sctd run`` with a skill, a robot (the Pinocchio simulator, or any robot driver
with ``--robot-backend NAME``: the kinematic stand-in, a Franka FR3 through franky) and the simulated
user as separate processes, prints the FSM state changes as the targets report them,
and finishes with the target rate, the input -> target latency and the daemon's tick
statistics. Exits non-zero if any part failed.
"""

from __future__ import annotations

import argparse
import json
import shlex
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import zenoh

from ..app.defaults import defaults
from ..app.errors import EXIT_FAILED, EXIT_OK, fail
from ..app.logs import log_folder
from ..app.options import SKILL_HELP, TASK_HELP
from ..robots import driver_names
from ..skill import Skill, SkillError, load_skill
from ..skill.catalog import find_skill
from ..task import TaskError, add_to_path, find_task, task_for_object
from ..wire import Keys, codec
from ..wire.session import session as zsession
from .procs import Child, free_port


def robot_command(name: str, task: str, extra: str) -> list[str]:
    """The robot process of ``--robot-backend NAME``: ``sctd sim`` for the simulator (its
    own service, with the bus mirror and the scene reset), else ``sctd robot NAME`` (any
    registered driver, with ``--robot-args``; moved to the task's start first)."""
    if name == "sim":
        return ["sctd_sim.service", "--task", task, *shlex.split(extra)]
    start = ["--move-to-start"] if name not in ("kinematic",) else []
    return ["sctd_services.robots.service", name, "--task", task, *start, *shlex.split(extra)]


def add_demo_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--skill", default=defaults().skill, help=SKILL_HELP + " (default %(default)s)")
    p.add_argument("--task", metavar="NAME|FILE",
                   help="what the simulated user tries to do: " + TASK_HELP + " (default: the task whose "
                        "object is the skill's)")
    p.add_argument("--seconds", type=float, default=40.0,
                   help="the longest the user drives; it stops when it has done the task "
                        "(default %(default)s)")
    p.add_argument("--rate", type=float, default=1000.0, help="daemon tick rate, Hz")
    p.add_argument("--robot-backend", default="sim", choices=driver_names(), metavar="DRIVER",
                   help="the arm: a robot driver (sctd robot --list): the Pinocchio simulator (sim, "
                        "default), the kinematic stand-in, franky (a Franka FR3, or franky-sim, with "
                        "--robot-args '--host ADDRESS ...'), or a registered one")
    p.add_argument("--robot-args", default="", metavar="FLAGS",
                   help="the robot's own flags, one string (sctd robot DRIVER --help lists them)")
    p.add_argument("--logs", help="keep the processes' logs in this folder")


def _last_json(text: str) -> dict | None:
    for line in reversed(text.splitlines()):
        line = line.strip()
        if line.startswith("{"):
            try:
                return json.loads(line)
            except ValueError:
                continue
    return None


class _Watch:
    """What the demo shows while it runs: the FSM state changes the daemon's status
    reports (printed as they happen) and the simulator's last scene message. A context
    manager owning its two subscriptions."""

    def __init__(self, session: zenoh.Session, keys: Keys):
        self.t0 = time.monotonic()
        self.state: str | None = None
        self.targets = 0
        self.scene: dict[str, Any] = {}
        self._lock = threading.Lock()
        self._stack = ExitStack()
        self._stack.enter_context(session.declare_subscriber(keys.status, self._on_status))
        self._stack.enter_context(session.declare_subscriber(keys.scene, self._on_scene))

    def __enter__(self) -> _Watch:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stack.close()

    def _on_status(self, sample: zenoh.Sample) -> None:
        try:
            msg = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        with self._lock:
            self.targets = msg.get("targets", 0)
            if self.targets > 0 and msg.get("state") != self.state:
                print(f"  t={time.monotonic() - self.t0:6.2f}s  state {self.state or '-'} -> "
                      f"{msg['state']}   (mode {msg.get('mode')})", flush=True)
                self.state = msg["state"]

    def _on_scene(self, sample: zenoh.Sample) -> None:
        try:
            self.scene.update(codec.unpack_map(sample.payload.to_bytes()))
        except codec.DecodeError:
            pass

    def wait_for_targets(self, seconds: float, *children: Child) -> bool:
        deadline = time.monotonic() + seconds
        while self.targets == 0 and time.monotonic() < deadline and all(c.running() for c in children):
            time.sleep(0.05)
        return self.targets > 0


def _drive(args: argparse.Namespace, task: str, ep: str, logdir: Path) -> tuple[dict | None, dict]:
    """Start the daemon and the robot, then the simulated user once targets flow; the
    user's report (None when it did not get one) and the last scene message."""
    with Child("sctd.cli.main", "run", "--skill", args.skill, "--listen", ep, "--rate", str(args.rate),
               "--stats-json", log=logdir / "daemon.log") as daemon, \
            Child(*robot_command(args.robot_backend, task, args.robot_args), "--connect", ep,
                  log=logdir / "robot.log") as robot, \
            zsession(connect=[ep]) as session, \
            _Watch(session, Keys("edan")) as watch:
        report = None
        if not watch.wait_for_targets(30.0, daemon, robot):
            fail("demo", "no targets within 30 s; see the logs", EXIT_FAILED)
        else:
            with Child("sctd_services.simulated_user", "--task", task, "--connect", ep,
                       "--duration", str(args.seconds), "--until-done", "--json") as user:
                report = _last_json(user.communicate(timeout=args.seconds + 60))
            if report is None:
                fail("demo", "the simulated user did not report", EXIT_FAILED)
        rc = daemon.stop()
    stats = _last_json(daemon.output())
    if rc != 0 or stats is None:
        fail("demo", f"the daemon exited with {rc}; see {logdir / 'daemon.log'}", EXIT_FAILED)
        return None, watch.scene
    return (None if report is None else {"user": report, "daemon": stats}), watch.scene


def _print_outcome(skill: Skill, rate: float, report: dict, scene: dict) -> None:
    user, stats = report["user"], report["daemon"]
    lat = user["latency_ms"]
    print(f"final state: {user['final_state']} (end state {skill.end}"
          f"{', reached' if user['final_state'] == skill.end else ', not reached'})")
    print(f"targets: {user['target_rate']:.0f} /s at the user over {user['elapsed_s']:.1f} s "
          f"(daemon at {rate:.0f} Hz; {stats['ticks']} ticks, {stats['late_ticks']} late)")
    print(f"input -> target latency: p50 {lat['p50']:.3f} ms, p99 {lat['p99']:.3f} ms, "
          f"max {lat['max']:.3f} ms ({lat['n']} samples)")
    tl, tc = stats["lateness_ms"], stats["compute_ms"]
    print(f"tick lateness: p50 {tl['p50']:.3f} ms, p99 {tl['p99']:.3f} ms; "
          f"compute: p50 {tc['p50']:.3f} ms, p99 {tc['p99']:.3f} ms")
    print(f"dropped messages: {stats['dropped'] or 'none'}; counters: {stats['counters']}")
    rtf = scene.get("rtf", float("nan"))
    readings = ", ".join(f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}"
                         for k, v in (scene.get("readings") or {}).items())
    print(f"task outcome (sim): {scene.get('scene')} done {scene.get('done')}, success {scene.get('success')}"
          f" ({readings}); sim real-time factor {rtf:.2f}")


def main_demo(args: argparse.Namespace) -> int:
    try:
        args.skill = str(find_skill(args.skill))
        skill = load_skill(args.skill)
    except SkillError as e:
        return fail("demo", str(e))
    try:
        found = find_task(args.task) if args.task else task_for_object(skill.object)
    except TaskError as e:
        return fail("demo", f"--task: {e}")
    if found is None:
        return fail("demo", f"{args.skill}: object: no task has the object {skill.object!r}; pass --task "
                            "(sctd tasks lists them)")
    task = found.name
    if args.task:
        add_to_path(args.task)  # the children find a task file by its name
    logdir = log_folder(args.logs, "sctd-demo-")
    ep = f"tcp/127.0.0.1:{free_port()}"
    print(f"sctd demo: skill {skill.name}@{skill.id} ({args.skill}), task {task}, "
          f"robot {args.robot_backend}, Zenoh {ep}, logs in {logdir}")
    report, scene = _drive(args, task, ep, logdir)
    if report is None:
        return EXIT_FAILED
    _print_outcome(skill, args.rate, report, scene)
    return EXIT_OK
