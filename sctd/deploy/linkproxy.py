"""The fault proxy: TCP (and UDP) from a listening address to a target, through the
faults of :mod:`sctd.deploy.linkfault`, one schedule per direction of each connection.

:class:`LinkProxy` runs in threads of the process that makes it (a context manager);
``python -m sctd.deploy.linkproxy`` runs one as a program, inside a host's network
namespace for example, with a control socket (a Unix socket: a path on the shared file
system reaches a namespace that its network does not) that :class:`LinkControl` drives.
Both have the same methods: :meth:`~LinkProxy.set` (a direction's fault),
:meth:`~LinkProxy.stall` (a stall from now), :meth:`~LinkProxy.reset` (every connection
now) and :meth:`~LinkProxy.counters`.

TCP: each connection gets a connection to the target, and per direction a reader that
schedules each chunk it receives and a writer that sends them in order at their release
times, holding them through stalls; the end of a stream (FIN) follows its last chunk. A
reset closes both sockets with SO_LINGER 0, so both peers get an RST. Bytes are never
dropped or reordered; while a stall holds more than ``MAX_HELD`` bytes of one direction,
its reader stops reading (the sender's TCP window fills, as it would on the link).

UDP (``udp=True``, the same port): each client address gets a socket connected to the
target; datagrams are dropped with the fault's ``loss`` and the rest released in order
like the chunks of a stream.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from .linkfault import DIRECTIONS, Direction, LinkFault, Schedule

CHUNK = 65536
MAX_HELD = 16 << 20  # bytes a direction of a connection holds before its reader waits
POLL_S = 0.1  # how often a blocked reader looks whether its connection was closed

Address = tuple[str, int]


def parse_address(text: str) -> Address:
    """``HOST:PORT`` -> (host, port); ValueError naming the text."""
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
        raise ValueError(f"{text!r}: expected HOST:PORT")
    return host, int(port)


def _abort(sock: socket.socket) -> None:
    """Close ``sock`` with an RST (SO_LINGER on, timeout 0)."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    except OSError:
        pass
    sock.close()


class _Counters:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.per = {d: {"bytes": 0, "chunks": 0, "delayed": 0, "held": 0, "datagrams": 0, "dropped": 0}
                    for d in DIRECTIONS}
        self.connections = 0
        self.resets = 0

    def add(self, direction: str, **kw: int) -> None:
        with self.lock:
            for k, v in kw.items():
                self.per[direction][k] += v


class _Queue:
    """A direction's chunks waiting for their release: (release, payload); None ends."""

    def __init__(self, cv: threading.Condition) -> None:
        self.cv = cv
        self.items: collections.deque[tuple[float, bytes | None, bool]] = collections.deque()
        self.held = 0


