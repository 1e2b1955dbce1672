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
links (echo on the runtime host, on keys the input and runtime roles may use, so the echo
crosses the router's access control as input and target do), and the time from a router restart to the first
target and state seen again on the observer host.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
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
    sign_certificate,
    tls_client_config,
    write_config,
)
from sctd.cli.errors import EXIT_FORCED, EXIT_OK
from sctd.wire import Keys

HOSTS = ("router", "robot", "runtime", "input", "learner", "observer", "intruder")
ROLE_OF_HOST = {"router": "sctd-router", "robot": "sctd-robot", "runtime": "sctd-runtime",
                "input": "sctd-input", "learner": "sctd-learner", "observer": "sctd-observer"}
# The client roles the cluster uses: the hosts' and the operator's, who watches for intruders.
CLIENT_ROLES = ("sctd-robot", "sctd-runtime", "sctd-input", "sctd-learner", "sctd-observer",
                "sctd-operator")
STEADY_INPUT = {"v": 1, "u": [0.0, 0.0, 0.0], "buttons": [0, 1, 0]}  # deadman held, stick at rest
TLS_PORT = 7448
# Every key of the wire contract an intruder could write to, as suffixes of sctd/<robot>/.
CONTRACT_KEYS = ("input/intruder", "state", "objects/mug", "target", "status", "scene", "can",
                 "demos/pour/intruder", "learner/status")
# The intruders: who tries (the name is also the mark on its messages).
INTRUDERS = ("no-certificate", "other-ca", "unlisted-name", "observer")
N_PER_KEY = 20


def secure_available() -> bool:
    """True when this sctd has ``sctd certs`` (mutual TLS and the roles' access control);
    else the cluster runs on plain TCP."""
    return importlib.util.find_spec("sctd.cli.certs") is not None


