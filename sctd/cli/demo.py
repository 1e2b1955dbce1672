"""``sctd demo``: the main job on one machine, end to end, on a free loopback port.

Starts ``sctd run`` with a skill, a robot (the Pinocchio simulator, or the kinematic
stand-in with ``--robot-backend kinematic``) and the simulated
user as separate processes, prints the FSM state changes as the targets report them,
and finishes with the target rate, the input -> target latency and the daemon's tick
statistics. Exits non-zero if any part failed.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import threading
import time
from pathlib import Path

TASK_OF_OBJECT = {"mug": "pour", "drawer_handle": "drawer"}
ROBOTS = {"sim": "sctd_sim.service", "kinematic": "sctd_sim.kinematic"}


def add_demo_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--skill", default="skills/pour.yaml", help="skill YAML (default %(default)s)")
    p.add_argument("--task", choices=sorted(set(TASK_OF_OBJECT.values())),
                   help="what the simulated user tries to do (default: from the skill's object)")
    p.add_argument("--seconds", type=float, default=40.0,
                   help="the longest the user drives; it stops when it has done the task "
                        "(default %(default)s)")
    p.add_argument("--rate", type=float, default=1000.0, help="daemon tick rate, Hz")
    p.add_argument("--robot-backend", default="sim", choices=sorted(ROBOTS),
                   help="what stands in for the arm: the Pinocchio simulator (sim, default) or "
                        "the kinematic stand-in")
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


def main_demo(args: argparse.Namespace) -> int:
    from ..runtime import codec
    from ..runtime.zsession import session as zsession
    from ..skill import SkillError, load_skill
    from .procs import Child, free_port

    try:
        skill = load_skill(args.skill)
    except SkillError as e:
        print(f"sctd demo: {e}", file=sys.stderr)
        return 2
    task = args.task or TASK_OF_OBJECT.get(skill.object)
    if task is None:
        print(f"sctd demo: no scene for object {skill.object!r}; pass --task", file=sys.stderr)
        return 2
    logdir = Path(args.logs) if args.logs else Path(tempfile.mkdtemp(prefix="sctd-demo-"))
    logdir.mkdir(parents=True, exist_ok=True)
    ep = f"tcp/127.0.0.1:{free_port()}"
    print(f"sctd demo: skill {skill.name}@{skill.id} ({args.skill}), task {task}, "
          f"robot {args.robot_backend}, Zenoh {ep}, logs in {logdir}")
    keys = codec.Keys("edan")
    t0 = time.monotonic()
    seen = {"state": None, "targets": 0}
    lock = threading.Lock()

    def on_status(sample) -> None:
        try:
            msg = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        with lock:
            seen["targets"] = msg.get("targets", 0)
            if msg.get("targets", 0) > 0 and msg.get("state") != seen["state"]:
                print(f"  t={time.monotonic() - t0:6.2f}s  state {seen['state'] or '-'} -> {msg['state']}"
                      f"   (mode {msg.get('mode')})", flush=True)
                seen["state"] = msg["state"]

    scene: dict = {}

    def on_scene(sample) -> None:
        try:
            scene.update(codec.unpack_map(sample.payload.to_bytes()))
        except codec.DecodeError:
            pass

    ok = True
    report: dict | None = None
    with Child("sctd.cli.main", "run", "--skill", args.skill, "--listen", ep, "--rate", str(args.rate),
               "--stats-json", log=logdir / "daemon.log") as daemon, \
         Child(ROBOTS[args.robot_backend], "--scene", task, "--connect", ep,
               log=logdir / "robot.log") as robot, \
         zsession(connect=[ep]) as session:
        sub = session.declare_subscriber(keys.status, on_status)
        sub_scene = session.declare_subscriber(keys.scene, on_scene)
        deadline = time.monotonic() + 30
        while seen["targets"] == 0 and time.monotonic() < deadline and daemon.running() and robot.running():
            time.sleep(0.05)
        if seen["targets"] == 0:
            print("sctd demo: no targets within 30 s; see the logs", file=sys.stderr)
            ok = False
        else:
            user = Child("sctd_services.simulated_user", "--task", task, "--connect", ep,
                         "--duration", str(args.seconds), "--until-done", "--json")
            report = _last_json(user.communicate(timeout=args.seconds + 60))
            user.stop()
            if report is None:
                print("sctd demo: the simulated user did not report", file=sys.stderr)
                ok = False
        sub.undeclare()
        sub_scene.undeclare()
        rc = daemon.stop()
        robot.stop()
    stats = _last_json(daemon.output())
    if rc != 0 or stats is None:
        print(f"sctd demo: the daemon exited with {rc}; see {logdir / 'daemon.log'}", file=sys.stderr)
        return 1
    if not ok or report is None:
        return 1
    lat = report["latency_ms"]
    print(f"final state: {report['final_state']} (end state {skill.end}"
          f"{', reached' if report['final_state'] == skill.end else ', not reached'})")
    print(f"targets: {report['target_rate']:.0f} /s at the user over {report['elapsed_s']:.1f} s "
          f"(daemon at {args.rate:.0f} Hz; {stats['ticks']} ticks, {stats['late_ticks']} late)")
    print(f"input -> target latency: p50 {lat['p50']:.3f} ms, p99 {lat['p99']:.3f} ms, "
          f"max {lat['max']:.3f} ms ({lat['n']} samples)")
    tl, tc = stats["lateness_ms"], stats["compute_ms"]
    print(f"tick lateness: p50 {tl['p50']:.3f} ms, p99 {tl['p99']:.3f} ms; "
          f"compute: p50 {tc['p50']:.3f} ms, p99 {tc['p99']:.3f} ms")
    print(f"dropped messages: {stats['dropped'] or 'none'}; counters: {stats['counters']}")
    if scene.get("scene") == "pour":
        print(f"task outcome (sim): poured {scene.get('poured', 0):.2f} of the bottle, spilled "
              f"{scene.get('spilled_amount', 0):.2f}, success {scene.get('success')}; "
              f"sim real-time factor {scene.get('rtf', float('nan')):.2f}")
    elif scene.get("scene") == "drawer":
        print(f"task outcome (sim): drawer open {scene.get('opening', 0):.3f} m, success "
              f"{scene.get('success')}; sim real-time factor {scene.get('rtf', float('nan')):.2f}")
    return 0
