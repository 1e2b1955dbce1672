"""Real hosts on one machine: Linux network namespaces joined by a bridge.

:class:`Hosts` makes one network namespace per host and one more for the switch: a
Linux bridge ``br0`` living in that switch namespace, and one veth pair per host, its
``eth0`` end in the host and its other end (``p<i>``) on the bridge. Nothing is added
to the root namespace; the hosts' addresses (``10.213.13.0/24`` by default) exist
only inside these namespaces, so no packet leaves the machine. Programs run inside a
host with ``ip netns exec`` (the environment kept, output to a log file); a host's link
can be taken down and up again on the switch side; on exit every process left in the
namespaces is killed and the namespaces are deleted, also after an exception.

Names are ``sctd-<pid>-<random>-<host>``, unique per run, so runs in parallel cannot
clash; :func:`sweep_stale` deletes the namespaces of runs whose process is gone (a run
killed with SIGKILL cannot clean up after itself).

The module is also the probe program the tests and ``sctd bench multihost`` run inside
a namespace (``python -m sctd.bench.netns listen|record|put|query|echo|ping ...``), each
printing JSON lines; see :func:`main`. The router in a namespace is ``sctd router``
itself, with the plain config of :func:`router_config` or the one ``sctd certs`` wrote.
"""

from __future__ import annotations

import argparse
import ipaddress
import json
import os
import re
import secrets
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

import msgpack
import zenoh

from sctd.timing import wait_until
from sctd.wire.session import MSGPACK, TEXT, make_config

PREFIX = "sctd-"
DEFAULT_SUBNET = "10.213.13.0/24"
ROUTER_PORT = 7447
_NETNS_DIR = Path("/run/netns")
_NAME = re.compile(r"^sctd-(\d+)-[0-9a-f]+-")


class NamespaceError(RuntimeError):
    """Network namespaces cannot be made here (not root, no ``ip`` command, or the
    kernel refuses); the message says which."""


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess:
    r = subprocess.run(["ip", *args], capture_output=True, text=True)
    if check and r.returncode != 0:
        raise NamespaceError(f"ip {' '.join(args)}: {r.stderr.strip() or 'exit ' + str(r.returncode)}")
    return r


def can_make_namespaces() -> str | None:
    """None when namespaces can be made here, else why not (for a test's skip reason)."""
    if shutil.which("ip") is None:
        return "the ip command (iproute2) is not installed"
    if os.geteuid() != 0:
        return f"network namespaces need root (running as uid {os.geteuid()})"
    name = f"{PREFIX}{os.getpid()}-{secrets.token_hex(3)}-check"
    r = _ip("netns", "add", name, check=False)
    if r.returncode != 0:
        return f"ip netns add failed: {r.stderr.strip()}"
    _ip("netns", "del", name, check=False)
    return None


def namespaces(prefix: str = PREFIX) -> list[str]:
    """The network namespaces whose names start with ``prefix``."""
    r = _ip("netns", "list", check=False)
    names = [line.split()[0] for line in r.stdout.splitlines() if line.strip()]
    return [n for n in names if n.startswith(prefix)]


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _kill_all_in(ns: str) -> None:
    """SIGKILL every process in namespace ``ns`` (``ip netns pids``)."""
    r = _ip("netns", "pids", ns, check=False)
    for pid in r.stdout.split():
        try:
            os.kill(int(pid), signal.SIGKILL)
        except (ProcessLookupError, ValueError):
            pass


def sweep_stale() -> list[str]:
    """Delete the namespaces (and their processes) of runs whose process is gone; the
    names of those deleted."""
    gone = []
    for ns in namespaces():
        m = _NAME.match(ns)
        if m and not _alive(int(m.group(1))):
            _kill_all_in(ns)
            _ip("netns", "del", ns, check=False)
            gone.append(ns)
    return gone


