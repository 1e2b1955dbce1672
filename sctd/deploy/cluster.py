"""sctd across real hosts on this machine: :class:`Cluster`, the setup that
``tests/test_multihost.py`` checks and ``sctd bench multihost`` measures.

In the namespaces of :class:`~sctd.deploy.netns.Hosts`,
- ``router``: ``sctd router``, on ``tcp/<router>:7447`` or, with ``sctd certs``'s
  configs (mutual TLS and the roles' access control), ``tls/<router>:7448``;
- ``robot``: ``sctd sim --task pour`` (the cluster's task: by default the one of
  ``sctd/app/defaults.yaml``);
- ``runtime``: ``sctd run --skill pour`` (its skill, by default that file's);
- ``input``: the simulated user (on the cluster's task), or a steady input source;
- ``learner``: ``sctd learner``;
- ``observer``: a recorder of the contract's keys (JSON lines, see
  ``python -m sctd.deploy.probe record``), and the live view (``sctd view``) when asked;
- ``intruder``: probes that try to read, write and query (:meth:`Cluster.intrude`).
Every program is a Zenoh client of the router, configured only by its role's file.

:meth:`Cluster.fault` puts a fault proxy (:mod:`sctd.deploy.linkproxy`) on a host's link
to the router: the host's programs started after it connect through it.
"""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from sctd.app.defaults import defaults
from sctd.task import Task
from sctd.wire import Keys

from .configs import (
    ROUTER_PORT,
    client_config,
    router_config,
    sign_certificate,
    tls_client_config,
    write_config,
)
from .linkfault import LinkFault
from .linkproxy import LinkControl
from .netns import Hosts, Process, last_json

HOSTS = ("router", "robot", "runtime", "input", "learner", "observer", "intruder")
ROLE_OF_HOST = {"router": "sctd-router", "robot": "sctd-robot", "runtime": "sctd-runtime",
                "input": "sctd-input", "learner": "sctd-learner", "observer": "sctd-observer"}
# The client roles the cluster uses: the hosts' and the operator's, who watches for intruders.
CLIENT_ROLES = ("sctd-robot", "sctd-runtime", "sctd-input", "sctd-learner", "sctd-observer",
                "sctd-operator")
STEADY_INPUT = {"v": 1, "u": [0.0, 0.0, 0.0], "buttons": [0, 1, 0]}  # deadman held, stick at rest
TLS_PORT = 7448


