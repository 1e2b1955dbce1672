"""``sctd bench multihost``: sctd across real hosts (network namespaces on this machine).

It runs the :class:`~sctd.deploy.cluster.Cluster` (a router, robot, runtime, input,
learner, observer and intruder host) and prints input -> target latency across the hosts
(probe on the input host, daemon on the runtime host, robot on the robot host) next to a
Zenoh echo over the same links (echo on the runtime host, on keys the input and runtime
roles may use, so the echo crosses the router's access control as input and target do),
the time from a router restart to the first target and state seen again on the observer
host, and, with ``sctd certs``'s configs, what the intruders got through.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from sctd.app.defaults import defaults
from sctd.app.errors import EXIT_FORCED, EXIT_OK
from sctd.bench import run_and_report
from sctd.deploy.cluster import HOSTS, Cluster
from sctd.deploy.netns import Process, last_json
from sctd.task import find_task


def _wait(pred, seconds: float, what: str, *procs: Process):
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        got = pred()
        if got:
            return got
        for p in procs:
            if not p.running():
                raise RuntimeError(f"{what}: {p.host}: {' '.join(p.argv[:4])} exited; see {p.log_path}")
        time.sleep(0.1)
    raise RuntimeError(f"{what}: not within {seconds:.0f} s")


def run_multihost_bench(seconds: float, input_rate: float, logdir: Path, restarts: int = 3) -> dict:
    """Latency across the hosts vs an echo; reconnection after router restarts; what
    the intruders got through (with the secured configs)."""
    with Cluster(logdir, task=find_task(defaults().task)) as c:  # the default task, resolved once
        h = c.hosts
        c.start_router()
        robot, runtime = c.start_robot(), c.start_runtime()
        observer = c.start_observer()
        echo = h.python("runtime", "sctd.deploy.probe", "echo", "--config",
                        str(c.config_on("runtime")), log="echo.log")
        _wait(lambda: c.first(c.keys.target), 60, "first target on the observer host",
              robot, runtime, observer, echo)
        n = int(seconds * input_rate)
        ping = h.call("input", "sctd.deploy.probe", "ping", "--config", str(c.config_on("input")),
                      "--rate", str(input_rate), "--n", str(n + n // 10), "--warmup", str(n // 10),
                      timeout=seconds + 90)
        # sctd.bench.latency's probe: its echo phase (on sctd/bench/*, which the roles
        # policy denies) kept short, then input -> target as in ``sctd bench latency``
        probe = h.call("input", "sctd.bench.latency", "probe", "--rate", str(input_rate),
                       "--seconds", str(seconds), "--echo-seconds", "0.1", *c.zenoh_args("input"),
                       timeout=seconds + 90)
        steady = c.start_steady_input()
        reconnect: list[dict[str, float]] = []
        killed: list[int] = []  # each killed router's exit code (-9)
        for _ in range(restarts):
            assert c.router is not None
            killed.append(c.router.kill())
            time.sleep(2.0)
            t0 = time.time()
            router = c.start_router()
            _wait(lambda r=router: "listening on" in r.output(), 30, "the restarted router", router)
            t_ready = time.time()
            tgt = _wait(lambda t0=t0: c.first(c.keys.target, t0), 60,
                        "target after the router restart", robot, runtime)
            st = _wait(lambda t0=t0: c.first(c.keys.state, t0), 60,
                       "state after the router restart", robot)
            reconnect.append({"router_open_s": t_ready - t0, "target_s": tgt["t"] - t0,
                              "state_s": st["t"] - t0})
            time.sleep(1.0)
        intrusion = None
        if c.secure:
            learner = c.start_learner()
            _wait(lambda: c.first(c.keys.learner_status), 60, "the learner's status", learner)
            intrusion = c.intrude()
        steady.stop()
        runtime.stop()
        stats = last_json(runtime.output())
        stopped = c.stop_router()  # 0 its session closed, 3 forced after 2 s (sctd router)
    return {"hosts": {n: h.addr(n) for n in HOSTS}, "router": c.endpoint, "secure": c.secure,
            "seconds": seconds,
            "input_rate_hz": input_rate, "latency_ms": probe["latency_ms"],
            "echo_rtt_ms": ping["echo_rtt_ms"], "reconnect_s": reconnect,
            "router_exit": {"killed": killed, "stopped": stopped},
            "intrusion": intrusion,
            "daemon": None if stats is None else {k: stats.get(k) for k in
                                                  ("ticks", "late_ticks", "skipped_ticks", "counters")}}


def print_report(r: dict) -> None:
    def row(name: str, h: dict) -> str:
        return (f"  {name:34s} p50 {h['p50']:8.3f}   p99 {h['p99']:8.3f}   max {h['max']:8.3f}"
                f"   (n={h['n']})")

    print(f"sctd bench multihost: router {r['router']} "
          f"({'mutual TLS and the roles policy' if r['secure'] else 'plain TCP, no access control'}); "
          "hosts " + ", ".join(f"{n} {a}" for n, a in r["hosts"].items()))
    print(f"  input at {r['input_rate_hz']:.0f} Hz for {r['seconds']:.0f} s; all figures in ms")
    print(row("input -> target (input->runtime)", r["latency_ms"]))
    print(row("Zenoh echo RTT (input<->runtime)", r["echo_rtt_ms"]))
    for i, x in enumerate(r["reconnect_s"], 1):
        print(f"  router restart {i}: its session open after {x['router_open_s'] * 1e3:6.0f}, first target "
              f"after {x['target_s'] * 1e3:6.0f}, first state after {x['state_s'] * 1e3:6.0f} "
              "(from the router's process start)")
    ex = r["router_exit"]
    how = {EXIT_OK: "its session closed", EXIT_FORCED: "forced: its session did not close in 2 s"}
    print(f"  router exit codes: {ex['killed']} when killed for the restarts, {ex['stopped']} when "
          f"stopped at the end ({how.get(ex['stopped'], 'it did not end by itself')})")
    if r["intrusion"]:
        print(f"  {'intruder':16s} {'delivered':>14s} {'reads':>7s} {'swap':>5s} {'train':>6s}  session")
        for name, x in r["intrusion"].items():
            asks = {k: v["ok"] + v["err"] for k, v in x.items() if isinstance(v, dict) and "ok" in v}
            reads = sum(x.get("received", {}).values())
            swaps = asks.get("swap", 0) + asks.get("swap-on-skill", 0)
            print(f"  {name:16s} {sum(x['delivered'].values()):>5d} of {x['tried']:<5d} {reads:>7d} "
                  f"{swaps:>5d} {asks.get('train', 0):>6d}  "
                  f"{'refused' if x.get('refused') else 'opened'}")
        print("  (control: the input role's own input and the operator's queries; reads: messages "
              "its subscriptions got, a valid observer may read target/state/status/scene)")


def add_bench_multihost_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seconds", type=float, default=10.0, help="latency measurement length")
    p.add_argument("--input-rate", type=float, default=500.0, help="probe input rate, Hz")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def main_bench_multihost(args: argparse.Namespace) -> int:
    return run_and_report("multihost", args, lambda logdir: run_multihost_bench(
        args.seconds, args.input_rate, logdir), print_report)

