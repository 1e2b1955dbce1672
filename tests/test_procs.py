"""Children of sctd's orchestrating commands (sctd.cli.procs.Child) do not outlive a
parent that was killed: the kernel sends them SIGTERM when it dies."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

SLEEPER = ("from sctd.cli.procs import Child; import time; "
           "c = Child('timeit', '-n', '1', '-r', '1', 'import time; time.sleep(120)'); "
           "print(c.p.pid, flush=True); time.sleep(120)")


def _alive(pid: int) -> bool:
    """Running (not gone, not a zombie nobody reaped)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (FileNotFoundError, ProcessLookupError, IndexError):
        return False
    return state != "Z"


@pytest.mark.slow
def test_a_child_gets_sigterm_when_its_parent_is_killed():
    parent = subprocess.Popen([sys.executable, "-c", SLEEPER], stdout=subprocess.PIPE, text=True)
    child = 0
    try:
        child = int(parent.stdout.readline())  # type: ignore[union-attr]
        assert _alive(child)
        parent.send_signal(signal.SIGKILL)  # no handler, no cleanup: only the kernel can tell the child
        parent.wait()
        for _ in range(200):  # a bound, not a measurement: SIGTERM ends python at once
            if not _alive(child):
                break
            time.sleep(0.05)
        assert not _alive(child), "the child outlived its killed parent"
    finally:
        parent.kill()
        parent.wait()
        if parent.stdout is not None:
            parent.stdout.close()
        if child:
            with contextlib.suppress(ProcessLookupError):
                os.kill(child, signal.SIGKILL)
