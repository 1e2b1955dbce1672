"""``sctd bench multihost``: sctd across real hosts (network namespaces on this machine).

:class:`Cluster` is the setup that ``tests/test_multihost.py`` checks and this bench
measures: in the namespaces of :class:`~sctd.bench.netns.Hosts`,
- ``router``: a Zenoh router on ``tcp/<router>:7447``;
- ``robot``: ``sctd sim --scene pour``;
- ``runtime``: ``sctd run --skill pour``;
- ``input``: the simulated user, or a steady input source;
- ``observer``: a recorder of the contract's keys (JSON lines, see
  ``python -m sctd.bench.netns record``);
- ``intruder``: probes that try to read, write and query.
Every program is a Zenoh client of the router, configured only by its role's file.

The bench prints input -> target latency across the hosts (probe on the input host,
daemon on the runtime host, robot on the robot host) next to a Zenoh echo over the same
links (echo on the runtime host), and the time from a router restart to the first
target and state seen again on the observer host.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from sctd.bench import run_and_report
from sctd.bench.netns import (
    ROUTER_PORT,
    Hosts,
    Process,
    client_config,
    last_json,
    router_config,
    write_config,
)
from sctd.runtime import codec

HOSTS = ("router", "robot", "runtime", "input", "observer", "intruder")
ROLE_OF_HOST = {"router": "sctd-router", "robot": "sctd-robot", "runtime": "sctd-runtime",
                "input": "sctd-input", "observer": "sctd-observer", "intruder": "sctd-observer"}
STEADY_INPUT = {"v": 1, "u": [0.0, 0.0, 0.0], "buttons": [0, 1, 0]}  # deadman held, stick at rest


class Cluster:
    """The hosts and their programs (module doc); a context manager that stops all.

    Parameters
    ----------
    logdir : Path
        Logs, configs and the observer's records.
    robot : str
        Key prefix ``sctd/<robot>``.
    """

    def __init__(self, logdir: Path, robot: str = "edan"):
        self.logdir = Path(logdir)
        self.keys = codec.Keys(robot)
        self.hosts = Hosts(HOSTS, self.logdir)
        self.router: Process | None = None
        self.records = self.logdir / "observer.jsonl"
        self._configs: dict[str, Path] = {}

    @property
    def endpoint(self) -> str:
        return f"tcp/{self.hosts.addr('router')}:{ROUTER_PORT}"

    def config(self, role: str) -> Path:
        """The Zenoh config file of ``role`` (``router`` or a client role)."""
        return self._configs[role]

    def __enter__(self) -> Cluster:
        self.hosts.__enter__()
        try:
            self._write_configs()
        except BaseException:
            self.hosts.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.hosts.close()

    def _write_configs(self) -> None:
        d = self.logdir / "zenoh"
        self._configs["router"] = write_config(d / "router.json5", router_config(self.endpoint))
        for role in sorted(set(ROLE_OF_HOST.values()) - {"sctd-router"}):
            self._configs[role] = write_config(d / f"{role}.json5", client_config(self.endpoint))

    def _zargs(self, host: str) -> list[str]:
        return ["--zenoh-config", str(self.config(ROLE_OF_HOST[host]))]

    # -- programs
    def start_router(self) -> Process:
        self.router = self.hosts.python("router", "sctd.bench.netns", "router", "--config",
                                        str(self.config("router")), log="router.log")
        return self.router

    def start_robot(self, *extra: str) -> Process:
        return self.hosts.python("robot", "sctd_sim.service", "--scene", "pour", *extra,
                                 *self._zargs("robot"), log="robot.log")

    def start_runtime(self, skill: str = "pour", *extra: str) -> Process:
        return self.hosts.python("runtime", "sctd.cli.main", "run", "--skill", skill, "--stats-json",
                                 *extra, *self._zargs("runtime"), log="runtime.log")

    def start_observer(self) -> Process:
        k = self.keys
        rec = ["--key", k.status, "--key", k.scene, "--key", k.target, "--key", k.state,
               "--field", "seq", "--field", "stamp", "--field", "state", "--field", "mode",
               "--field", "in_seq", "--field", "pose", "--field", "success", "--field", "poured",
               "--field", "targets", "--field", "state_age", "--field", "counters"]
        return self.hosts.python("observer", "sctd.bench.netns", "record", "--config",
                                 str(self.config("sctd-observer")), "--out", str(self.records), *rec,
                                 log="observer.log")

    def start_steady_input(self) -> Process:
        """Input at 50 Hz, stick at rest and deadman held, until stopped."""
        return self.hosts.python("input", "sctd.bench.netns", "put", "--config",
                                 str(self.config("sctd-input")), "--key", self.keys.input("steady"),
                                 "--n", "100000000", "--rate", "50", "--settle", "0",
                                 "--payload", json.dumps(STEADY_INPUT), log="steady-input.log")

    def user(self, seconds: float = 90.0) -> dict:
        """The simulated user doing the pour task until done; its JSON report."""
        return self.hosts.call("input", "sctd_services.simulated_user", "--task", "pour",
                               "--duration", str(seconds), "--until-done", "--json",
                               *self._zargs("input"), timeout=seconds + 60)

    # -- what the observer recorded
    def seen(self, key: str, since: float = 0.0) -> Iterator[dict[str, Any]]:
        """Records on ``key`` that arrived at the observer after ``since`` (Unix time)."""
        if not self.records.exists():
            return
        with open(self.records) as f:
            for line in f:
                try:
                    r = json.loads(line)
                except ValueError:  # the line being written
                    continue
                if r["key"] == key and r["t"] > since and isinstance(r["msg"], dict):
                    yield r

    def last(self, key: str, since: float = 0.0) -> dict[str, Any] | None:
        records = list(self.seen(key, since))
        return records[-1] if records else None

    def first(self, key: str, since: float = 0.0) -> dict[str, Any] | None:
        return next(self.seen(key, since), None)


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


def run_multihost_bench(seconds: float, input_rate: float, logdir: Path) -> dict:
    """Latency across the hosts vs an echo; reconnection time after a router restart."""
    with Cluster(logdir) as c:
        h = c.hosts
        c.start_router()
        robot, runtime = c.start_robot(), c.start_runtime()
        observer = c.start_observer()
        echo = h.python("runtime", "sctd.bench.latency", "echo", *c._zargs("runtime"), log="echo.log")
        _wait(lambda: c.first(c.keys.target), 60, "first target on the observer host",
              robot, runtime, observer, echo)
        probe = h.call("input", "sctd.bench.latency", "probe", "--rate", str(input_rate),
                       "--seconds", str(seconds), *c._zargs("input"), timeout=seconds + 90)
        restarts = []
        for _ in range(3):
            assert c.router is not None
            c.router.kill()
            time.sleep(2.0)
            t0 = time.time()
            c.start_router()
            tgt = _wait(lambda t0=t0: c.first(c.keys.target, t0), 60,
                        "target after the router restart", robot, runtime)
            st = _wait(lambda t0=t0: c.first(c.keys.state, t0), 60,
                       "state after the router restart", robot)
            restarts.append({"target_s": tgt["t"] - t0, "state_s": st["t"] - t0})
            time.sleep(1.0)
        stats = None
        runtime.stop()
        stats = last_json(runtime.output())
    return {"hosts": {n: h.addr(n) for n in HOSTS}, "router": c.endpoint, "seconds": seconds,
            "input_rate_hz": input_rate, "latency_ms": probe["latency_ms"],
            "echo_rtt_ms": probe["echo_rtt_ms"], "reconnect_s": restarts,
            "daemon": None if stats is None else {k: stats.get(k) for k in
                                                  ("ticks", "late_ticks", "skipped_ticks")}}


def print_report(r: dict) -> None:
    def row(name: str, h: dict) -> str:
        return (f"  {name:34s} p50 {h['p50']:8.3f}   p99 {h['p99']:8.3f}   max {h['max']:8.3f}"
                f"   (n={h['n']})")

    print(f"sctd bench multihost: router {r['router']}, hosts "
          + ", ".join(f"{n} {a}" for n, a in r["hosts"].items()))
    print(f"  input at {r['input_rate_hz']:.0f} Hz for {r['seconds']:.0f} s; all figures in ms")
    print(row("input -> target (input->runtime)", r["latency_ms"]))
    print(row("Zenoh echo RTT (input<->runtime)", r["echo_rtt_ms"]))
    for i, x in enumerate(r["reconnect_s"], 1):
        print(f"  router restart {i}: first target after {x['target_s'] * 1e3:7.0f} ms, "
              f"first state after {x['state_s'] * 1e3:7.0f} ms (from the router's start)")


def add_bench_multihost_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seconds", type=float, default=10.0, help="latency measurement length")
    p.add_argument("--input-rate", type=float, default=500.0, help="probe input rate, Hz")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def main_bench_multihost(args: argparse.Namespace) -> int:
    return run_and_report("multihost", args, lambda logdir: run_multihost_bench(
        args.seconds, args.input_rate, logdir), print_report)