class Cluster:
    """The hosts and their programs (module doc); a context manager that stops all.

    Parameters
    ----------
    logdir : Path
        Logs, configs and the observer's records.
    robot : str
        Key prefix ``sctd/<robot>``.
    """

    def __init__(self, logdir: Path, robot: str = "edan", secure: bool | None = None):
        self.logdir = Path(logdir)
        self.keys = Keys(robot)
        self.hosts = Hosts(HOSTS, self.logdir)
        self.secure = secure_available() if secure is None else secure
        self.router: Process | None = None
        self.records = self.logdir / "observer.jsonl"
        self._configs: dict[str, Path] = {}
        self.intruder_configs: dict[str, Path] = {}
        self._seen: dict[str, list[dict[str, Any]]] = {}
        self._offset = 0
        self._router_starts = 0

    @property
    def endpoint(self) -> str:
        if self.secure:
            return f"tls/{self.hosts.addr('router')}:{TLS_PORT}"
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
        if self.secure:
            self._write_secure_configs()
            return
        d = self.logdir / "zenoh"
        self._configs["router"] = write_config(d / "router.json5", router_config(self.endpoint))
        for role in CLIENT_ROLES:
            self._configs[role] = write_config(d / f"{role}.json5", client_config(self.endpoint))

    def _certs(self, out: Path) -> Path:
        r = subprocess.run([sys.executable, "-m", "sctd.cli.main", "certs", "--out", str(out),
                            "--router", self.endpoint, "--ip", self.hosts.addr("router")],
                           capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"sctd certs --out {out}: exit {r.returncode}: {r.stderr.strip()}")
        return out

    def _write_secure_configs(self) -> None:
        """``sctd certs`` renders every role's file (the programs get nothing else); the
        intruders get a client without a certificate, one whose certificate another CA
        signed, one with a CA-signed certificate whose name is no role, and a valid
        observer."""
        tls = self._certs(self.logdir / "tls")
        self._configs["router"] = tls / "zenoh" / "router.json5"
        for role in CLIENT_ROLES:
            self._configs[role] = tls / "zenoh" / f"{role}.json5"
        other = self._certs(self.logdir / "other-ca")
        cert, key = sign_certificate(tls, "intruder", self.logdir / "unlisted")
        ca, ep, d = tls / "ca.pem", self.endpoint, self.logdir / "intruders"
        self.intruder_configs = {
            "no-certificate": write_config(d / "no-certificate.json5", tls_client_config(ep, ca)),
            "other-ca": write_config(d / "other-ca.json5", tls_client_config(
                ep, ca, other / "sctd-observer.pem", other / "sctd-observer-key.pem")),
            "unlisted-name": write_config(d / "unlisted-name.json5", tls_client_config(ep, ca, cert, key)),
            "observer": self._configs["sctd-observer"],
        }

    def _zargs(self, host: str) -> list[str]:
        return ["--zenoh-config", str(self.config(ROLE_OF_HOST[host]))]

    # -- programs
    def start_router(self) -> Process:
        """``sctd router`` with the router's config (again, after a restart: each start
        logs to its own file); it prints ``listening on`` once its session is open."""
        self._router_starts += 1
        self.router = self.hosts.python("router", "sctd.cli.main", "router", "--config",
                                        str(self.config("router")), log=f"router-{self._router_starts}.log")
        return self.router

    def stop_router(self) -> int | None:
        """Stop the router with SIGTERM (SIGKILL after 10 s); its exit code (None when no
        router was started): ``sctd router`` exits 0 when its session closed and 3
        (``EXIT_FORCED``) when Zenoh did not close it within 2 s, -9 only if killed."""
        return None if self.router is None else self.router.stop()

    def start_learner(self) -> Process:
        return self.hosts.python("learner", "sctd.cli.main", "learner", "--store",
                                 str(self.logdir / "store"), *self._zargs("learner"), log="learner.log")

    def start_robot(self, *extra: str) -> Process:
        return self.hosts.python("robot", "sctd_sim.service", "--scene", "pour", *extra,
                                 *self._zargs("robot"), log="robot.log")

    def start_runtime(self, skill: str = "pour", *extra: str) -> Process:
        return self.hosts.python("runtime", "sctd.cli.main", "run", "--skill", skill, "--stats-json",
                                 *extra, *self._zargs("runtime"), log="runtime.log")

    def start_observer(self) -> Process:
        k = self.keys
        rec = ["--key", k.status, "--key", k.scene, "--key", k.target, "--key", k.state,
               "--key", k.learner_status,
               "--field", "seq", "--field", "stamp", "--field", "state", "--field", "mode",
               "--field", "in_seq", "--field", "pose", "--field", "success", "--field", "poured",
               "--field", "targets", "--field", "state_age", "--field", "counters"]
        rec += ["--max-rate", "100"]  # of each key: enough to see seq and pose change
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

    # -- the intruders
    def intrude(self, intruders: tuple[str, ...] = INTRUDERS, n: int = N_PER_KEY) -> dict:
        """Each intruder (on the intruder host, at once) puts ``n`` marked messages on
        every key of :data:`CONTRACT_KEYS`, subscribes to all of them, asks for a skill
        swap and for training; an operator on the observer host counts the marked
        messages that arrive. The input host puts ``n`` marked input messages too (the
        control: what an allowed sender delivers), the operator asks for a swap and for
        training (the control: the runtime and the learner answer). Per intruder:
        ``delivered`` (key -> marked messages the operator got), ``received`` (key ->
        messages it got), ``swap`` and ``train`` (ok and error replies)."""
        h, k = self.hosts, self.keys
        keys = [f"{k.prefix}/{suffix}" for suffix in CONTRACT_KEYS]
        configs = {name: self.intruder_configs.get(name, self.config("sctd-observer"))
                   for name in intruders}
        op = ["--config", str(self.config("sctd-operator"))]
        # first the listeners (until stopped), each ready before anyone sends
        listeners = {"watch": h.python("observer", "sctd.bench.netns", "listen", *op, "--mark", "intruder",
                                       "--seconds", "600", *_each("--key", keys),
                                       log="intrusion-watch.log")}
        for name, conf in configs.items():
            listeners[name] = h.python("intruder", "sctd.bench.netns", "listen", "--config", str(conf),
                                       "--seconds", "600", *_each("--key", keys),
                                       log=f"intruder-{name}-read.log")
        for p in listeners.values():
            if not _wait_line(p, '"ready"', 60):
                raise RuntimeError(f"{p.host}: a listener did not start; see {p.log_path}")
        procs: dict[tuple[str, str], Process] = {}
        for name, conf in configs.items():
            c = ["--config", str(conf)]
            procs[name, "put"] = h.python(
                "intruder", "sctd.bench.netns", "put", *c, "--n", str(n), "--settle", "3",
                "--payload", json.dumps({"v": 1, "intruder": name, **STEADY_INPUT}),
                *_each("--key", keys), log=f"intruder-{name}-put.log")
            for what, key, payload in self._asks():
                procs[name, what] = h.python("intruder", "sctd.bench.netns", "query", *c, "--key", key,
                                             "--payload", payload, "--settle", "1",
                                             log=f"intruder-{name}-{what}.log")
        procs["control", "put"] = h.python(
            "input", "sctd.bench.netns", "put", "--config", str(self.config("sctd-input")), "--n", str(n),
            "--settle", "3", "--payload", json.dumps({"v": 1, "intruder": "control", **STEADY_INPUT}),
            "--key", k.input("intruder"), log="control-put.log")
        controls: list[tuple[str, str, str | None]] = [
            ("summary", k.skill, None), ("swap", k.skill + "/swap", "{}"), ("train", k.learner, '{"bad": 1}')]
        for what, key, pay in controls:
            procs["control", what] = h.python("observer", "sctd.bench.netns", "query", *op, "--key", key,
                                              *(() if pay is None else ("--payload", pay)),
                                              log=f"control-{what}.log")
        got = {what: _result(p, 90) for what, p in procs.items()}
        time.sleep(1.0)  # the last messages on their way
        for p in listeners.values():
            p.stop()
        heard = {name: _result(p, 10) for name, p in listeners.items()}
        out: dict[str, dict] = {}
        for name in [*intruders, "control"]:
            out[name] = {"delivered": heard["watch"]["marked"].get(name, {}),
                         "sent": sum(got[name, "put"]["sent"].values()),
                         "tried": got[name, "put"]["tried"],
                         "refused": got[name, "put"].get("refused"),
                         **{what: r for (who, what), r in got.items()
                            if who == name and what != "put"}}
            if name in heard:
                out[name]["received"] = heard[name]["counts"]
        return out

    def _asks(self) -> list[tuple[str, str, str]]:
        """What an intruder asks: a swap on both queryables that take bundles, and
        training (name, key, JSON payload)."""
        k = self.keys
        return [("swap-on-skill", k.skill, '{"bundle": "intruder"}'),
                ("swap", k.skill + "/swap", '{"bundle": "intruder"}'),
                ("train", k.learner, '{"task": "pour", "intruder": true}')]

    # -- what the observer recorded
    def seen(self, key: str, since: float = 0.0) -> Iterator[dict[str, Any]]:
        """Records on ``key`` that arrived at the observer after ``since`` (Unix time)."""
        self._read_records()
        for r in self._seen.get(key, ()):
            if r["t"] > since:
                yield r

    def _read_records(self) -> None:
        """Parse the lines the recorder added since the last call (whole lines only)."""
        if not self.records.exists():
            return
        with open(self.records, "rb") as f:
            f.seek(self._offset)
            chunk = f.read()
        end = chunk.rfind(b"\n") + 1
        self._offset += end
        for line in chunk[:end].splitlines():
            r = json.loads(line)
            if isinstance(r["msg"], dict):
                self._seen.setdefault(r["key"], []).append(r)

    def last(self, key: str, since: float = 0.0) -> dict[str, Any] | None:
        records = list(self.seen(key, since))
        return records[-1] if records else None

    def first(self, key: str, since: float = 0.0) -> dict[str, Any] | None:
        return next(self.seen(key, since), None)