def contract_keys(task: Task) -> tuple[str, ...]:
    """Every key of the wire contract an intruder could write to while ``task`` runs, as
    suffixes of ``sctd/<robot>/``: its object's and its demonstrations' among them."""
    return ("input/intruder", "state", f"objects/{task.object}", "target", "status", "scene", "can",
            f"demos/{task.name}/intruder", "learner/status")


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
    secure : bool, optional
        Mutual TLS and the roles' access control (default: when ``sctd certs`` is there).
    task : Task
        The robot host's scene and the simulated user's task (its name goes on their
        command lines; whoever starts the cluster resolves it, by default the task of
        ``sctd/app/defaults.yaml``).
    skill : str, optional
        The runtime's skill (default: the skill of ``sctd/app/defaults.yaml``).
    udp : tuple of str
        Hosts whose link to the router runs over UDP (Zenoh's unreliable unicast link,
        where datagrams can be lost): the router listens on ``udp/<router>:7447`` too, and
        a fault on such a host's link (:meth:`fault`) is a proxy of datagrams. Plain
        clusters only (``secure`` False): Zenoh's TLS runs over TCP.
    """

    def __init__(self, logdir: Path, robot: str = "edan", secure: bool | None = None, *,
                 task: Task, skill: str | None = None, udp: tuple[str, ...] = ()):
        self.udp = tuple(udp)
        if self.udp and secure is not False:
            raise ValueError("udp: links over UDP need a plain cluster (secure=False): Zenoh's TLS runs "
                             "over TCP")
        self.task = task
        self.skill = defaults().skill if skill is None else skill
        self.logdir = Path(logdir)
        self.keys = Keys(robot)
        self.hosts = Hosts(HOSTS, self.logdir)
        self.secure = secure_available() if secure is None else secure
        self.router: Process | None = None
        self.records = self.logdir / "observer.jsonl"
        self._configs: dict[str, Path] = {}
        self.intruder_configs: dict[str, Path] = {}
        self._seen: dict[str, list[dict[str, Any]]] = {}
        # a log folder used before keeps the earlier clusters' records: this one reads its own
        self._offset = self.records.stat().st_size if self.records.exists() else 0
        self._router_starts = 0
        self._links: dict[str, FaultedLink] = {}

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
        udp = [f"udp/{self.hosts.addr('router')}:{ROUTER_PORT}"] if self.udp else []
        self._configs["router"] = write_config(d / "router.json5", router_config(self.endpoint, *udp))
        for role in CLIENT_ROLES:
            self._configs[role] = write_config(d / f"{role}.json5", client_config(self.endpoint))

    def _certs(self, out: Path) -> Path:
        """A fresh CA for this cluster: one left in ``out`` by an earlier cluster in the same
        log folder (a resumed ``sctd bench link --record``) signed for that cluster's
        addresses, so it is replaced."""
        r = subprocess.run([sys.executable, "-m", "sctd.cli.main", "certs", "--out", str(out), "--force",
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

    def zenoh_args(self, host: str) -> list[str]:
        """``--zenoh-config`` with the config of ``host``'s role, for an sctd program."""
        return ["--zenoh-config", str(self.config_on(host))]

    def config_on(self, host: str, role: str | None = None) -> Path:
        """The config of ``role`` (default: ``host``'s) for a program on ``host``: the
        role's own file, or, when the host's link has a fault proxy, a copy of it that
        connects to the router through the proxy; over UDP for the hosts of ``udp``."""
        path = self.config(ROLE_OF_HOST[host] if role is None else role)
        link = self._links.get(host)
        if link is None and host not in self.udp:
            return path
        endpoint = link.endpoint if link is not None else f"udp/{self.hosts.addr('router')}:{ROUTER_PORT}"
        text = path.read_text()
        if self.endpoint not in text:
            raise RuntimeError(f"{path}: does not connect to {self.endpoint}; cannot route it through a "
                               "proxy")
        via = self.logdir / "via" / host / path.name
        via.parent.mkdir(parents=True, exist_ok=True)
        via.write_text(text.replace(self.endpoint, endpoint))
        return via

    # -- faults on the links
    def fault(self, src: str, dst: str, fault: LinkFault) -> FaultedLink:
        """Put ``fault`` on what flows from ``src`` to ``dst``, one of them the router
        (every program is a client of the router: the links are each host's to it).

        The first fault on a host's link starts a proxy in the host's namespace
        (``python -m sctd.deploy.linkproxy`` on 127.0.0.1, to the router's endpoint);
        programs started on the host afterwards connect through it. A program already
        running there would not, so that is refused. Another fault on the same link
        (either direction) changes the running proxy. The returned link starts stalls,
        changes faults, resets and reports counters while the programs run.
        """
        host, direction = link_of(src, dst)
        link = self._links.get(host)
        if link is None:
            running = sorted({" ".join(p.argv[2:4]) for p in self.hosts._procs
                              if p.host == host and p.running() and p.argv[2:3] != ["sctd.deploy.linkproxy"]})
            if running:
                raise RuntimeError(f"{host}: programs already run there ({'; '.join(running)}) and talk to "
                                   "the router directly; put the fault on the link before starting them")
            link = self._start_link(host, direction, fault)
        else:
            link.set(direction, fault)
        return link

    def _start_link(self, host: str, direction: str, fault: LinkFault) -> FaultedLink:
        control = self.logdir / f"link-{host}.sock"
        target = self.endpoint.split("/", 1)[1]
        faults = {d: json.dumps((fault if d == direction else LinkFault()).to_dict()) for d in ("up", "down")}
        udp = ["--udp"] if host in self.udp else []
        proc = self.hosts.python(host, "sctd.deploy.linkproxy", "--listen", "127.0.0.1:0", "--target", target,
                                 "--up", faults["up"], "--down", faults["down"], "--control", str(control),
                                 *udp, log=f"link-{host}.log")
        if not _wait_line(proc, '"ready"', 30):
            proc.stop()
            raise RuntimeError(f"{host}: the link's fault proxy did not start; see {proc.log_path}")
        ready = next(json.loads(line) for line in proc.output().splitlines() if '"ready"' in line)
        proto = "udp" if udp else self.endpoint.split("/", 1)[0]
        link = FaultedLink(self, host, proc, LinkControl(control), f"{proto}/{ready['listen']}")
        self._links[host] = link
        return link

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
                                 str(self.logdir / "store"), *self.zenoh_args("learner"), log="learner.log")

    def start_robot(self, *extra: str) -> Process:
        return self.hosts.python("robot", "sctd_sim.service", "--task", self.task.name, *extra,
                                 *self.zenoh_args("robot"), log="robot.log")

    def start_runtime(self, skill: str | None = None, *extra: str) -> Process:
        """``sctd run`` with ``skill`` (default the cluster's)."""
        skill = self.skill if skill is None else skill
        return self.hosts.python("runtime", "sctd.cli.main", "run", "--skill", skill, "--stats-json",
                                 *extra, *self.zenoh_args("runtime"), log="runtime.log")

    def start_observer(self, *keys: str) -> Process:
        """The recorder of ``status``, ``scene``, ``target``, ``state`` and
        ``learner/status`` (and ``keys``, e.g. an input's) on the observer host."""
        k = self.keys
        rec = ["--key", k.status, "--key", k.scene, "--key", k.target, "--key", k.state,
               "--key", k.learner_status, *_each("--key", list(keys)),
               "--field", "seq", "--field", "stamp", "--field", "state", "--field", "mode",
               "--field", "in_seq", "--field", "pose", "--field", "success", "--field", "poured",
               "--field", "targets", "--field", "state_age", "--field", "input_age", "--field", "input",
               "--field", "counters",
               "--field", "done", "--field", "spilled_amount", "--field", "radial", "--field", "tilt",
               "--field", "skipped", "--field", "behind_s"]
        rec += ["--max-rate", "100"]  # of each key: enough to see seq and pose change
        return self.hosts.python("observer", "sctd.deploy.probe", "record", "--config",
                                 str(self.config_on("observer")), "--out", str(self.records), *rec,
                                 log="observer.log")

    def start_view(self, seconds: float) -> Process:
        """``sctd view`` on the observer host with the observer's certificate, for
        ``seconds``; it prints its report as JSON (``--stats-json``) when it stops."""
        return self.hosts.python("observer", "sctd.cli.main", "view", "--task", self.task.name,
                                 "--view-for", str(seconds), "--stats-json", *self.zenoh_args("observer"),
                                 log="view.log")

    def start_steady_input(self) -> Process:
        """Input at 50 Hz, stick at rest and deadman held, until stopped."""
        return self.start_input(STEADY_INPUT)

    def start_input(self, payload: dict[str, Any] | Path, name: str = "steady",
                    rate: float = 50.0) -> Process:
        """Input ``payload`` (``u``, ``buttons``) on ``input/<name>`` at ``rate`` Hz from
        the input host, until stopped (each message with its ``seq`` and ``stamp``); a
        path is a JSON file of the payload (with ``v``), read again whenever it changes
        (:func:`write_payload`): one device whose stick moves."""
        what = ["--payload-file", str(payload)] if isinstance(payload, Path) else \
            ["--payload", json.dumps({"v": 1, **payload})]
        return self.hosts.python("input", "sctd.deploy.probe", "put", "--config",
                                 str(self.config_on("input")), "--key", self.keys.input(name),
                                 "--n", "100000000", "--rate", str(rate), "--settle", "0",
                                 *what, log=f"input-{name}.log")

    def user(self, seconds: float = 90.0) -> dict:
        """The simulated user doing the cluster's task until done; its JSON report."""
        return self.hosts.call("input", "sctd_services.simulated_user", "--task", self.task.name,
                               "--duration", str(seconds), "--until-done", "--json",
                               *self.zenoh_args("input"), timeout=seconds + 60)

    # -- the intruders
    def intrude(self, intruders: tuple[str, ...] = INTRUDERS, n: int = N_PER_KEY) -> dict:
        """Each intruder (on the intruder host, at once) puts ``n`` marked messages on
        every key of :func:`contract_keys`, subscribes to all of them, asks for a skill
        swap and for training; an operator on the observer host counts the marked
        messages that arrive. The input host puts ``n`` marked input messages too (the
        control: what an allowed sender delivers), the operator asks for a swap and for
        training (the control: the runtime and the learner answer). Per intruder:
        ``delivered`` (key -> marked messages the operator got), ``received`` (key ->
        messages it got), ``swap`` and ``train`` (ok and error replies)."""
        keys = [f"{self.keys.prefix}/{suffix}" for suffix in contract_keys(self.task)]
        configs = {name: self.intruder_configs.get(name, self.config("sctd-observer"))
                   for name in intruders}
        listeners = self._start_listeners(keys, configs)  # each ready before anyone sends
        procs = {**self._start_intruders(keys, configs, n), **self._start_controls(n)}
        got = {what: _result(p, 90) for what, p in procs.items()}
        time.sleep(1.0)  # the last messages on their way
        for p in listeners.values():
            p.stop()
        heard = {name: _result(p, 10) for name, p in listeners.items()}
        return _tally([*intruders, "control"], got, heard)

    def _start_listeners(self, keys: list[str], configs: dict[str, Path]) -> dict[str, Process]:
        """The operator's watch for marked messages and each intruder's subscriptions to
        ``keys`` (until stopped), once all of them are ready."""
        h = self.hosts
        listeners = {"watch": h.python("observer", "sctd.deploy.probe", "listen", *self._operator(),
                                       "--mark", "intruder", "--seconds", "600", *_each("--key", keys),
                                       log="intrusion-watch.log")}
        for name, conf in configs.items():
            listeners[name] = h.python("intruder", "sctd.deploy.probe", "listen", "--config", str(conf),
                                       "--seconds", "600", *_each("--key", keys),
                                       log=f"intruder-{name}-read.log")
        for p in listeners.values():
            if not _wait_line(p, '"ready"', 60):
                raise RuntimeError(f"{p.host}: a listener did not start; see {p.log_path}")
        return listeners

    def _start_intruders(self, keys: list[str], configs: dict[str, Path],
                         n: int) -> dict[tuple[str, str], Process]:
        """Each intruder's puts on ``keys`` and its asks (:meth:`_asks`), by (name, what)."""
        procs: dict[tuple[str, str], Process] = {}
        for name, conf in configs.items():
            c = ["--config", str(conf)]
            procs[name, "put"] = self.hosts.python(
                "intruder", "sctd.deploy.probe", "put", *c, "--n", str(n), "--settle", "3",
                "--payload", json.dumps({"v": 1, "intruder": name, **STEADY_INPUT}),
                *_each("--key", keys), log=f"intruder-{name}-put.log")
            for what, key, payload in self._asks():
                procs[name, what] = self.hosts.python(
                    "intruder", "sctd.deploy.probe", "query", *c, "--key", key, "--payload", payload,
                    "--settle", "1", log=f"intruder-{name}-{what}.log")
        return procs

    def _start_controls(self, n: int) -> dict[tuple[str, str], Process]:
        """What the roles may do, by ("control", what): the input role's marked input, the
        operator's summary, swap and training queries."""
        h, k = self.hosts, self.keys
        procs = {("control", "put"): h.python(
            "input", "sctd.deploy.probe", "put", "--config", str(self.config_on("input")), "--n", str(n),
            "--settle", "3", "--payload", json.dumps({"v": 1, "intruder": "control", **STEADY_INPUT}),
            "--key", k.input("intruder"), log="control-put.log")}
        controls: list[tuple[str, str, str | None]] = [
            ("summary", k.skill, None), ("swap", k.skill + "/swap", "{}"), ("train", k.learner, '{"bad": 1}')]
        for what, key, pay in controls:
            procs["control", what] = h.python("observer", "sctd.deploy.probe", "query", *self._operator(),
                                              "--key", key, *(() if pay is None else ("--payload", pay)),
                                              log=f"control-{what}.log")
        return procs

    def _operator(self) -> list[str]:
        return ["--config", str(self.config_on("observer", "sctd-operator"))]

    def _asks(self) -> list[tuple[str, str, str]]:
        """What an intruder asks: a swap on both queryables that take bundles, and
        training (name, key, JSON payload)."""
        k = self.keys
        return [("swap-on-skill", k.skill, '{"bundle": "intruder"}'),
                ("swap", k.skill + "/swap", '{"bundle": "intruder"}'),
                ("train", k.learner, json.dumps({"task": self.task.name, "intruder": True}))]

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


