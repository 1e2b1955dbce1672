"""Child processes and loopback ports for the commands that orchestrate several sctd
programs (``sctd demo``, ``sctd bench``) and for the tests.

Every child runs in its own session and is stopped with SIGTERM (then SIGKILL after a
grace period) when its context exits, so nothing is left running. A child also gets
SIGTERM from the kernel when its parent dies, however it dies (Linux's parent-death
signal): a ``sctd try`` or study runner killed with SIGKILL leaves no simulator, daemon
or logger running behind it. The kernel sends it when the *thread* that started the
child ends: a child must not outlive the thread that started it (``sctd try`` starts a
trial's programs in the trial's thread and stops them before it ends).
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import random
import signal
import socket
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import IO

_EPHEMERAL = Path("/proc/sys/net/ipv4/ip_local_port_range")
_handed_out: set[int] = set()
_random = random.SystemRandom()  # not the seeded global generator: processes must differ
PR_SET_PDEATHSIG = 1  # linux/prctl.h


def _libc_prctl() -> Callable[..., int] | None:
    """libc's ``prctl``, looked up here, before any fork (a child between fork and exec
    should not load libraries), or None where there is none."""
    try:
        return ctypes.CDLL(None).prctl
    except (OSError, AttributeError):
        return None


_prctl = _libc_prctl()


def _ephemeral_range() -> tuple[int, int]:
    try:
        low, high = (int(x) for x in _EPHEMERAL.read_text().split())
        return low, high
    except (OSError, ValueError):
        return 32768, 60999  # Linux's default


def _port_range() -> tuple[int, int]:
    given = os.environ.get("SCTD_PORT_RANGE", "")
    if given:
        try:
            low, high = (int(x) for x in given.split("-"))
        except ValueError:
            raise ValueError(f"SCTD_PORT_RANGE: {given!r} is not LOW-HIGH") from None
        if not 1024 <= low < high <= 65535:
            raise ValueError(f"SCTD_PORT_RANGE: {given!r} is not within 1024-65535")
        return low, high
    low, _high = _ephemeral_range()
    top = min(low, 65536) - 1
    return max(10000, top - 15000), top


def free_port() -> int:
    """A TCP port on 127.0.0.1 that was free a moment ago, and that nothing else will
    be given in the meantime.

    It is drawn at random from below the kernel's ephemeral range, never from it: a
    port from ``bind(("127.0.0.1", 0))`` is free again once that socket closes, and
    until the child that is to listen on it has started (a second or more for Python),
    any ephemeral allocation can take it, e.g. a test's own session listening on
    ``tcp/127.0.0.1:0``, which then connects to itself while the child retries its
    listen forever. A port is not handed out twice by one process.

    ``SCTD_PORT_RANGE=LOW-HIGH`` narrows the draw, so that processes running side by
    side (the test suite's parallel workers, and the programs they start) can never be
    handed the same port.
    """
    bottom, top = _port_range()
    if top - bottom < 1000 and not os.environ.get("SCTD_PORT_RANGE"):
        # an unusual ephemeral range: fall back to the kernel's choice
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.bind(("127.0.0.1", 0))
            return s.getsockname()[1]
    for _ in range(1000):
        port = _random.randint(bottom, top)
        if port in _handed_out or port == 7447:
            continue
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
        _handed_out.add(port)
        return port
    raise RuntimeError(f"no free TCP port on 127.0.0.1 in {bottom}-{top}")


def port_is_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
            return True
        except OSError:
            return False


def _default_signals() -> None:
    """In the child before exec: default SIGINT. A parent started as a background job
    inherits SIGINT ignored, and Python would then never raise KeyboardInterrupt, so
    tools that stop on Ctrl-C (python -m can.logger) would not stop on SIGINT."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _default_signals_and_parent_death(parent: int) -> Callable[[], None]:
    """:func:`_default_signals`, and SIGTERM when the parent ``parent`` dies (where the
    platform has ``prctl``); a parent already gone by then gets the child its SIGTERM at
    once."""
    def before_exec() -> None:
        _default_signals()
        if _prctl is not None and _prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0) == 0 \
                and os.getppid() != parent:
            os.kill(os.getpid(), signal.SIGTERM)
    return before_exec


_live: set[Child] = set()  # the children started and not yet stopped


def kill_children() -> int:
    """SIGKILL the process group of every child not yet stopped (a process that must
    exit now and cannot unwind: its children are in sessions of their own and would
    outlive it); how many there were."""
    n = 0
    for c in list(_live):
        if c.p.poll() is None:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(c.p.pid, signal.SIGKILL)
            n += 1
        _live.discard(c)
    return n


class Child:
    """``python -m MODULE ARGS`` as a child process; a context manager that reaps it.

    Parameters
    ----------
    module : str
        Module to run with ``python -m``.
    args : str
        Its arguments.
    log : Path, optional
        File receiving stdout and stderr; default: stderr passes through and stdout
        is captured (read it with :meth:`communicate`).
    env : dict, optional
        Its environment (default: this process's).
    """

    def __init__(self, module: str, *args: str, log: Path | None = None, cwd: Path | None = None,
                 env: dict[str, str] | None = None):
        self.log_path = log
        self._log: IO[bytes] | None = open(log, "wb") if log is not None else None
        self.p = subprocess.Popen(
            [sys.executable, "-m", module, *args],
            stdout=self._log if self._log is not None else subprocess.PIPE,
            stderr=subprocess.STDOUT if self._log is not None else None,
            cwd=cwd, env=env, start_new_session=True,
            preexec_fn=_default_signals_and_parent_death(os.getpid()),
        )
        _live.add(self)

    def __enter__(self) -> Child:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def running(self) -> bool:
        return self.p.poll() is None

    def communicate(self, timeout: float) -> str:
        """Wait for exit and return captured stdout (kills the child after timeout)."""
        try:
            out, _ = self.p.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.stop()
            out = b""
        return (out or b"").decode(errors="replace")

    def stop(self, timeout: float = 10.0, sig: int = signal.SIGTERM) -> int:
        """``sig`` (SIGTERM), wait up to ``timeout`` s, then SIGKILL the child's process
        group; the exit code (``-9`` when it had to be killed)."""
        if self.p.poll() is None:
            self.p.send_signal(sig)
            try:
                self.p.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(self.p.pid, signal.SIGKILL)
                self.p.wait()
        _live.discard(self)
        if self.p.stdout is not None:
            self.p.stdout.close()
        if self._log is not None:
            self._log.close()
        return self.p.returncode

    def output(self) -> str:
        if self._log is not None and not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace") if self.log_path else ""
