"""Skill bundles validated in a separate process, the containment boundary for
hostile bundles.

Unpacking, YAML parsing and validation of a hot-swap bundle are pure-Python work that
holds the GIL for as long as they run (seconds for a large YAML), and a hostile bundle
can do worse: a nesting too deep for the parser, a model file that inflates to
gigabytes, a parser that crashes or hangs. They run in a process of their own
(``python -m sctd.runtime.worker``), started by the daemon's skill server
(:mod:`sctd.runtime.skillserver`): its address space is capped, and when it crashes or
takes too long it is replaced and the bundle refused. The caller receives the validated
:class:`~sctd.skill.Skill`, or the error that names what is wrong.

The validator is a plain subprocess (not :mod:`multiprocessing`, which would re-import
its parent's main module in it) receiving bundles and sending results on its end of a
socket pair, as :mod:`sctd.runtime.frames` messages (a skill's model arrays travel out
of band, not copied into a pickle); it exits when the other end closes, so it never
outlives its parent.
"""

from __future__ import annotations

import os
import pickle
import socket
import subprocess
import sys
import threading
from typing import Any

from ..skill import Skill, SkillError
from . import frames

WHERE = "<bundle>"


class BundleWorker:
    """A child process that turns packed skill bundles into validated skills.

    Parameters
    ----------
    timeout : float
        Seconds a bundle may take (to be taken, and to be answered); a slower one is
        refused and the child replaced.
    memory : int
        Bytes of address space the child may add to what it holds after start-up; a
        bundle needing more is refused.
    """

    def __init__(self, timeout: float = 30.0, memory: int = 2 << 30):
        self.timeout = timeout
        self.memory = memory
        self._lock = threading.Lock()  # one bundle at a time
        self._proc: subprocess.Popen | None = None
        self._sock: socket.socket | None = None
        self._closed = False
        self._spawn()

    def _spawn(self) -> None:
        ours, theirs = frames.pair()
        with theirs:
            self._proc = subprocess.Popen(
                [sys.executable, "-m", "sctd.runtime.worker", str(self.memory), str(theirs.fileno())],
                stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                pass_fds=[theirs.fileno()])
        ours.settimeout(self.timeout)
        self._sock = ours

    def _replace(self) -> None:
        self._kill()
        if not self._closed:
            self._spawn()

    def _kill(self) -> None:
        proc, sock = self._proc, self._sock
        if proc is not None:
            proc.kill()
            proc.wait()
        if sock is not None:
            sock.close()

    def skill(self, payload: bytes) -> Skill:
        """Validate a packed bundle (``Bundle.pack``) in the child. The skill's arrays
        are views of memory maps (:func:`sctd.runtime.frames.receive`).

        Raises
        ------
        SkillError
            Whatever is wrong with the bundle, including one that is too slow, too big
            or crashes the parser.
        """
        with self._lock:
            if self._proc is not None and self._proc.poll() is not None and not self._closed:
                self._replace()  # it died while idle: not this bundle's doing
            proc, sock = self._proc, self._sock
            if self._closed or proc is None or sock is None:
                raise SkillError(WHERE, "", "the validating process is stopped")
            try:
                frames.send(sock, pickle.PickleBuffer(payload))
                kind, value = frames.receive(sock)  # written by our own child
            except TimeoutError:
                self._replace()
                raise SkillError(WHERE, "", f"validation took longer than {self.timeout:g} s") from None
            except (EOFError, OSError, ValueError, pickle.UnpicklingError):
                try:  # its end closes as it exits: its exit code follows
                    code: int | None = proc.wait(1.0)
                except subprocess.TimeoutExpired:
                    code = None
                self._replace()
                if self._closed:
                    raise SkillError(WHERE, "", "the validating process was stopped") from None
                raise SkillError(WHERE, "", f"the validating process died (exit code {code})") from None
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
            self._proc = self._sock = None

    def __enter__(self) -> BundleWorker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


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
    """The child's loop: bundles in, ``compile_bundle`` results out, on the socket
    ``argv[1]``, until its other end closes."""
    _limit_memory(int(argv[0]))
    sock = frames.from_fd(int(argv[1]))
    while True:
        try:
            payload = frames.receive(sock)
        except (EOFError, OSError, ValueError):
            return 0
        frames.send(sock, compile_bundle(bytes(payload)))


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
