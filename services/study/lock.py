"""One live runner per study folder: ``DIR/runner.lock`` (``docs/study.md``, "The lock").

The lock is an advisory ``flock`` on the file, which the kernel releases when the
process that holds it ends however it ends (a kill, a crash, a power cut): a lock can
never be left behind by a dead runner, and pid reuse cannot fool it. The file also holds
the holder's pid, so that a second runner can say whose lock it met, and so that a
runner taking over after a killed one can say whose it took over. A clean exit empties
the file; a killed runner's pid stays in it until the next runner takes over.
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path

from .errors import StudyError

LOCK_FILE = "runner.lock"


class RunnerLock:
    """The lock of study folder ``directory`` (a context manager; :meth:`acquire` on
    enter). ``stale`` is the pid a killed runner left in the file, None when there was
    none; a :class:`StudyError` names the live holder when another runner holds it."""

    def __init__(self, directory: str | Path):
        self.path = Path(directory) / LOCK_FILE
        self.stale: int | None = None
        self._fd: int | None = None

    def __enter__(self) -> RunnerLock:
        self.acquire()
        return self

    def __exit__(self, *exc: object) -> None:
        self.release()

    def acquire(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _pid_in(fd)
            os.close(fd)
            who = f"pid {holder}" if holder is not None else "another process"
            raise StudyError(f"{self.path}: another sctd study run ({who}) is running on this folder; "
                             "stop it first (one runner per study folder)") from None
        self.stale = _pid_in(fd)
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        os.fsync(fd)
        self._fd = fd

    def release(self) -> None:
        """Empty the file (a clean exit leaves no pid behind) and unlock."""
        if self._fd is None:
            return
        os.ftruncate(self._fd, 0)
        os.close(self._fd)  # (closing the last descriptor releases the flock)
        self._fd = None


def _pid_in(fd: int) -> int | None:
    text = os.pread(fd, 64, 0).decode(errors="replace").strip()
    return int(text) if text.isdigit() else None
