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

What runs in the hosts is up to the caller: :mod:`sctd.deploy.cluster` puts sctd's
programs there, and :mod:`sctd.deploy.probe` is the Zenoh probe it measures with.
"""

from __future__ import annotations

import ipaddress
import json
import os
import re
import secrets
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO

PREFIX = "sctd-"
DEFAULT_SUBNET = "10.213.13.0/24"
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
    start: int = 0
    """Where this program's output begins in ``log_path`` (a log is appended to, so a
    folder used before keeps the earlier programs' lines)."""

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
        """What this program printed (not what earlier ones left in the same log)."""
        if not self._log.closed:
            self._log.flush()
        with open(self.log_path, "rb") as f:
            f.seek(self.start)
            return f.read().decode(errors="replace")


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
        start = fh.tell()
        fh.write(f"# {host}: {' '.join(argv)}\n".encode())
        fh.flush()
        p = subprocess.Popen(["ip", "netns", "exec", self.ns(host), *argv], stdout=fh,
                             stderr=subprocess.STDOUT, start_new_session=True,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        proc = Process(host, list(argv), path, p, fh, start)
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
