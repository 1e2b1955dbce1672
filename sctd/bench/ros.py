"""``sctd bench ros``: a person's Joy through ``sctd ros`` to the target on ROS, against a
bare rclpy round trip measured in the same run, and the node's CPU.

Everything runs in a network namespace the bench makes (Fast DDS discovers by
multicast: none of it leaves), as root: the simulator and the daemon (``--device
ros``) on sctd's keys, ``sctd ros`` with Joy in and the target out, and the probes of
:mod:`sctd_services.ros2.probe`. Per target rate (``--rates``, default 100 and 500 Hz):

- **Joy -> target**: Joy at 100 Hz, centred, then pushed (deadman held) until the
  ``PoseStamped`` target moves, ``--steps`` times: the time from the first pushed Joy
  to the first moved target (two DDS hops, two Zenoh hops, the daemon's tick, and up
  to one period of the node's target schedule);
- **the node's CPU**: its user + system time over the measured pushes (from the probe's
  ``measuring`` line, after its warm-up, to its end: no start-up counted; targets in at
  1 kHz from the daemon, Joy at 100 Hz, the target out at the rate), a share of one
  core, beside **two floors** over the same seconds: an idle rclpy node spinning a
  single-threaded executor with a Zenoh session open (``probe idle``), what any rclpy
  process with a Zenoh session costs before it carries a message; and the same node
  subscribed to the daemon's 1 kHz target, which nothing reads (``probe idle
  --follow``): what receiving sctd's target stream costs any process.

And once, **the latency's floor**: a bare rclpy round trip (``PoseStamped`` out, echoed
back by another rclpy process), two DDS hops and two Python callbacks.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import time
from pathlib import Path
from typing import Any

from ..app.defaults import defaults
from ..app.options import SKILL_HELP
from ..wire.keys import DEFAULT_ROBOT, Keys
from . import run_and_report

EP = "tcp/127.0.0.1:7447"  # inside the bench's own namespace


def add_ros_bench_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--skill", default=defaults().skill, help=f"{SKILL_HELP} (default %(default)s)")
    p.add_argument("--task", default=defaults().task,
                   help="the task the simulator runs (default %(default)s)")
    p.add_argument("--rates", default="100,500", help="target rates of the node, Hz (default %(default)s)")
    p.add_argument("--steps", type=int, default=40, help="pushes per rate (default %(default)s)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def _cpu(pid: int) -> float:
    """User + system seconds of process ``pid`` so far."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_ros_bench(skill: str, task: str, rates: list[float], steps: int, logdir: Path) -> dict[str, Any]:
    from sctd.deploy.netns import Hosts, NamespaceError, can_make_namespaces

    why = can_make_namespaces()
    if why is not None:
        raise RuntimeError(f"needs network namespaces (DDS stays inside one): {why}")
    try:
        import rclpy  # noqa: F401
    except ImportError as e:
        raise RuntimeError(f"needs the ros2 extra ({e}): pip install 'sctd[ros2]'") from None
    out: dict[str, Any] = {"skill": skill, "task": task, "steps": steps, "rates": {}}
    try:
        with Hosts(["ros"], logdir) as h:
            h.python("ros", "sctd_sim.service", "--task", task, "--listen", EP, log="sim.log")
            h.python("ros", "sctd.cli.main", "run", "--skill", skill, "--device", "ros", "--connect", EP,
                     log="run.log")
            echo = h.python("ros", "sctd_services.ros2.probe", "echo", log="echo.log")
            out["bare_rclpy"] = h.call("ros", "sctd_services.ros2.probe", "ping", "--n", "500", timeout=120)
            echo.stop()
            for rate in rates:
                out["rates"][f"{rate:g}"] = _push_phase(h, rate, steps, Keys(DEFAULT_ROBOT).target)
    except (NamespaceError, RuntimeError) as e:
        raise RuntimeError(str(e)) from None
    return out


