"""``sctd router`` ends by itself after SIGINT/SIGTERM, and its exit code says how: 0
when Zenoh closed the session within ``CLOSE_WAIT`` (2 s), 3 (``EXIT_FORCED``) when it
did not and the process exited without it. A router that had to be killed would exit
-9: every test here would fail on that, not on a clock.

Loopback only: the routers listen on free 127.0.0.1 ports, never on 7447.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import signal
import socket
import subprocess
from pathlib import Path

import pytest
import zenoh

from sctd.app.errors import EXIT_FORCED, EXIT_OK
from sctd.cli.router import CLOSE_WAIT
from sctd.wire.session import close_session
from tests.conftest import free_port, run_sctd, sctd, wait_for

pytestmark = pytest.mark.slow  # sctd router as a process

# listening again and again (a port another socket holds): how the loopback defaults do it
RETRY = {"period_init_ms": 250, "period_max_ms": 1000, "period_increase_factor": 2}


def router_file(path: Path, port: int, **listen: object) -> Path:
    """A plain TCP router config on ``tcp/127.0.0.1:<port>`` (``listen``: more of its
    ``listen`` section)."""
    conf = {"listen": {"endpoints": [f"tcp/127.0.0.1:{port}"], **listen},
            "scouting": {"multicast": {"enabled": False}},
            "transport": {"shared_memory": {"enabled": False}}}
    path.write_text(json.dumps(conf))
    return path


def client(port: int, clients: contextlib.ExitStack) -> zenoh.Session:
    """A client session of the router on ``port``, closed (bounded) when ``clients``
    exits."""
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    s = zenoh.open(conf)
    clients.callback(close_session, s)
    return s


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_router_stopped_by_a_signal_closes_its_session_and_exits_0(tmp_path, sig):
    """A router that routed one client's put to another, the clients gone: its session
    closes well within the bound (milliseconds here) and the exit code is 0, with
    nothing said on stderr."""
    port = free_port()
    log = tmp_path / "router.log"
    router = sctd("router", "--config", str(router_file(tmp_path / "router.json5", port)), log=log)
    try:
        assert wait_for(lambda: "listening on" in log.read_text(), 30), log.read_text()
        with contextlib.ExitStack() as clients:
            a, b = client(port, clients), client(port, clients)
            got: list[zenoh.Sample] = []
            a.declare_subscriber("sctd/test/ping", got.append)
            # (put until one arrives: the subscription takes a moment to reach b)
            assert wait_for(lambda: (b.put("sctd/test/ping", b"1"), got)[1], 10), \
                "the router does not route"
    finally:
        rc = router.stop(sig=sig)
    assert rc == EXIT_OK, (rc, log.read_text())
    assert "did not close" not in log.read_text()


def _tgkill(pid: int, tid: int, sig: int) -> None:
    """Send ``sig`` to the thread ``tid`` of process ``pid`` (Linux ``tgkill``): the
    kernel hands a signal sent to a process to any of its threads that does not block
    it, often one of Zenoh's."""
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.syscall(234, pid, tid, sig) != 0:  # SYS_tgkill on x86-64
        raise OSError(ctypes.get_errno(), "tgkill")


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_taken_by_one_of_zenohs_threads_still_stops_the_router(tmp_path, sig):
    """A stop signal that the kernel gives to one of Zenoh's threads, not to Python's main
    thread, stops the router as one the main thread took does (a router that waited on
    an event without a timeout never saw it and was killed after the 10 s grace)."""
    port = free_port()
    log = tmp_path / "router.log"
    router = sctd("router", "--config", str(router_file(tmp_path / "router.json5", port)), log=log)
    try:
        assert wait_for(lambda: "listening on" in log.read_text(), 30), log.read_text()
        pid = router.p.pid
        others = sorted(int(t) for t in os.listdir(f"/proc/{pid}/task") if int(t) != pid)
        assert others, "the router runs Zenoh's threads"
        _tgkill(pid, others[-1], sig)
        with contextlib.suppress(subprocess.TimeoutExpired):
            router.p.wait(3 * CLOSE_WAIT + 10)  # the router's own bound, with room
        ended = router.p.returncode  # None: it did not end by itself
    finally:
        router.stop()
    assert ended == EXIT_OK, (ended, log.read_text())


def test_router_whose_session_does_not_close_exits_3_after_the_bound(tmp_path):
    """Another socket holds the router's port and the router retries to listen on it:
    Zenoh cannot cancel that retry and ``Session.close`` blocks for about 10 s. The
    router gives it ``CLOSE_WAIT`` s, says so on stderr and exits 3 by itself (a router
    that waited for Zenoh, or for the interpreter's shutdown, would be killed by
    ``stop`` after its 10 s grace and exit -9)."""
    log = tmp_path / "router.log"
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        port = held.getsockname()[1]
        conf = router_file(tmp_path / "router.json5", port, timeout_ms=-1, exit_on_failure=False,
                           retry=RETRY)
        router = sctd("router", "--config", str(conf), log=log)
        try:
            assert wait_for(lambda: "listening on" in log.read_text(), 30), log.read_text()
        finally:
            rc = router.stop()
    assert rc == EXIT_FORCED, (rc, log.read_text())
    assert (f"sctd router: the Zenoh session did not close within {CLOSE_WAIT:g} s; exiting without "
            f"it (exit {EXIT_FORCED})") in log.read_text()


def test_router_help_names_its_exit_codes():
    r = run_sctd("router", "--help")
    assert r.returncode == 0, r.stderr
    text = " ".join(r.stdout.split())
    assert "exit codes: 0 done; 1 the job ran and did not succeed; 2 bad arguments" in text
    assert (f"{EXIT_FORCED} stopped by SIGINT/SIGTERM, but Zenoh did not close the session within "
            f"{CLOSE_WAIT:g} s") in text