class FaultedLink:
    """A fault proxy on ``host``'s link to the router (:meth:`Cluster.fault`): ``up`` is
    what the host sends, ``down`` what it receives. Its methods are the proxy's
    (:class:`~sctd.deploy.linkproxy.LinkControl`); a context manager that stops it."""

    def __init__(self, cluster: Cluster, host: str, process: Process, control: LinkControl, endpoint: str):
        self.cluster, self.host, self.process, self.control = cluster, host, process, control
        self.endpoint = endpoint  # the proxy's, in the host's namespace

    def __enter__(self) -> FaultedLink:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def set(self, direction: str, fault: LinkFault) -> None:
        self.control.set(direction, fault)

    def stall(self, seconds: float, direction: str = "both") -> None:
        self.control.stall(seconds, direction)

    def reset(self) -> int:
        return self.control.reset()

    def counters(self) -> dict[str, Any]:
        return self.control.counters()

    def close(self) -> dict[str, Any] | None:
        """Stop the proxy (programs still connected through it lose the router: stop
        them first); the host's programs started afterwards connect directly again. The
        proxy's last counters (None if it printed none)."""
        self.process.stop()
        self.cluster._links.pop(self.host, None)
        got = last_json(self.process.output())
        return None if got is None else got.get("counters")


def write_payload(path: Path, payload: dict[str, Any]) -> None:
    """Set what an input started with ``start_input(path)`` sends (whole, by a rename:
    the sender never reads half a file)."""
    part = path.with_name(path.name + ".part")
    part.write_text(json.dumps({"v": 1, **payload}))
    part.replace(path)


