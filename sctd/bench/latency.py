"""``sctd bench latency``: the daemon's timing next to a bare Zenoh echo, in one run.

Processes, all on one free loopback port:
- ``sctd run`` (the daemon under test), with the pour skill by default;
- the kinematic stand-in robot (state at 1 kHz, objects at 50 Hz) in the pour's scene
  (the skill and the task of ``sctd/app/defaults.yaml``);
- an echo process that republishes ``sctd/bench/ping`` on ``sctd/bench/pong``;
- the probe (``python -m sctd.bench.latency probe``): first measures the echo round
  trip, then publishes input and measures input -> target latency (send time of input
  ``seq`` to the arrival of the first target whose ``in_seq`` is ``seq``).
Both probe measurements use the same kind of Zenoh callback, so they are comparable.
The daemon reports tick lateness, per-tick compute and publish times on exit.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

import zenoh

from sctd.app.defaults import defaults
from sctd.app.options import SKILL_HELP
from sctd.bench import run_and_report
from sctd.cli.procs import Child, free_port
from sctd.deploy.netns import last_json
from sctd.runtime.controller import RuntimeConfig
from sctd.runtime.driver import TickDriver
from sctd.skill import load_skill
from sctd.skill.catalog import find_skill
from sctd.timing import Histogram, RoundTrips, Ticker, set_timer_slack, wait_until
from sctd.wire import Keys, codec
from sctd.wire.session import MSGPACK, TEXT, add_zenoh_arguments, session, session_from_args

from ..app.options import add_robot_argument

PING = "sctd/bench/ping"
PONG = "sctd/bench/pong"


def echo_main(argv: list[str]) -> int:
    p = argparse.ArgumentParser(prog="sctd-bench-echo")
    add_zenoh_arguments(p)
    args = p.parse_args(argv)
    with session_from_args(args) as s, s.declare_publisher(PONG, express=True, encoding=TEXT) as pub, \
            s.declare_subscriber(PING, lambda sample: pub.put(sample.payload.to_bytes())):
        wait_until(threading.Event())
    return 0


def _probe_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="sctd-bench-probe")
    p.add_argument("--rate", type=float, default=500.0)
    p.add_argument("--echo-seconds", type=float, default=3.0)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--warmup", type=float, default=1.0)
    add_robot_argument(p)
    add_zenoh_arguments(p)
    return p


def _send_phase(trips: RoundTrips, rate: float, seconds: float, warmup: float,
                send: Callable[[int], None]) -> None:
    """Send messages 0, 1, ... at ``rate`` for ``seconds``, counting round trips after
    ``warmup``; then wait 0.2 s for the last answers and forget the unanswered."""
    ticker = Ticker(1.0 / rate, spin=0.0)
    start = time.monotonic()
    seq = 0
    trips.counting = False
    while (now := time.monotonic()) < start + seconds:
        ticker.wait()
        trips.counting = now - start > warmup
        trips.sent(seq)
        send(seq)
        seq += 1
    trips.counting = False
    time.sleep(0.2)
    trips.clear()


def _sweep(k: int) -> list[float]:
    """Input ``k`` of a slow sweep, so the target really moves (and the skill works)."""
    return [0.6 * math.sin(k * 0.002), 0.6 * math.cos(k * 0.0013), 0.3 * math.sin(k * 0.0007)]


def probe_main(argv: list[str]) -> int:
    """The echo round trip, then the input -> target latency; prints both as JSON."""
    args = _probe_parser().parse_args(argv)
    keys = Keys(args.robot)
    set_timer_slack(1)
    echo, latency = RoundTrips(), RoundTrips()

    def on_pong(sample: zenoh.Sample) -> None:
        echo.answered(int(sample.payload.to_bytes()), time.monotonic())

    def on_target(sample: zenoh.Sample) -> None:
        now = time.monotonic()
        try:
            latency.answered(codec.decode_target(sample.payload.to_bytes())["in_seq"], now)
        except codec.DecodeError:
            pass

    with session_from_args(args) as s, \
            s.declare_subscriber(PONG, on_pong), s.declare_subscriber(keys.target, on_target), \
            s.declare_publisher(PING, express=True, encoding=TEXT) as pub_ping, \
            s.declare_publisher(keys.input("bench"), express=True, encoding=MSGPACK) as pub_in:
        _send_phase(echo, args.rate, args.echo_seconds + args.warmup, args.warmup,
                    lambda k: pub_ping.put(str(k).encode()))
        _send_phase(latency, args.rate, args.seconds + args.warmup, args.warmup,
                    lambda k: pub_in.put(codec.encode_input(k, time.time(), _sweep(k))))
    print(json.dumps({"echo_rtt_ms": echo.histogram.summary_ms(),
                      "latency_ms": latency.histogram.summary_ms(),
                      "pongs": echo.answers, "targets": latency.answers}))
    return 0


def tick_baseline(skill_path: str, rate: float, n: int = 2000, paced: bool = False) -> dict:
    """:func:`tick_histogram`'s timings (ms) as a Histogram summary."""
    return tick_histogram(skill_path, rate, n, paced).summary_ms()


