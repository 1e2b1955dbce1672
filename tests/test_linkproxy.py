"""The fault proxy (``sctd.deploy.linkproxy``) on 127.0.0.1: a proxied echo keeps every
byte in order under delay and jitter, a stall holds and then releases, a reset closes
both sides, UDP loses the datagrams the seed says, and the program answers its control
socket. Real sockets and real time (slow); the schedule itself is tested pure in
``tests/test_linkfault.py``."""

from __future__ import annotations

import json
import socket
import threading
import time

import pytest

from sctd.deploy.linkfault import Direction, LinkFault, Schedule
from sctd.deploy.linkproxy import LinkControl, LinkProxy
from sctd.deploy.netns import last_json
from tests.conftest import Proc, wait_for

pytestmark = pytest.mark.slow  # real sockets in real time, and a program


class Echo:
    """A TCP echo server on 127.0.0.1 in a thread; it stamps each chunk's arrival
    (monotonic) and says how its connection ended (``eof``, ``reset``)."""

    def __init__(self) -> None:
        self.server = socket.create_server(("127.0.0.1", 0))
        self.server.settimeout(10.0)
        self.arrivals: list[tuple[float, bytes]] = []
        self.ended: str | None = None
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    @property
    def address(self) -> tuple[str, int]:
        return self.server.getsockname()[:2]

    def _serve(self) -> None:
        try:
            conn, _ = self.server.accept()
        except OSError:
            return
        with conn:
            try:
                while data := conn.recv(65536):
                    self.arrivals.append((time.monotonic(), data))
                    conn.sendall(data)
                self.ended = "eof"
            except ConnectionResetError:
                self.ended = "reset"

    def close(self) -> None:
        self.server.close()
        self.thread.join(10.0)


@pytest.fixture
def echo():
    e = Echo()
    yield e
    e.close()


def _recv_all(sock: socket.socket, n: int) -> bytes:
    got = b""
    sock.settimeout(20.0)
    while len(got) < n:
        chunk = sock.recv(65536)
        if not chunk:
            break
        got += chunk
    return got


def test_echo_through_delay_and_jitter_keeps_every_byte_in_order(echo):
    data = bytes(i % 251 for i in range(140_000))  # a period that no chunk size lines up with
    fault = LinkFault(delay_ms=5, jitter=1.0, seed=1)
    with LinkProxy(("127.0.0.1", 0), echo.address, up=fault, down=fault) as proxy, \
            socket.create_connection(proxy.address) as c:
        c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        reader = threading.Thread(target=lambda: got.append(_recv_all(c, len(data))))
        got: list[bytes] = []
        reader.start()
        for i in range(0, len(data), 700):  # many small writes 2 ms apart (within the
            c.sendall(data[i:i + 700])       # jitter of +-5 ms): many chunks, each jittered
            time.sleep(0.002)
        reader.join(30.0)
        counters = proxy.counters()
    assert got and got[0] == data
    up, down = counters["up"], counters["down"]
    assert up["bytes"] == down["bytes"] == len(data)
    assert up["chunks"] > 10 and up["delayed"] > 0.9 * up["chunks"], counters
    assert counters["connections"] == 1 and counters["resets"] == 0


def test_a_stall_holds_the_bytes_and_releases_them_in_order_when_it_ends(echo):
    stall_s = 1.0
    with LinkProxy(("127.0.0.1", 0), echo.address) as proxy, \
            socket.create_connection(proxy.address) as c:
        c.sendall(b"before|")
        assert _recv_all(c, 7) == b"before|"
        proxy.stall(stall_s, "up")
        began = time.monotonic()
        parts = [f"held-{k}|".encode() for k in range(20)]
        for p in parts:
            c.sendall(p)
        assert _recv_all(c, sum(map(len, parts))) == b"".join(parts)
        counters = proxy.counters()
    # what the echo server got during the stall: nothing; the held bytes arrived after
    # the stall's end (a lower bound: a loaded machine makes them later, never earlier)
    held = [t for t, d in echo.arrivals if d != b"before|"]
    assert held and min(held) - began >= stall_s - 0.02, (min(held) - began)
    assert b"".join(d for _, d in echo.arrivals) == b"before|" + b"".join(parts)
    assert counters["up"]["held"] >= 1 and counters["stalls"] == 1, counters


def test_a_stall_in_the_spec_holds_from_its_time(echo):
    fault = LinkFault(stalls=((0.0, 0.8),))
    with LinkProxy(("127.0.0.1", 0), echo.address, down=fault) as proxy, \
            socket.create_connection(proxy.address) as c:
        c.sendall(b"ping")
        assert _recv_all(c, 4) == b"ping"  # held on the way back, then released
        assert echo.arrivals and echo.arrivals[0][0] - proxy.t0 < 0.7  # went up at once
        counters = proxy.counters()
    assert counters["down"]["held"] == 1 and counters["up"]["held"] == 0, counters


