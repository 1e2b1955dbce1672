"""Training in a child process of the learner, with a memory cap, a time limit and a
lower CPU priority, so that nothing a request asks for can take the machine's memory or
CPU from the daemon beside it.

One warm worker (spawned once, ``sctd.learn`` imported once) runs one training at a
time: its address space is capped (``RLIMIT_AS``), it runs ``nice``-d below the learner,
and it dies with the learner (``PR_SET_PDEATHSIG``). A training that takes longer than
the time limit, or a learner stopped meanwhile, kills the worker (the next training
gets a new one); one that needs more memory than the cap fails in the worker with
``MemoryError`` and is reported as such. Each stage the training ends is passed back as
it ends (``on_stage``).
"""

from __future__ import annotations

import ctypes
import os
import queue
import resource
import signal
from collections.abc import Callable, Mapping
from concurrent.futures import ProcessPoolExecutor
from concurrent.futures import TimeoutError as FutureTimeout
from dataclasses import dataclass
from multiprocessing import get_context
from typing import Any

_stages: Any = None  # the worker's end of the stage queue


@dataclass(frozen=True)
class TrainingLimits:
    """What one training may take: ``memory`` bytes of address space, ``timeout``
    seconds, and ``nice`` steps below the learner's CPU priority."""

    memory: int = 4 * 1024**3
    timeout: float = 600.0
    nice: int = 5

    def __post_init__(self) -> None:
        if self.memory < 256 * 1024**2 or not self.timeout > 0 or not 0 <= self.nice <= 19:
            raise ValueError("--train-memory-mb must be >= 256, --train-timeout > 0, nice in [0, 19]")


class TrainingError(RuntimeError):
    """A training that did not finish: too slow, too big, or its worker died."""


def _worker_init(parent: int, memory: int, nice: int, stages: Any) -> None:
    """In the worker: the caps, death with the learner (also when it was killed before
    this ran: the orphan ends here), the stage queue, the imports."""
    global _stages
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:
        os._exit(0)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the learner decides what a Ctrl-C stops
    resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
    if nice:
        os.nice(nice)
    _stages = stages
    import sctd.learn  # noqa: F401  (once per worker, not per training)


def _train(demos: list, method: str, frames: Mapping[str, Any] | None, params: dict[str, Any]) -> Any:
    """In the worker: one training, each stage put on the queue as it ends. An error
    that cannot cross back to the learner whole comes back as a ValueError of its text."""
    import pickle

    from sctd.learn import learn

    try:
        return learn(demos, method, frames=frames, progress=_stages.put, **params)
    except Exception as e:
        try:
            pickle.loads(pickle.dumps(e))
        except Exception:
            raise ValueError(f"{type(e).__name__}: {e}") from None
        raise


class Trainer:
    """Trains in a warm child process (module doc). A context manager."""

    def __init__(self, limits: TrainingLimits | None = None):
        self.limits = limits or TrainingLimits()
        self._ctx = get_context("spawn")
        self._stages: Any = None
        self._pool: ProcessPoolExecutor | None = None

    def _start(self) -> ProcessPoolExecutor:
        if self._pool is None:
            self._stages = self._ctx.SimpleQueue()
            self._pool = ProcessPoolExecutor(1, mp_context=self._ctx, initializer=_worker_init,
                                             initargs=(os.getpid(), self.limits.memory, self.limits.nice,
                                                       self._stages))
        return self._pool

    def warm(self) -> None:
        """Start the worker and its imports now, not at the first training."""
        self._start().submit(os.getpid)

    def kill(self) -> None:
        """End the worker now (a training under way is lost); the next gets a new one."""
        pool, self._pool = self._pool, None
        if pool is None:
            return
        for p in list(getattr(pool, "_processes", {}).values()):
            p.kill()
        pool.shutdown(wait=True, cancel_futures=True)

    def close(self) -> None:
        self.kill()

    def __enter__(self) -> Trainer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def train(self, demos: list, method: str, frames: Mapping[str, Any] | None, params: dict[str, Any],
              on_stage: Callable[[str], None] = lambda stage: None) -> Any:
        """``sctd.learn.learn(demos, method, frames=frames, **params)`` in the worker.

        Raises
        ------
        TrainingError
            Longer than the time limit, more memory than the cap, or the worker died.
        Whatever ``learn`` raises on bad demonstrations or hyperparameters, as it raised it.
        """
        from concurrent.futures.process import BrokenProcessPool

        future = self._start().submit(_train, demos, method, dict(frames) if frames else None, params)
        waited = 0.0
        try:
            while True:
                try:
                    result = future.result(timeout=0.1)
                    break
                except FutureTimeout:
                    waited += 0.1
                    self._pass_stages(on_stage)
                    if waited >= self.limits.timeout:
                        self.kill()
                        raise TrainingError(f"training took longer than {self.limits.timeout:g} s "
                                            "(the learner's --train-timeout)") from None
        except MemoryError:
            raise TrainingError(f"training needed more than {self.limits.memory // 1024**2} MB "
                                "(the learner's --train-memory-mb)") from None
        except BrokenProcessPool:
            self.kill()
            raise TrainingError("the training process died") from None
        except BaseException:  # stopped (a signal) or a training error: no worker half-way
            if not future.done():
                self.kill()
            raise
        self._pass_stages(on_stage)
        return result

    def _pass_stages(self, on_stage: Callable[[str], None]) -> None:
        stages = self._stages
        while stages is not None and not stages.empty():
            try:
                on_stage(stages.get())
            except (queue.Empty, EOFError, OSError):
                return