class LinkProxy:
    """A proxy from ``listen`` to ``target`` applying ``up`` (listen -> target) and
    ``down`` (target -> listen) faults; a context manager.

    Parameters
    ----------
    listen, target : (host, port)
        Port 0 in ``listen``: a free one (:attr:`address` says which).
    up, down : LinkFault
    udp : bool
        Forward UDP datagrams on the same port too.
    clock : callable
        Monotonic seconds (the schedule's times count from the proxy's start).
    """

    def __init__(self, listen: Address, target: Address, up: LinkFault | None = None,
                 down: LinkFault | None = None, udp: bool = False,
                 clock: Callable[[], float] = time.monotonic):
        self.target = target
        self.directions = {"up": Direction(up or LinkFault()), "down": Direction(down or LinkFault())}
        self.clock = clock
        self.counts = _Counters()
        self._listen, self._udp = listen, udp
        self._lock = threading.Lock()
        self._conns: list[_Connection] = []
        self._flows: dict[Address, _Flow] = {}
        self._threads: list[threading.Thread] = []
        self._closed = threading.Event()
        self._resets_done = 0
        self.t0 = 0.0
        self.address: Address = listen

    # -- life cycle
    def __enter__(self) -> LinkProxy:
        self._server = socket.create_server(self._listen, reuse_port=False)
        self._server.settimeout(POLL_S)
        self.address = self._server.getsockname()[:2]
        self._udp_sock: socket.socket | None = None
        if self._udp:
            self._udp_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            self._udp_sock.bind(self.address)
            self._udp_sock.settimeout(POLL_S)
        self.t0 = self.clock()
        self._spawn(self._accept_loop, "accept")
        self._spawn(self._reset_loop, "resets")
        if self._udp_sock is not None:
            self._spawn(self._udp_loop, "udp")
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Stop accepting, close every connection (RST) and join the threads."""
        self._closed.set()
        self._reset_all(count=False)
        for t in self._threads:
            t.join(5.0)
        self._server.close()
        if self._udp_sock is not None:
            self._udp_sock.close()

    def now(self) -> float:
        """Seconds since the proxy started (the schedules' time)."""
        return self.clock() - self.t0

    def _spawn(self, fn: Callable[..., None], name: str, *args: Any) -> threading.Thread:
        t = threading.Thread(target=fn, args=args, name=f"linkproxy-{name}", daemon=True)
        t.start()
        self._threads.append(t)
        return t

    # -- control
    def set(self, direction: str, fault: LinkFault) -> None:
        """Replace ``direction``'s fault (its stalls and resets count from the proxy's
        start); the next chunk of every connection follows it."""
        for d in _directions(direction):
            self.directions[d].fault = fault
        self._wake()

    def stall(self, seconds: float, direction: str = "both") -> None:
        """Hold everything in ``direction`` (``up``, ``down`` or ``both``) from now for
        ``seconds``; it leaves in order when the stall ends."""
        LinkFault(stalls=((0.0, seconds),))  # validates
        now = self.now()
        for d in _directions(direction):
            self.directions[d].stalls.append((now, float(seconds)))
        self._wake()

    def reset(self) -> int:
        """Reset every connection now (RST to both sides); how many were open."""
        return self._reset_all(count=True)

    def counters(self) -> dict[str, Any]:
        """Per direction: ``bytes``, ``chunks``, ``delayed`` (chunks that left later than
        they came), ``held`` (chunks a stall held), ``datagrams``, ``dropped``; and
        ``connections`` (accepted), ``open``, ``resets``, ``stalls`` (begun, both
        directions)."""
        now = self.now()
        with self.counts.lock:
            out: dict[str, Any] = {d: dict(v) for d, v in self.counts.per.items()}
            out.update(connections=self.counts.connections, resets=self.counts.resets)
        with self._lock:
            out["open"] = sum(1 for c in self._conns if not c.closed)
        out["stalls"] = sum(self.directions[d].stalls_begun(now) for d in DIRECTIONS)
        return out

    def _wake(self) -> None:
        with self._lock:
            conns = list(self._conns)
            flows = list(self._flows.values())
        for cv in [c.cv for c in conns] + [f.cv for f in flows]:
            with cv:
                cv.notify_all()

    def _reset_all(self, count: bool) -> int:
        with self._lock:
            conns = [c for c in self._conns if not c.closed]
            self._conns = []
        for c in conns:
            c.abort()
        if count:
            with self.counts.lock:
                self.counts.resets += 1
        return len(conns)

    def _forget(self, conn: _Connection) -> None:
        with self._lock:
            if conn in self._conns:
                self._conns.remove(conn)

    def _reset_loop(self) -> None:
        """Reset at the faults' reset times."""
        while not self._closed.wait(0.01):
            times = sorted({*self.directions["up"].fault.resets, *self.directions["down"].fault.resets})
            due = [t for t in times if t <= self.now()]
            if len(due) > self._resets_done:
                self._resets_done = len(due)
                self.reset()

    # -- TCP
    def _accept_loop(self) -> None:
        n = 0
        while not self._closed.is_set():
            try:
                client, _ = self._server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            try:
                upstream = socket.create_connection(self.target, timeout=5.0)
            except OSError:
                _abort(client)
                continue
            conn = _Connection(self, client, upstream, n)
            n += 1
            with self._lock:
                self._conns.append(conn)
            with self.counts.lock:
                self.counts.connections += 1
            conn.start()

    # -- UDP
    def _udp_loop(self) -> None:
        assert self._udp_sock is not None
        n = 0
        while not self._closed.is_set():
            try:
                data, client = self._udp_sock.recvfrom(CHUNK)
            except TimeoutError:
                continue
            except OSError:
                return
            flow = self._flows.get(client)
            if flow is None:
                flow = _Flow(self, client, n)
                n += 1
                with self._lock:
                    self._flows[client] = flow
            flow.up.put(data)


def _directions(direction: str) -> tuple[str, ...]:
    if direction == "both":
        return DIRECTIONS
    if direction not in DIRECTIONS:
        raise ValueError(f"direction: expected up, down or both, got {direction!r}")
    return (direction,)


class _Pump:
    """One direction of one stream: chunks in (:meth:`put`), scheduled, and sent in order
    at their release times by a writer thread through ``send``."""

    def __init__(self, proxy: LinkProxy, name: str, stream: int, cv: threading.Condition,
                 send: Callable[[bytes], object], end: Callable[[], None], datagrams: bool):
        self.proxy, self.name, self.cv = proxy, name, cv
        self.direction = proxy.directions[name]
        self.schedule = Schedule(self.direction, name, stream)
        self.queue = _Queue(cv)
        self.send, self.end, self.datagrams = send, end, datagrams
        self.closed = False
        self.failed: Callable[[], None] = lambda: None  # a send failed (the peer is gone)

    def put(self, data: bytes | None) -> None:
        """Schedule ``data`` (None: the end of the stream, after everything before it)."""
        p = self.proxy
        if data is not None and self.datagrams:
            p.counts.add(self.name, datagrams=1)
            if self.schedule.drops():
                p.counts.add(self.name, dropped=1)
                return
        t = p.now()
        release = self.schedule.release(t, len(data or b""))
        if data is not None:
            p.counts.add(self.name, bytes=len(data), chunks=1, delayed=int(release > t))
        with self.cv:
            while data is not None and self.queue.held > MAX_HELD and not self.closed:
                self.cv.wait(POLL_S)
            self.queue.items.append((release, data, self.schedule.held))
            self.queue.held += len(data or b"")
            self.cv.notify_all()

    def _next(self) -> tuple[bytes | None, bool] | None:
        """The next chunk once it is due and no stall holds it, and whether a stall held
        it; None when the stream was closed."""
        held = False
        with self.cv:
            while not self.closed:
                now = self.proxy.now()
                if not self.queue.items:
                    self.cv.wait(POLL_S)
                    continue
                release, data, held_before = self.queue.items[0]
                if now < release:
                    self.cv.wait(release - now)
                    continue
                end = self.direction.stall_end(now)
                if end > now:
                    held = True
                    self.cv.wait(end - now)
                    continue
                self.queue.items.popleft()
                self.queue.held -= len(data or b"")
                self.cv.notify_all()
                return data, held or held_before
        return None

    def write_loop(self) -> None:
        while True:
            got = self._next()
            if got is None:
                return
            data, held = got
            if held:
                self.proxy.counts.add(self.name, held=1)
            try:
                if data is None:
                    self.end()
                    return
                self.send(data)
            except OSError:
                self.failed()
                return


class _Connection:
    """One TCP connection: the client's socket, the target's, a pump per direction."""

    def __init__(self, proxy: LinkProxy, client: socket.socket, upstream: socket.socket, n: int):
        self.proxy, self.client, self.upstream = proxy, client, upstream
        self.cv = threading.Condition()
        self.closed = False
        for s in (client, upstream):
            s.settimeout(POLL_S)
            s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.pumps = {
            "up": _Pump(proxy, "up", n, self.cv, upstream.sendall, lambda: self._ended(upstream), False),
            "down": _Pump(proxy, "down", n, self.cv, client.sendall, lambda: self._ended(client), False)}
        for p in self.pumps.values():
            p.failed = self.abort
        self._n = n
        self._ends = 0

    def start(self) -> None:
        for name, src in (("up", self.client), ("down", self.upstream)):
            self.proxy._spawn(self._read_loop, f"{self._n}-{name}-read", src, self.pumps[name])
            self.proxy._spawn(self.pumps[name].write_loop, f"{self._n}-{name}-write")

    def _read_loop(self, src: socket.socket, pump: _Pump) -> None:
        while not self.closed:
            try:
                data = src.recv(CHUNK)
            except TimeoutError:
                continue
            except (OSError, ValueError):
                break
            pump.put(data or None)
            if not data:
                return
        pump.put(None)

    def _ended(self, sock: socket.socket) -> None:
        """One direction's stream ended (its FIN passed on); once both have, the
        connection is over."""
        try:
            sock.shutdown(socket.SHUT_WR)
        except OSError:
            pass
        with self.cv:
            self._ends += 1
            over = self._ends == 2 and not self.closed
            if over:
                self.closed = True
                for p in self.pumps.values():
                    p.closed = True
                self.cv.notify_all()
        if over:
            self.client.close()
            self.upstream.close()
            self.proxy._forget(self)

    def abort(self) -> None:
        """Reset both sides and end the pumps (what they held is gone with the link)."""
        with self.cv:
            self.closed = True
            for p in self.pumps.values():
                p.closed = True
            self.cv.notify_all()
        _abort(self.client)
        _abort(self.upstream)
        self.proxy._forget(self)


class _Flow:
    """One UDP client address: a socket connected to the target, a pump per direction."""

    def __init__(self, proxy: LinkProxy, client: Address, n: int):
        assert proxy._udp_sock is not None
        server = proxy._udp_sock
        self.cv = threading.Condition()
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.connect(proxy.target)
        self.sock.settimeout(POLL_S)
        self.up = _Pump(proxy, "up", n, self.cv, self.sock.send, lambda: None, True)
        self.down = _Pump(proxy, "down", n, self.cv, lambda d: server.sendto(d, client), lambda: None, True)
        self.proxy = proxy
        for pump in (self.up, self.down):
            proxy._spawn(pump.write_loop, f"udp{n}-{pump.name}-write")
        proxy._spawn(self._read_loop, f"udp{n}-down-read")

    def _read_loop(self) -> None:
        while not self.proxy._closed.is_set():
            try:
                self.down.put(self.sock.recv(CHUNK))
            except TimeoutError:
                continue
            except OSError:
                break
        with self.cv:
            self.up.closed = self.down.closed = True
            self.cv.notify_all()
        self.sock.close()


# -- the control socket
class LinkControl:
    """A client of a proxy program's control socket ``path``: the methods of
    :class:`LinkProxy` (``set``, ``stall``, ``reset``, ``counters``)."""

    def __init__(self, path: str | Path, timeout: float = 5.0):
        self.path, self.timeout = str(path), timeout

    def _ask(self, **request: Any) -> Any:
        with socket.socket(socket.AF_UNIX, socket.SOCK_STREAM) as s:
            s.settimeout(self.timeout)
            s.connect(self.path)
            s.sendall(json.dumps(request).encode() + b"\n")
            reply = s.makefile("r").readline()
        got = json.loads(reply)
        if "error" in got:
            raise ValueError(f"linkproxy {self.path}: {got['error']}")
        return got["ok"]

    def set(self, direction: str, fault: LinkFault) -> None:
        self._ask(op="set", direction=direction, fault=fault.to_dict())

    def stall(self, seconds: float, direction: str = "both") -> None:
        self._ask(op="stall", seconds=seconds, direction=direction)

    def reset(self) -> int:
        return int(self._ask(op="reset"))

    def counters(self) -> dict[str, Any]:
        return dict(self._ask(op="counters"))


def answer(proxy: LinkProxy, request: Any) -> dict[str, Any]:
    """The reply to one control request: ``{"ok": result}`` or ``{"error": why}``."""
    try:
        if not isinstance(request, dict):
            raise ValueError("expected a JSON map with op")
        op = request.get("op")
        if op == "counters":
            return {"ok": proxy.counters()}
        if op == "set":
            proxy.set(str(request.get("direction")), LinkFault.from_dict(request.get("fault")))
            return {"ok": None}
        if op == "stall":
            proxy.stall(request.get("seconds"), str(request.get("direction", "both")))  # type: ignore[arg-type]
            return {"ok": None}
        if op == "reset":
            return {"ok": proxy.reset()}
        raise ValueError(f"op: expected counters, set, stall or reset, got {op!r}")
    except (ValueError, TypeError) as e:
        return {"error": str(e)}


def serve_control(proxy: LinkProxy, path: Path, stop: threading.Event) -> threading.Thread:
    """Answer control requests (one JSON line in, one out) on the Unix socket ``path``
    until ``stop``."""
    if len(os.fsencode(path)) > 100:
        raise ValueError(f"--control {path}: longer than a Unix socket path may be (100 bytes)")
    path.unlink(missing_ok=True)
    server = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    server.bind(str(path))
    server.listen()
    server.settimeout(POLL_S)

    def loop() -> None:
        with server:
            while not stop.is_set():
                try:
                    conn, _ = server.accept()
                except TimeoutError:
                    continue
                with conn:
                    conn.settimeout(5.0)
                    try:
                        line = conn.makefile("r").readline()
                        reply = answer(proxy, json.loads(line)) if line else {"error": "empty request"}
                    except (OSError, ValueError) as e:
                        reply = {"error": str(e)}
                    try:
                        conn.sendall(json.dumps(reply).encode() + b"\n")
                    except OSError:
                        pass
        path.unlink(missing_ok=True)
    t = threading.Thread(target=loop, name="linkproxy-control", daemon=True)
    t.start()
    return t


def main(argv: list[str] | None = None) -> int:
    """``python -m sctd.deploy.linkproxy --listen H:P --target H:P [--up JSON] [--down
    JSON] [--udp] [--control PATH]``: prints ``{"ready": true, "listen": "H:P"}``, then
    runs until SIGTERM and prints its counters as JSON."""
    from sctd.timing import wait_until

    p = argparse.ArgumentParser(prog="python -m sctd.deploy.linkproxy", description=__doc__.split("\n")[0])
    p.add_argument("--listen", required=True, help="HOST:PORT (port 0: a free one)")
    p.add_argument("--target", required=True, help="HOST:PORT")
    p.add_argument("--up", default="{}", help="the LinkFault of listen -> target, as a JSON map")
    p.add_argument("--down", default="{}", help="the LinkFault of target -> listen, as a JSON map")
    p.add_argument("--udp", action="store_true", help="forward UDP on the same port too")
    p.add_argument("--control", type=Path, default=None, help="a Unix socket to control it through")
    args = p.parse_args(argv)
    try:
        listen, target = parse_address(args.listen), parse_address(args.target)
        up, down = (LinkFault.from_dict(json.loads(x)) for x in (args.up, args.down))
    except ValueError as e:
        print(f"python -m sctd.deploy.linkproxy: {e}", file=sys.stderr)
        return 2
    stop = threading.Event()
    with LinkProxy(listen, target, up, down, udp=args.udp) as proxy:
        control = None if args.control is None else serve_control(proxy, args.control, stop)
        print(json.dumps({"ready": True, "listen": f"{proxy.address[0]}:{proxy.address[1]}"}), flush=True)
        wait_until(stop)
        stop.set()
        if control is not None:
            control.join(5.0)
        counters = proxy.counters()
    print(json.dumps({"counters": counters}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