def link_of(src: str, dst: str) -> tuple[str, str]:
    """The host whose link to the router carries ``src -> dst``, and the direction on it
    (``up``: from the host); ValueError when neither or both are the router, or the host
    has no role."""
    if (src == "router") == (dst == "router"):
        raise ValueError(f"link {src} -> {dst}: every program is a client of the router, so a link is "
                         f"a host's to the router: fault('{src}', 'router', ...) and/or "
                         f"fault('router', '{dst}', ...)")
    host = dst if src == "router" else src
    if host not in ROLE_OF_HOST or host == "router":
        raise ValueError(f"link {src} -> {dst}: {host!r} is not a host with a role "
                         f"({', '.join(h for h in ROLE_OF_HOST if h != 'router')})")
    return host, "up" if src == host else "down"


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


def _tally(names: list[str], got: dict[tuple[str, str], dict], heard: dict[str, dict]) -> dict:
    """Per intruder (and the control): what the operator's watch got of its marked
    messages, what it sent and tried, its asks' replies, and what its subscriptions read."""
    out: dict[str, dict] = {}
    for name in names:
        out[name] = {"delivered": heard["watch"]["marked"].get(name, {}),
                     "sent": sum(got[name, "put"]["sent"].values()),
                     "tried": got[name, "put"]["tried"],
                     "refused": got[name, "put"].get("refused"),
                     **{what: r for (who, what), r in got.items()
                        if who == name and what != "put"}}
        if name in heard:
            out[name]["received"] = heard[name]["counts"]
    return out