def tick_histogram(skill_path: str, rate: float, n: int = 2000, paced: bool = False) -> Histogram:
    """The daemon's per-tick control step, in this process and without Zenoh: the tick
    driver the daemon runs, fed one state, object pose and input message a period (taken
    ahead of each deadline, outside the compute it reports, as the daemon's drain does),
    with the skill, a robot that follows every target and a slowly sweeping input; its
    between-ticks work untimed. Back to back (``paced=False``) the caches stay hot;
    ``paced=True`` sleeps to the next period between ticks as the daemon does, which on
    some machines (virtual CPUs) makes each tick start cold. Timings (s)."""

    cfg = RuntimeConfig(rate=rate)
    skill = load_skill(find_skill(skill_path))
    drv = TickDriver(skill, cfg)
    pose_obj = [0.6, 0.0, 0.78, 0.0, 0.0, 1.0, 0.0]
    pose_ee = [0.35, 0.1, 0.9, 0.0, 0.0, 0.0, 1.0]
    q = [0.1] * 7
    h = Histogram()
    set_timer_slack(1)
    ticker = Ticker(cfg.period, spin=1e-4)
    for k in range(n):
        if paced:
            ticker.wait()
        t = k * cfg.period
        u = (0.6 * math.sin(k * 0.001), 0.6 * math.cos(k * 0.00065), 0.3 * math.sin(k * 0.00035))
        pose = drv.controller._pose if drv.controller._pose is not None else pose_ee
        # the messages of one period, drained and decoded ahead of the deadline (untimed)
        drv.receive("state", "", codec.encode_state(k, t, pose, q=q, dq=q, wrench=[0.0] * 6), t)
        drv.receive("object", skill.object, codec.encode_object(k, t, pose_obj), t)
        drv.receive("input", "bench", codec.encode_input(k, t, u), t)
        t0 = time.perf_counter()
        drv.tick(t, t)
        h.add(time.perf_counter() - t0)
        drv.after_tick()  # between ticks (not timed)
    return h


def wait_for_targets(ep: str, daemon: Child, logdir: Path, timeout: float = 30.0) -> None:
    """Until the daemon started as ``daemon`` publishes targets on ``ep`` (RuntimeError
    naming its log when it does not within ``timeout`` s or exits)."""
    with session(connect=[ep]) as s:
        sub = s.declare_subscriber(Keys().target, zenoh.handlers.RingChannel(1))
        end = time.monotonic() + timeout
        while sub.try_recv() is None:
            if time.monotonic() > end or not daemon.running():
                raise RuntimeError(f"daemon produced no targets; see {logdir / 'daemon.log'}")
            time.sleep(0.05)
        sub.undeclare()


