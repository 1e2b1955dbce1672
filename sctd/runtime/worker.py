"""Skill bundles validated in a separate process, so that no bundle stalls the tick.

Unpacking, YAML parsing and validation of a hot-swap bundle are pure-Python work that
holds the GIL for as long as they run (seconds for a 10 MB YAML): in the daemon's
process they would delay every SCHED_FIFO tick that falls in that time. They run in a
child process instead, which also contains what a hostile bundle can do: a nesting too
deep for the parser, a model file that inflates to gigabytes (the child's address space
is limited), or a crash of the parser (the child is replaced). The daemon receives the
validated :class:`~sctd.skill.Skill`, or the error that names what is wrong.

The child is started with ``spawn`` (a fresh interpreter: forking a process that runs
Zenoh's threads is not safe) when the worker is created, and it exits when its pipe
closes, so it never outlives the daemon.
"""

from __future__ import annotations

import logging
import multiprocessing
import threading
from multiprocessing.connection import Connection
from typing import Any

from ..skill import Skill, SkillError

log = logging.getLogger("sctd.run")
WHERE = "<bundle>"


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
        self._ctx = multiprocessing.get_context("spawn")
        self._lock = threading.Lock()  # one bundle at a time
        self._proc: Any = None
        self._conn: Connection | None = None
        self._closed = False
        self._spawn()

    def _spawn(self) -> None:
        parent, child = self._ctx.Pipe()
        proc = self._ctx.Process(target=_serve, args=(child, self.memory), daemon=True,
                                 name="sctd-skill-worker")
        proc.start()
        child.close()
        self._proc, self._conn = proc, parent

    def _replace(self) -> None:
        if self._conn is not None:
            self._conn.close()
        if self._proc is not None:
            self._proc.kill()
            self._proc.join(timeout=5.0)
        self._spawn()

    def skill(self, payload: bytes) -> Skill:
        """Validate a packed bundle (``Bundle.pack``) in the child.

        Raises
        ------
        SkillError
            Whatever is wrong with the bundle, including one that is too slow, too big
            or crashes the parser.
        """
        with self._lock:
            conn = self._conn
            if conn is None:
                raise SkillError(WHERE, "", "the validating process is closed")
            try:
                conn.send_bytes(payload)
                if not conn.poll(self.timeout):
                    self._replace()
                    raise SkillError(WHERE, "", f"validation took longer than {self.timeout:g} s")
                kind, value = conn.recv()  # a Skill pickled by our own child
            except (EOFError, OSError) as exc:
                if self._closed:
                    raise SkillError(WHERE, "", "the validating process was stopped") from None
                code = self._proc.exitcode if self._proc is not None else None
                self._replace()
                raise SkillError(WHERE, "", f"the validating process died (exit code {code}): "
                                 f"{type(exc).__name__}") from None
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
            proc.join(timeout=5.0)
        with self._lock:
            if self._conn is not None:
                self._conn.close()
                self._conn = None
            self._proc = None

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


def _serve(conn: Connection, memory: int) -> None:
    """The child's loop: bundle bytes in, ``compile_bundle`` out, until the pipe closes."""
    _limit_memory(memory)
    while True:
        try:
            payload = conn.recv_bytes()
        except (EOFError, OSError):
            return
        conn.send(compile_bundle(payload))


def _limit_memory(extra: int) -> None:
    """Cap the address space at what the process holds now plus ``extra`` bytes."""
    import resource

    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[0])
        import os

        limit = pages * os.sysconf("SC_PAGE_SIZE") + extra
        resource.setrlimit(resource.RLIMIT_AS, (limit, resource.RLIM_INFINITY))
    except (OSError, ValueError):  # not Linux: no cap
        pass
