"""The learner's check before a swap: lockstep trials of the new skill, against a floor
and against the active skill's own stored evaluation (pure decisions, plus the trials
themselves through :mod:`sctd_services.eval`)."""

from __future__ import annotations

import ctypes
import os
import signal
import time
from collections.abc import Callable
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, replace
from multiprocessing import get_context
from typing import Any

from sctd.skill.catalog import StoredSkill
from sctd.task import TaskError, find_task
from sctd_services.eval.evaluate import entries, evaluate, table
from sctd_services.eval.trial import TaskSpec


def can_evaluate(task: str) -> bool:
    """Whether a lockstep evaluation can run ``task``: whether it is a task sctd finds
    whose file validates (its file gives the simulated scene and the user's intent)."""
    try:
        find_task(task)
    except TaskError:
        return False
    return True


@dataclass(frozen=True)
class CheckSettings:
    """How a new skill is checked: ``trials`` lockstep trials from ``seed``; it passes
    with a success rate of at least ``floor`` and, when the active skill has a stored
    evaluation on the task, no lower than that minus ``tolerance``. Only with
    ``allow_unchecked`` (set by whoever starts the learner) may a request skip it."""

    trials: int = 10
    floor: float = 0.9
    tolerance: float = 0.1
    seed: int = 0
    jobs: int = 2
    allow_unchecked: bool = False  # requests may skip the check (gate: false): the operator's call

    def __post_init__(self) -> None:
        if self.trials < 1 or self.jobs < 1 or self.seed < 0:
            raise ValueError("--trials and --jobs must be >= 1, --seed >= 0")
        if not 0.0 <= self.floor <= 1.0 or not 0.0 <= self.tolerance <= 1.0:
            raise ValueError("--floor and --tolerance must be within [0, 1]")


def _die_with_parent(parent: int) -> None:
    """A pool worker: killed when the learner dies (kill -9 included), and warm. A
    learner killed before this ran (while the pool was starting) sent no signal: the
    worker, already an orphan, ends here."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:
        os._exit(0)
    import sctd_services.eval.lockstep  # noqa: F401  (the imports a trial needs, done once)


def trial_pool(jobs: int) -> Executor:
    """The learner's pool of trial processes, started once and kept warm."""
    return ProcessPoolExecutor(jobs, mp_context=get_context("spawn"), initializer=_die_with_parent,
                               initargs=(os.getpid(),))


def failed_already(per_trial: list[dict[str, Any]], settings: CheckSettings,
                   active: dict[str, Any] | None) -> bool:
    """Whether the check's verdict is a fail whatever the trials not yet run give: even
    if all of them succeeded, the success rate over ``settings.trials`` would be below
    the floor (or below the active skill's rate minus the tolerance)."""
    ok = sum(1 for t in per_trial if t["outcome"] == "success")
    best = (ok + settings.trials - len(per_trial)) / settings.trials
    need = settings.floor
    if active is not None:
        need = max(need, active["success_rate"] - settings.tolerance)
    return best < need - 1e-9


def evaluation(stored: StoredSkill, task: str, settings: CheckSettings, seed: int,
               pool: Executor | None,
               progress: Callable[[int, int, str], None] | None = None,
               active: dict[str, Any] | None = None, stop_early: bool = True) -> dict[str, Any]:
    """``sctd eval --lockstep`` of a stored skill on ``task``: the figures of
    :func:`sctd_services.eval.evaluate.summarise` without the per-trial series, and the
    table's rows. With ``stop_early``, the trials end as soon as the verdict is a fail
    whatever the rest would give (:func:`failed_already`; ``active``: the active skill's
    evaluation the verdict compares with): a skill that passes always runs them all, so
    its stored evaluation, a later check's baseline, is over every trial."""
    t0 = time.monotonic()
    until = (lambda per_trial: failed_already(per_trial, settings, active)) if stop_early else None
    # one skill and no baseline: entries() writes no copy into the work folder
    ents = [replace(e, label=stored.ref)
            for e in entries([str(stored.path)], baseline=False, workdir=stored.path.parent)]
    [res] = evaluate(ents, TaskSpec(task), settings.trials, seed, jobs=settings.jobs,
                     progress=progress, pool=pool, until=until)
    res["per_trial"] = [{k: t[k] for k in ("seed", "outcome", "reason", "time_s", "spill")}
                        for t in res["per_trial"]]
    res.update(task=task, seed=seed, lockstep=True, wall_s=round(time.monotonic() - t0, 2),
               table=table([res]))
    return res


def verdict(ev: dict[str, Any] | None, task: str, settings: CheckSettings,
            active: dict[str, Any] | None) -> tuple[bool, str]:
    """Whether a skill with evaluation ``ev`` on ``task`` may replace the active one, and
    why. ``active``: the active skill's stored evaluation on the task (None when it did
    not come from the store or was never evaluated on it)."""
    if ev is None:
        return False, (f"no lockstep evaluation for task {task!r} (no such task, or its file does not "
                       "validate: sctd tasks says which); send gate: false to swap it unchecked")
    rate = ev["success_rate"]
    got = f"{ev['successes']}/{ev['trials']} trials succeeded"
    if ev.get("stopped_early"):
        got += f" (stopped after {ev['trials']} of {ev['planned']}: the rest could not pass it)"
    if rate < settings.floor:
        return False, f"{got} ({rate:.2f} < the floor {settings.floor:.2f})"
    if active is not None and rate < active["success_rate"] - settings.tolerance - 1e-9:
        return False, (f"{got} ({rate:.2f}), worse than the active skill's {active['success_rate']:.2f} "
                       f"minus the tolerance {settings.tolerance:.2f}")
    than = "" if active is None else f", the active skill had {active['success_rate']:.2f}"
    return True, f"{got} ({rate:.2f} >= the floor {settings.floor:.2f}{than})"
