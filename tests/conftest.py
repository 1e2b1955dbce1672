"""Shared fixtures: free loopback ports, real subprocesses that are always reaped, and
Zenoh sessions on explicit loopback endpoints (multicast scouting off)."""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_live: list[subprocess.Popen] = []


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def port_is_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
            return True
        except OSError:
            return False


class Proc:
    """A child process (``python -m MODULE ARGS``) that is reaped on exit of the block."""

    def __init__(self, module: str, *args: str, log: Path):
        self.log_path = log
        self._log = open(log, "wb")
        self.p = subprocess.Popen([sys.executable, "-m", module, *args], stdout=self._log,
                                  stderr=subprocess.STDOUT, cwd=ROOT, start_new_session=True)
        _live.append(self.p)

    def __enter__(self) -> Proc:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def stop(self, timeout: float = 10.0) -> int:
        if self.p.poll() is None:
            self.p.send_signal(signal.SIGTERM)
            try:
                self.p.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.p.pid, signal.SIGKILL)
                self.p.wait()
        self._log.close()
        if self.p in _live:
            _live.remove(self.p)
        return self.p.returncode

    def output(self) -> str:
        self._log.flush()
        return self.log_path.read_text(errors="replace")


def sctd(*args: str, log: Path) -> Proc:
    return Proc("sctd.cli.main", *args, log=log)


@pytest.fixture(autouse=True)
def no_leaked_processes():
    yield
    leaked = [p for p in _live if p.poll() is None]
    for p in leaked:
        os.killpg(p.pid, signal.SIGKILL)
        p.wait()
    _live.clear()
    assert not leaked, f"test left {len(leaked)} process(es) running"


def wait_for(pred, timeout: float = 10.0, interval: float = 0.02):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(interval)
    return pred()