@dataclass
class Process:
    """A program running inside a host's namespace (``ip netns exec`` execs it, so the
    pid is the program's own); a context manager that stops it."""

    host: str
    argv: list[str]
    log_path: Path
    p: subprocess.Popen
    _log: IO[bytes]

    def __enter__(self) -> Process:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def running(self) -> bool:
        return self.p.poll() is None

    def kill(self) -> int:
        """SIGKILL at once (a host that crashes or loses power); the exit code (-9 unless
        it had ended already)."""
        if self.p.poll() is None:
            os.killpg(self.p.pid, signal.SIGKILL)
        return self.p.wait()

    def stop(self, timeout: float = 10.0) -> int:
        """SIGTERM, then SIGKILL after ``timeout`` s; the exit code (-9 when it had to be
        killed)."""
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
            try:
                self.p.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.p.pid, signal.SIGKILL)
                self.p.wait()
        if not self._log.closed:
            self._log.close()
        return self.p.returncode

    def output(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")


class Hosts:
    """Network namespaces for ``names``, one address each, joined by one bridge.

    Parameters
    ----------
    names : sequence of str
        Host names (short: letters, digits, ``-``); host ``i`` gets the address
        ``subnet[i + 1]``.
    logdir : Path
        Folder for the logs of the programs run with :meth:`run`.
    subnet : str
        An IPv4 /24 (or larger) that exists only inside these namespaces.

    Raises
    ------
    NamespaceError
        On entry, when namespaces cannot be made (see :func:`can_make_namespaces`).
    """

    def __init__(self, names: Sequence[str], logdir: Path, subnet: str = DEFAULT_SUBNET):
        for n in names:
            if not re.fullmatch(r"[a-z][a-z0-9-]{0,15}", n):
                raise ValueError(f"host name {n!r}: lowercase letters, digits, '-', at most 16")
        if len(set(names)) != len(names):
            raise ValueError(f"host names {list(names)}: not unique")
        self.names = list(names)
        self.logdir = Path(logdir)
        self.net = ipaddress.ip_network(subnet)
        if self.net.num_addresses < len(names) + 2:
            raise ValueError(f"subnet {subnet}: too small for {len(names)} hosts")
        self.run_id = f"{PREFIX}{os.getpid()}-{secrets.token_hex(3)}"
        self.switch = f"{self.run_id}-switch"
        self._procs: list[Process] = []
        self._made: list[str] = []

    # -- names and addresses
    def ns(self, host: str) -> str:
        """The namespace of ``host``."""
        if host not in self.names:
            raise KeyError(f"host {host!r}: not one of {self.names}")
        return f"{self.run_id}-{host}"

    def addr(self, host: str) -> str:
        """The IPv4 address of ``host`` (inside the namespaces only)."""
        return str(self.net[self.names.index(host) + 1])

    def port_of(self, host: str) -> str:
        """The switch-side veth of ``host`` (in the switch namespace)."""
        return f"p{self.names.index(host)}"

    # -- life cycle
    def __enter__(self) -> Hosts:
        why = can_make_namespaces()
        if why is not None:
            raise NamespaceError(why)
        sweep_stale()
        self.logdir.mkdir(parents=True, exist_ok=True)
        try:
            self._build()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _add_ns(self, ns: str) -> None:
        _ip("netns", "add", ns)
        self._made.append(ns)
        _ip("-n", ns, "link", "set", "lo", "up")

    def _build(self) -> None:
        self._add_ns(self.switch)
        sw = self.switch
        _ip("-n", sw, "link", "add", "br0", "type", "bridge")
        _ip("-n", sw, "link", "set", "br0", "up")
        plen = self.net.prefixlen
        for host in self.names:
            ns, port = self.ns(host), self.port_of(host)
            self._add_ns(ns)
            _ip("-n", sw, "link", "add", port, "type", "veth", "peer", "name", "eth0", "netns", ns)
            _ip("-n", sw, "link", "set", port, "master", "br0")
            _ip("-n", sw, "link", "set", port, "up")
            _ip("-n", ns, "addr", "add", f"{self.addr(host)}/{plen}", "dev", "eth0")
            _ip("-n", ns, "link", "set", "eth0", "up")

    def close(self) -> None:
        """Stop every program, kill whatever is left in the namespaces, delete them."""
        for proc in self._procs:
            try:
                proc.stop(timeout=3.0)
            except OSError:
                pass
        for ns in reversed(self._made):
            _kill_all_in(ns)
        for ns in reversed(self._made):
            r = _ip("netns", "del", ns, check=False)
            for _ in range(20):  # a namespace busy for a moment after its last process
                if r.returncode == 0 or ns not in namespaces(ns):
                    break
                time.sleep(0.05)
                r = _ip("netns", "del", ns, check=False)
        self._made.clear()

    def leftovers(self) -> list[str]:
        """The namespaces of this run that still exist (empty after :meth:`close`)."""
        return namespaces(self.run_id)

    # -- programs
    def run(self, host: str, argv: Sequence[str], log: str) -> Process:
        """Start ``argv`` inside ``host``, its output to ``logdir/log``; the environment
        (``PATH``, ``SCTD_STORE``, the virtual environment) is kept."""
        path = self.logdir / log
        fh = open(path, "ab")
        fh.write(f"# {host}: {' '.join(argv)}\n".encode())
        fh.flush()
        p = subprocess.Popen(["ip", "netns", "exec", self.ns(host), *argv], stdout=fh,
                             stderr=subprocess.STDOUT, start_new_session=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        proc = Process(host, list(argv), path, p, fh)
        self._procs.append(proc)
        return proc

    def python(self, host: str, module: str, *args: str, log: str) -> Process:
        """``python -m module args`` inside ``host`` (this interpreter)."""
        return self.run(host, [sys.executable, "-m", module, *args], log)

    def call(self, host: str, module: str, *args: str, timeout: float = 60.0) -> dict:
        """Run ``python -m module args`` inside ``host`` to its end and return the last
        JSON line it printed."""
        r = subprocess.run(["ip", "netns", "exec", self.ns(host), sys.executable, "-m", module, *args],
                           capture_output=True, text=True, timeout=timeout)
        got = last_json(r.stdout)
        if got is None:
            raise RuntimeError(f"{host}: python -m {module} {' '.join(args)}: exit {r.returncode}, "
                               f"no JSON; stderr: {r.stderr.strip()[-2000:]}")
        return got

    # -- links
    def link(self, host: str, up: bool) -> None:
        """Take ``host``'s link down (its cable pulled at the switch) or up again."""
        _ip("-n", self.switch, "link", "set", self.port_of(host), "up" if up else "down")


def last_json(text: str) -> dict | None:
    """The last line of ``text`` that parses as a JSON object."""
    for line in reversed(text.splitlines()):
        line = line.strip()
        if line.startswith("{"):
            try:
                return json.loads(line)
            except ValueError:
                continue
    return None


# -- plain TCP Zenoh configs (until the secured ones of ``sctd certs`` are used)

def router_config(listen: str) -> dict:
    """A Zenoh router listening on ``listen``, multicast scouting off."""
    return {"mode": "router", "listen": {"endpoints": [listen]},
            "scouting": {"multicast": {"enabled": False}},
            "transport": {"shared_memory": {"enabled": False}}}


def client_config(router: str, timeout_ms: int = -1) -> dict:
    """A Zenoh client of the router at ``router`` that retries forever (also after the
    router restarts), multicast scouting off. ``timeout_ms``: how long opening the
    session waits for the router (-1: until it is there)."""
    retry = {"period_init_ms": 100, "period_max_ms": 500, "period_increase_factor": 2}
    return {"mode": "client",
            "connect": {"endpoints": [router], "timeout_ms": timeout_ms, "exit_on_failure": False,
                        "retry": retry},
            "scouting": {"multicast": {"enabled": False}},
            "transport": {"shared_memory": {"enabled": False}}}


def tls_client_config(router: str, ca: Path, cert: Path | None = None,
                      key: Path | None = None, timeout_ms: int = 3000) -> dict:
    """A Zenoh client of the TLS router at ``router`` that trusts ``ca``, presenting the
    certificate ``cert`` (private key ``key``) or, without them, none; opening the session
    gives up waiting after ``timeout_ms`` (a refused client would wait forever)."""
    conf = client_config(router, timeout_ms)
    tls: dict = {"root_ca_certificate": str(ca), "verify_name_on_connect": True}
    if cert is not None and key is not None:
        tls.update(connect_certificate=str(cert), connect_private_key=str(key), enable_mtls=True)
    conf["transport"]["link"] = {"protocols": ["tls"], "tls": tls}
    return conf


def sign_certificate(ca_dir: Path, name: str, out: Path) -> tuple[Path, Path]:
    """A client certificate with common name ``name`` signed by the CA in ``ca_dir``
    (``ca.pem``, ``ca-key.pem``), EC P-256, made with the openssl command line; the
    (certificate, key) paths in ``out``."""
    if shutil.which("openssl") is None:
        raise RuntimeError("openssl: not found on PATH")
    out.mkdir(parents=True, exist_ok=True)
    cert, key, csr, ext = (out / f"{name}.pem", out / f"{name}-key.pem", out / f"{name}.csr",
                           out / f"{name}.ext")
    ext.write_text("basicConstraints=critical,CA:FALSE\nkeyUsage=critical,digitalSignature\n"
                   "extendedKeyUsage=clientAuth\n")
    for argv in (["req", "-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes",
                  "-subj", f"/CN={name}", "-keyout", str(key), "-out", str(csr)],
                 ["x509", "-req", "-in", str(csr), "-CA", str(ca_dir / "ca.pem"), "-CAkey",
                  str(ca_dir / "ca-key.pem"), "-CAcreateserial", "-CAserial", str(out / "ca.srl"),
                  "-days", "30", "-extfile", str(ext), "-out", str(cert)]):
        r = subprocess.run(["openssl", *argv], capture_output=True, text=True)
        if r.returncode != 0:
            raise RuntimeError(f"openssl {argv[0]}: {r.stderr.strip()}")
    return cert, key


def write_config(path: Path, conf: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(conf, indent=2))
    return path


# -- the probe program: Zenoh sessions inside a namespace

class _Refused(Exception):
    """The session could not be opened (the router refused or is not there)."""


def _open(config: str) -> zenoh.Session:
    try:
        return zenoh.open(zenoh.Config.from_file(config))
    except zenoh.ZError as e:
        raise _Refused(str(e)) from None


def listen_main(args: argparse.Namespace) -> int:
    """Count the samples arriving on each key expression for ``--seconds``, and the Unix
    time of the first one per key. With ``--mark NAME`` only msgpack maps that have the
    field NAME count, per value of that field (``marked``: value -> key -> count)."""
    counts = {k: 0 for k in args.key}
    marked: dict[str, dict[str, int]] = {}
    first: dict[str, float] = {}
    lock = threading.Lock()
    try:
        s = _open(args.config)
    except _Refused as e:
        print(json.dumps({"ready": True, "refused": str(e)}), flush=True)
        print(json.dumps({"counts": counts, "marked": marked, "first": first, "refused": str(e)}))
        return 0
    subs = []
    for key in args.key:
        def on(sample: zenoh.Sample, key: str = key) -> None:
            mark = None
            if args.mark is not None:
                try:
                    msg = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
                except (ValueError, msgpack.UnpackException):
                    return
                if not isinstance(msg, dict) or args.mark not in msg:
                    return
                mark = str(msg[args.mark])
            with lock:
                counts[key] += 1
                first.setdefault(key, time.time())
                if mark is not None:
                    per_key = marked.setdefault(mark, {})
                    per_key[key] = per_key.get(key, 0) + 1
        subs.append(s.declare_subscriber(key, on))
    print(json.dumps({"ready": True}), flush=True)
    stop = threading.Event()
    wait_until(stop, args.seconds)
    for sub in subs:
        sub.undeclare()
    s.close()
    with lock:
        print(json.dumps({"counts": counts, "marked": marked, "first": first}), flush=True)
    return 0


def record_main(args: argparse.Namespace) -> int:
    """Write every sample on ``--key`` to ``--out`` as JSON lines ``{"key", "t",
    "msg"}`` (``t``: arrival, Unix time; ``msg``: the msgpack map, only ``--field``
    fields if given), until SIGTERM."""
    fields = set(args.field or ())
    lock = threading.Lock()
    out = open(args.out, "a", buffering=1)

    def on(sample: zenoh.Sample) -> None:
        t = time.time()
        try:
            msg = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
        except (ValueError, msgpack.UnpackException):
            msg = None
        if isinstance(msg, dict) and fields:
            msg = {k: v for k, v in msg.items() if k in fields}
        line = json.dumps({"key": str(sample.key_expr), "t": t, "msg": msg}, default=repr)
        with lock:
            out.write(line + "\n")

    stop = threading.Event()
    limits = [(key, args.max_rate) for key in args.key] if args.max_rate else []
    s = zenoh.open(make_config(config_file=args.config, rate_limits=limits))
    subs = [s.declare_subscriber(key, on) for key in args.key]
    wait_until(stop)
    for sub in subs:
        sub.undeclare()
    s.close()
    with lock:
        out.close()
    return 0


def put_main(args: argparse.Namespace) -> int:
    """Put ``--n`` msgpack maps (``--payload`` JSON) on each ``--key``, ``--rate`` Hz."""
    sent = {k: 0 for k in args.key}
    try:
        s = _open(args.config)
    except _Refused as e:
        print(json.dumps({"sent": sent, "tried": args.n * len(args.key), "refused": str(e)}))
        return 0
    time.sleep(args.settle)  # let the declarations of the others reach this session
    payload = json.loads(args.payload)
    block = zenoh.CongestionControl.BLOCK
    for i in range(args.n):
        for key in args.key:
            msg = dict(payload, seq=i, stamp=time.time())
            # blocking, not dropped when a queue is full: the count must be what was sent
            s.put(key, msgpack.packb(msg, use_bin_type=True), congestion_control=block, encoding=MSGPACK)
            sent[key] += 1
        time.sleep(1.0 / args.rate)
    time.sleep(0.3)
    s.close()
    print(json.dumps({"sent": sent, "tried": args.n * len(args.key)}), flush=True)
    return 0


def query_main(args: argparse.Namespace) -> int:
    """One query on ``--key`` (msgpack ``--payload`` JSON, if any); how many ok and
    error replies arrived."""
    try:
        s = _open(args.config)
    except _Refused as e:
        print(json.dumps({"ok": 0, "err": 0, "refused": str(e)}))
        return 0
    time.sleep(args.settle)
    kw = {} if args.payload is None else {"payload": msgpack.packb(json.loads(args.payload),
                                                                    use_bin_type=True)}
    ok = err = 0
    for reply in s.get(args.key, timeout=args.timeout, **kw):
        if reply.ok is not None:
            ok += 1
        else:
            err += 1
    s.close()
    print(json.dumps({"ok": ok, "err": err}), flush=True)
    return 0


# The echo runs on keys the roles may use, so it takes the same path through the router's
# access control as input and target: the input role publishes ``input/**``, the runtime
# role subscribes to it and publishes ``target``, which the input role may read. The robot
# name ``echo`` keeps it apart from the robot's own keys.
ECHO_PING = "sctd/echo/input/ping"
ECHO_PONG = "sctd/echo/target"


def echo_main(args: argparse.Namespace) -> int:
    """Republish every ``ECHO_PING`` sample on ``ECHO_PONG`` until SIGTERM (run it in the
    runtime's role)."""
    stop = threading.Event()
    with _open(args.config) as s, s.declare_publisher(ECHO_PONG, express=True, encoding=TEXT) as pub, \
            s.declare_subscriber(ECHO_PING, lambda sample: pub.put(sample.payload.to_bytes())):
        print(json.dumps({"ready": True}), flush=True)
        wait_until(stop)
    return 0


def ping_main(args: argparse.Namespace) -> int:
    """Ping the echo ``--n`` times at ``--rate`` Hz (in the input's role); the round-trip
    summary (ms) after ``--warmup`` pings."""
    from sctd.timing import RoundTrips, Ticker
    trips = RoundTrips()
    with _open(args.config) as s, \
            s.declare_subscriber(ECHO_PONG, lambda sample: trips.answered(
                int(sample.payload.to_bytes()), time.monotonic())), \
            s.declare_publisher(ECHO_PING, express=True, encoding=TEXT) as pub:
        time.sleep(args.settle)
        ticker = Ticker(1.0 / args.rate, spin=0.0)
        for seq in range(args.n):
            ticker.wait()
            trips.counting = seq >= args.warmup
            trips.sent(seq)
            pub.put(str(seq).encode())
        time.sleep(0.3)
    print(json.dumps({"echo_rtt_ms": trips.histogram.summary_ms(), "pongs": trips.answers}), flush=True)
    return 0


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m sctd.bench.netns",
                                description="Zenoh probes run inside a host's namespace")
    sub = p.add_subparsers(dest="cmd", required=True)
    lis = sub.add_parser("listen", help="count samples per key")
    lis.add_argument("--config", required=True)
    lis.add_argument("--key", action="append", required=True)
    lis.add_argument("--seconds", type=float, default=5.0)
    lis.add_argument("--mark", default=None, help="count only msgpack maps with this field")
    lis.set_defaults(func=listen_main)
    rec = sub.add_parser("record", help="samples on keys to a JSON-lines file until SIGTERM")
    rec.add_argument("--config", required=True)
    rec.add_argument("--key", action="append", required=True)
    rec.add_argument("--field", action="append", help="keep only these fields (repeatable)")
    rec.add_argument("--out", required=True)
    rec.add_argument("--max-rate", type=float, default=None,
                     help="Hz: take at most this many samples per second of each key (Zenoh's "
                          "downsampling, on arrival)")
    rec.set_defaults(func=record_main)
    put = sub.add_parser("put", help="put msgpack maps on keys")
    put.add_argument("--config", required=True)
    put.add_argument("--key", action="append", required=True)
    put.add_argument("--n", type=int, default=10)
    put.add_argument("--rate", type=float, default=50.0)
    put.add_argument("--settle", type=float, default=1.0)
    put.add_argument("--payload", default="{}")
    put.set_defaults(func=put_main)
    q = sub.add_parser("query", help="one query, count replies")
    q.add_argument("--config", required=True)
    q.add_argument("--key", required=True)
    q.add_argument("--payload", default=None)
    q.add_argument("--timeout", type=float, default=3.0)
    q.add_argument("--settle", type=float, default=1.0)
    q.set_defaults(func=query_main)
    e = sub.add_parser("echo", help=f"republish {ECHO_PING} on {ECHO_PONG} until SIGTERM")
    e.add_argument("--config", required=True)
    e.set_defaults(func=echo_main)
    pg = sub.add_parser("ping", help="round trips to the echo")
    pg.add_argument("--config", required=True)
    pg.add_argument("--n", type=int, default=5000)
    pg.add_argument("--rate", type=float, default=500.0)
    pg.add_argument("--warmup", type=int, default=500)
    pg.add_argument("--settle", type=float, default=1.0)
    pg.set_defaults(func=ping_main)
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    return int(args.func(args))


if __name__ == "__main__":
    sys.exit(main())