@pytest.mark.parametrize("how", ["now", "scheduled"])
def test_a_reset_closes_both_sides(echo, how):
    fault = LinkFault(resets=(0.5,)) if how == "scheduled" else LinkFault()
    with LinkProxy(("127.0.0.1", 0), echo.address, up=fault) as proxy, \
            socket.create_connection(proxy.address) as c:
        c.sendall(b"x")
        assert _recv_all(c, 1) == b"x"
        if how == "now":
            assert proxy.reset() == 1
        c.settimeout(10.0)
        with pytest.raises(ConnectionResetError):
            while c.recv(10):
                pass
        assert wait_for(lambda: echo.ended is not None, 10)
        counters = proxy.counters()
    assert echo.ended == "reset"  # the target's side got an RST too, not an orderly end
    assert counters["resets"] == 1 and counters["open"] == 0, counters


def test_the_end_of_a_stream_follows_its_last_bytes(echo):
    with LinkProxy(("127.0.0.1", 0), echo.address, up=LinkFault(delay_ms=50)) as proxy, \
            socket.create_connection(proxy.address) as c:
        c.sendall(b"last words")
        c.shutdown(socket.SHUT_WR)
        assert _recv_all(c, 100) == b"last words"  # then EOF: the echo ended in order
        assert wait_for(lambda: proxy.counters()["open"] == 0, 10)
    assert echo.ended == "eof"


def test_udp_loses_the_datagrams_the_seed_says():
    fault = LinkFault(loss=0.3, seed=11)
    n = 200
    s = Schedule(Direction(fault), "up", 0)
    expected = [k for k in range(n) if s.drops()]
    target = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    target.bind(("127.0.0.1", 0))
    target.settimeout(1.0)
    got: list[int] = []
    with target, LinkProxy(("127.0.0.1", 0), target.getsockname()[:2], up=fault, udp=True) as proxy, \
            socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as c:
        for k in range(n):
            c.sendto(str(k).encode(), proxy.address)
            time.sleep(0.001)  # loopback drops nothing at this pace
        try:
            while len(got) < n - len(expected):
                got.append(int(target.recv(100)))
        except TimeoutError:
            pass
        counters = proxy.counters()
    assert got == [k for k in range(n) if k not in expected]
    assert counters["up"]["datagrams"] == n and counters["up"]["dropped"] == len(expected), counters


def test_the_program_answers_its_control_socket_and_reports_its_counters(echo, tmp_path):
    control = tmp_path / "c.sock"
    p = Proc("sctd.deploy.linkproxy", "--listen", "127.0.0.1:0", "--target", "{}:{}".format(*echo.address),
             "--up", json.dumps({"delay_ms": 10, "seed": 3}), "--control", str(control),
             log=tmp_path / "proxy.log")
    try:
        assert wait_for(lambda: '"ready"' in p.output(), 30), p.output()
        host, port = json.loads(p.output().splitlines()[0])["listen"].rsplit(":", 1)
        link = LinkControl(control)
        with socket.create_connection((host, int(port))) as c:
            c.sendall(b"one")
            assert _recv_all(c, 3) == b"one"
            link.set("down", LinkFault(delay_ms=30))
            link.stall(0.3, "up")
            c.sendall(b"two")
            assert _recv_all(c, 3) == b"two"
            counters = link.counters()
            assert counters["up"]["held"] == 1 and counters["down"]["delayed"] == 1, counters
            with pytest.raises(ValueError, match=r"LinkFault\.delay: unknown field"):
                link._ask(op="set", direction="up", fault={"delay": 5})
            with pytest.raises(ValueError, match="direction: expected up, down or both"):
                link.stall(1.0, "sideways")
            assert link.reset() == 1
    finally:
        rc = p.stop()
    assert rc == 0, p.output()
    final = last_json(p.output())
    assert final is not None and final["counters"]["resets"] == 1, p.output()
    assert not control.exists()


def test_the_program_refuses_a_bad_fault_naming_the_field(tmp_path):
    p = Proc("sctd.deploy.linkproxy", "--listen", "127.0.0.1:0", "--target", "127.0.0.1:9",
             "--down", '{"jitter": 3}', log=tmp_path / "proxy.log")
    assert p.p.wait(30) == 2
    p.stop()
    assert "LinkFault.jitter: expected a number in [0, 1]" in p.output()
