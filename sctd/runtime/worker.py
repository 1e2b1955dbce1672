"""Skill bundles validated in a separate process, so that no bundle stalls the tick.

Unpacking, YAML parsing and validation of a hot-swap bundle are pure-Python work that
holds the GIL for as long as they run (seconds for a large YAML): in the daemon's
process they would delay every SCHED_FIFO tick that falls in that time. They run in a
child process instead (``python -m sctd.runtime.worker``), which also contains what a
hostile bundle can do: a nesting too deep for the parser, a model file that inflates
to gigabytes (the child's address space is capped), a parser that crashes or hangs
(the child is replaced). The daemon receives the validated
:class:`~sctd.skill.Skill`, or the error that names what is wrong.

The child is a plain subprocess (not :mod:`multiprocessing`, which would re-import the
daemon's main module in it) reading length-prefixed bundles on stdin and writing
length-prefixed results on stdout; it exits when stdin closes, so it never outlives
the daemon.
"""

from __future__ import annotations

import os
import pickle
import select
import struct
import subprocess
import sys
import threading
from typing import IO, Any

from ..skill import Skill, SkillError

WHERE = "<bundle>"
_HEADER = struct.Struct("!Q")


class BundleWorker:
    """A child process that turns packed skill bundles into validated skills.

    Parameters
    ----------
    timeout : float
        Seconds a bundle may take; a slower one is refused and the child replaced.
    memory : int
        Bytes of address space the child may add to what it holds after start-up; a
        bundle needing more is refused.
    """

    def __init__(self, timeout: float = 30.0, memory: int = 2 << 30):
        self.timeout = timeout
        self.memory = memory
        self._lock = threading.Lock()  # one bundle at a time
        self._proc: subprocess.Popen | None = None
        self._closed = False
        self._spawn()

    def _spawn(self) -> None:
        self._proc = subprocess.Popen(
            [sys.executable, "-m", "sctd.runtime.worker", str(self.memory)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
            close_fds=True)

    def _replace(self) -> None:
        self._kill()
        if not self._closed:
            self._spawn()

    def _kill(self) -> None:
        proc = self._proc
        if proc is not None:
            proc.kill()
            proc.wait()
            for f in (proc.stdin, proc.stdout):
                if f is not None:
                    f.close()

    def skill(self, payload: bytes) -> Skill:
        """Validate a packed bundle (``Bundle.pack``) in the child.

        Raises
        ------
        SkillError
            Whatever is wrong with the bundle, including one that is too slow, too big
            or crashes the parser.
        """
        with self._lock:
            proc = self._proc
            if self._closed or proc is None:
                raise SkillError(WHERE, "", "the validating process is stopped")
            assert proc.stdin is not None and proc.stdout is not None
            try:
                proc.stdin.write(_HEADER.pack(len(payload)))
                proc.stdin.write(payload)
                proc.stdin.flush()
                data = _read_message(proc.stdout, self.timeout)
            except TimeoutError:
                self._replace()
                raise SkillError(WHERE, "", f"validation took longer than {self.timeout:g} s") from None
            except (EOFError, OSError, ValueError):
                code = proc.poll()
                self._replace()
                if self._closed:
                    raise SkillError(WHERE, "", "the validating process was stopped") from None
                raise SkillError(WHERE, "", f"the validating process died (exit code {code})") from None
            kind, value = pickle.loads(data)  # written by our own child
        if kind == "ok":
            return value
        error = SkillError(WHERE, "", value) if kind == "raw" else value
        try:
            raise error
        finally:  # no frame -> exception -> traceback -> frame cycle: the query it answers
            error = value = None  # must be freed (and so finished) as soon as it is replied to

    def close(self) -> None:
        """Stop the child. A bundle being validated meanwhile fails (its caller gets a
        SkillError), so closing never waits for one."""
        self._closed = True
        proc = self._proc
        if proc is not None:
            proc.kill()  # a pure validator: nothing to lose
        with self._lock:
            self._kill()
            self._proc = None

    def __enter__(self) -> BundleWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _read_message(f: IO[bytes], timeout: float) -> bytes:
    """One length-prefixed message from a pipe, waiting at most ``timeout`` s for it."""
    fd = f.fileno()
    ready, _, _ = select.select([fd], [], [], timeout)
    if not ready:
        raise TimeoutError
    header = _read_exactly(fd, _HEADER.size)
    return _read_exactly(fd, _HEADER.unpack(header)[0])


def _read_exactly(fd: int, n: int) -> bytes:
    parts = []
    while n > 0:
        chunk = os.read(fd, min(n, 1 << 20))
        if not chunk:
            raise EOFError
        parts.append(chunk)
        n -= len(chunk)
    return b"".join(parts)


def compile_bundle(payload: bytes) -> tuple[str, Any]:
    """``("ok", skill)`` for a valid packed bundle, else ``("error", SkillError)`` or
    ``("raw", message)`` for a failure that is not a SkillError (too deep, too big)."""
    from ..skill import Bundle, skill_from_bundle

    try:
        return "ok", skill_from_bundle(Bundle.unpack(payload))
    except SkillError as exc:
        return "error", exc
    except RecursionError:
        return "raw", "nested too deeply to parse"
    except MemoryError:
        return "raw", "needs more memory than a skill may take to validate"


def _limit_memory(extra: int) -> None:
    """Cap the address space at what the process holds now plus ``extra`` bytes."""
    import resource

    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[0])
        limit = pages * os.sysconf("SC_PAGE_SIZE") + extra
        resource.setrlimit(resource.RLIMIT_AS, (limit, resource.RLIM_INFINITY))
    except (OSError, ValueError):  # not Linux: no cap
        pass


def main(argv: list[str]) -> int:
    """The child's loop: bundles on stdin, ``compile_bundle`` results on stdout, until
    stdin closes."""
    _limit_memory(int(argv[0]) if argv else 2 << 30)
    fd_in, out = sys.stdin.buffer.fileno(), sys.stdout.buffer
    while True:
        try:
            header = _read_exactly(fd_in, _HEADER.size)
            payload = _read_exactly(fd_in, _HEADER.unpack(header)[0])
        except (EOFError, OSError):
            return 0
        result = pickle.dumps(compile_bundle(payload), protocol=pickle.HIGHEST_PROTOCOL)
        out.write(_HEADER.pack(len(result)))
        out.write(result)
        out.flush()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