def _push_phase(h: Any, rate: float, steps: int, target_key: str) -> dict[str, Any]:
    """The node at ``rate`` with its two floors beside it, and the Joy probe's pushes;
    CPU over the measured pushes only (from the probe's ``measuring`` line to its end:
    no process's start-up counted)."""
    from sctd.deploy.netns import last_json

    idle = h.python("ros", "sctd_services.ros2.probe", "idle", "--connect", EP, log=f"idle-{rate:g}.log")
    follow = h.python("ros", "sctd_services.ros2.probe", "idle", "--connect", EP, "--follow", target_key,
                      log=f"follow-{rate:g}.log")
    node = h.python("ros", "sctd.cli.main", "ros", "--target-rate", str(rate), "--connect", EP,
                    "--stats-json", log=f"ros-{rate:g}.log")
    probe = h.python("ros", "sctd_services.ros2.probe", "joy", "--steps", str(steps), log=f"joy-{rate:g}.log")
    try:
        end = time.monotonic() + 120.0
        while '"measuring"' not in probe.output():
            if probe.p.poll() is not None or time.monotonic() > end:
                raise RuntimeError(f"the Joy probe never began measuring: {probe.output()[-2000:]}")
            time.sleep(0.05)
        procs = {"node_cpu": node, "floor_cpu": idle, "follow_floor_cpu": follow}
        cpu0, t0 = {k: _cpu(p.p.pid) for k, p in procs.items()}, time.monotonic()
        try:
            probe.p.wait(timeout=300)
        except subprocess.TimeoutExpired:
            raise RuntimeError(f"the Joy probe did not finish in 300 s: {probe.output()[-2000:]}") from None
        seconds = time.monotonic() - t0
        cpu = {k: round((_cpu(p.p.pid) - cpu0[k]) / seconds, 3) for k, p in procs.items()}
    finally:
        for p in (probe, node, follow, idle):
            p.stop()
    got = last_json(probe.output())
    if got is None or "joy_to_target_ms" not in got:
        raise RuntimeError(f"the Joy probe reported nothing: {probe.output()[-2000:]}")
    return {**got, **cpu, "cpu_seconds": round(seconds, 1)}


def print_report(r: dict[str, Any]) -> None:
    bare = r["bare_rclpy"]["round_trip_ms"]
    print(f"sctd bench ros: {r['skill']} on {r['task']}, Fast DDS in a network namespace; ms")
    print(f"  bare rclpy round trip (PoseStamped out and echoed back): p50 {bare['p50']}  p99 {bare['p99']}  "
          f"max {bare['max']}  (n {bare['n']}, lost {r['bare_rclpy']['lost']})")
    print(f"  goal: Joy -> target p50 <= {bare['p50'] + 2:.2f}, p99 <= {bare['p99'] + 5:.2f} (the round trip "
          "+ 2 and + 5 ms); node CPU <= 0.15")
    print("  target rate   Joy -> target p50     p99     max     n    node CPU   floors: idle   "
          "+ 1 kHz target (shares of a core over the measured pushes)")
    for rate, x in r["rates"].items():
        j = x["joy_to_target_ms"]
        print(f"  {rate:>8} Hz   {j.get('p50', '-'):>13}  {j.get('p99', '-'):>6}  {j.get('max', '-'):>6}  "
              f"{j['n']:>4}    {x['node_cpu']:.3f}            {x['floor_cpu']:.3f}   "
              f"{x['follow_floor_cpu']:.3f}")
    print("  floors: an idle rclpy node with a Zenoh session; the same subscribed to the daemon's 1 kHz "
          "target (a ring of one nothing reads)")


def main_ros_bench(args: argparse.Namespace) -> int:
    try:
        rates = [float(x) for x in args.rates.split(",") if x.strip()]
    except ValueError:
        rates = []
    if not rates or not all(x > 0 for x in rates):
        from ..app.errors import fail

        return fail("bench ros", f"--rates {args.rates!r}: comma-separated rates > 0")
    return run_and_report("ros", args, lambda logdir: run_ros_bench(args.skill, args.task, rates, args.steps,
                                                                     logdir), print_report)