def _each(flag: str, values: list[str]) -> list[str]:
    return [x for v in values for x in (flag, v)]


def _wait_line(p: Process, text: str, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end and p.running():
        if text in p.output():
            return True
        time.sleep(0.05)
    return text in p.output()


def _result(p: Process, seconds: float) -> dict:
    """The last JSON line of a probe once it has ended."""
    try:
        p.p.wait(seconds)
    except subprocess.TimeoutExpired:
        p.stop()
    got = last_json(p.output())
    if got is None or "ready" in got:
        raise RuntimeError(f"{p.host}: {' '.join(p.argv[2:5])}: no result; see {p.log_path}")
    return got


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
    with Cluster(logdir) as c:
        h = c.hosts
        c.start_router()
        robot, runtime = c.start_robot(), c.start_runtime()
        observer = c.start_observer()
        echo = h.python("runtime", "sctd.bench.netns", "echo", "--config",
                        str(c.config("sctd-runtime")), log="echo.log")
        _wait(lambda: c.first(c.keys.target), 60, "first target on the observer host",
              robot, runtime, observer, echo)
        n = int(seconds * input_rate)
        ping = h.call("input", "sctd.bench.netns", "ping", "--config", str(c.config("sctd-input")),
                      "--rate", str(input_rate), "--n", str(n + n // 10), "--warmup", str(n // 10),
                      timeout=seconds + 90)
        # sctd.bench.latency's probe: its echo phase (on sctd/bench/*, which the roles
        # policy denies) kept short, then input -> target as in ``sctd bench latency``
        probe = h.call("input", "sctd.bench.latency", "probe", "--rate", str(input_rate),
                       "--seconds", str(seconds), "--echo-seconds", "0.1", *c._zargs("input"),
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