def run_latency_bench(skill: str, rate: float, seconds: float, input_rate: float,
                      rt_priority: int, logdir: Path, cpu: int | None = None) -> dict:
    """Run the processes described in the module doc; return all figures."""
    baseline_hot = tick_baseline(skill, rate)
    baseline_paced = tick_baseline(skill, rate, paced=True)
    ep = f"tcp/127.0.0.1:{free_port()}"
    total = seconds + 3.0 + 2.0 + 2.0  # latency + echo + two warm-ups
    pin = ["--cpu", str(cpu)] if cpu is not None else []
    with Child("sctd.cli.main", "run", "--skill", skill, "--listen", ep, "--rate", str(rate),
               "--rt-priority", str(rt_priority), "--stats-json", *pin,
               log=logdir / "daemon.log") as daemon, \
         Child("sctd_sim.kinematic", "--task", defaults().task, "--connect", ep, log=logdir / "robot.log"), \
         Child("sctd.bench.latency", "echo", "--connect", ep, log=logdir / "echo.log"):
        wait_for_targets(ep, daemon, logdir)
        probe = Child("sctd.bench.latency", "probe", "--connect", ep, "--rate", str(input_rate),
                      "--seconds", str(seconds))
        figures = last_json(probe.communicate(timeout=total + 60))
        probe.stop()
        daemon.stop()
    stats = last_json(daemon.output())
    if figures is None or stats is None:
        raise RuntimeError(f"benchmark processes did not report; see {logdir}")
    period_ms = 1e3 / rate
    bound = period_ms + 2 * figures["echo_rtt_ms"]["p99"]
    return {
        "rate_hz": rate,
        "skill": skill,
        "seconds": seconds,
        "input_rate_hz": input_rate,
        "realtime": stats.get("realtime"),
        "ticks": stats["ticks"],
        "late_ticks": stats["late_ticks"],
        "skipped_ticks": stats["skipped_ticks"],
        "lateness_ms": stats["lateness_ms"],
        "compute_ms": stats["compute_ms"],
        "baseline_tick_hot_ms": baseline_hot,
        "baseline_tick_paced_ms": baseline_paced,
        "publish_ms": stats.get("publish_ms"),
        "echo_rtt_ms": figures["echo_rtt_ms"],
        "latency_ms": figures["latency_ms"],
        "criteria": {
            "lateness_p99_le_0.2ms": stats["lateness_ms"]["p99"] <= 0.2,
            "compute_p99_le_0.15ms": stats["compute_ms"]["p99"] <= 0.15,
            "latency_p99_le_period_plus_2_echo_p99": figures["latency_ms"]["p99"] <= bound,
            "latency_bound_ms": round(bound, 4),
        },
    }


def print_report(r: dict) -> None:
    def row(name: str, h: dict) -> str:
        return (f"  {name:30s} p50 {h['p50']:8.3f}   p99 {h['p99']:8.3f}   p99.9 {h['p999']:8.3f}"
                f"   max {h['max']:8.3f}   (n={h['n']})")

    print(f"sctd bench latency: {r['skill']} at {r['rate_hz']:.0f} Hz for {r['seconds']:.0f} s, "
          f"input at {r['input_rate_hz']:.0f} Hz, SCHED_FIFO {'on' if r['realtime'] else 'off'}")
    print(f"  ticks {r['ticks']}, late (> half a period) {r['late_ticks']}, skipped {r['skipped_ticks']}")
    print("  all figures in ms")
    print(row("tick lateness", r["lateness_ms"]))
    print(row("tick compute", r["compute_ms"]))
    print(row("  same tick, no Zenoh, hot", r["baseline_tick_hot_ms"]))
    print(row("  same tick, no Zenoh, 1 kHz", r["baseline_tick_paced_ms"]))
    if r.get("publish_ms"):
        print(row("target put (after the step)", r["publish_ms"]))
    print(row("input -> target", r["latency_ms"]))
    print(row("bare Zenoh echo RTT", r["echo_rtt_ms"]))
    c = r["criteria"]
    mark = {True: "met", False: "NOT met"}
    print(f"  lateness p99 <= 0.2 ms: {mark[c['lateness_p99_le_0.2ms']]}; "
          f"compute p99 <= 0.15 ms: {mark[c['compute_p99_le_0.15ms']]}; "
          f"latency p99 <= period + 2 x echo p99 = {c['latency_bound_ms']:.3f} ms: "
          f"{mark[c['latency_p99_le_period_plus_2_echo_p99']]}")


def add_latency_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rate", type=float, default=1000.0, help="daemon tick rate, Hz")
    p.add_argument("--seconds", type=float, default=10.0, help="latency measurement length")
    p.add_argument("--input-rate", type=float, default=500.0, help="probe input rate, Hz")
    p.add_argument("--skill", default=defaults().skill, help=f"{SKILL_HELP} (default %(default)s)")
    p.add_argument("--rt-priority", type=int, default=10, help="daemon SCHED_FIFO priority (0: off)")
    p.add_argument("--cpu", type=int, default=None, help="pin the daemon's tick thread to this CPU")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def main_latency(args: argparse.Namespace) -> int:
    return run_and_report("latency", args, lambda logdir: run_latency_bench(
        args.skill, args.rate, args.seconds, args.input_rate, args.rt_priority, logdir, args.cpu),
        print_report)


if __name__ == "__main__":
    commands = {"echo": echo_main, "probe": probe_main}
    if len(sys.argv) < 2 or sys.argv[1] not in commands:
        print("usage: python -m sctd.bench.latency {echo,probe} ...", file=sys.stderr)
        sys.exit(2)
    sys.exit(commands[sys.argv[1]](sys.argv[2:]))
