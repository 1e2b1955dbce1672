"""The learner's check before a swap: lockstep trials of the new skill, against a floor
and against the active skill's own stored evaluation (pure decisions, plus the trials
themselves through :mod:`sctd_services.eval`)."""

from __future__ import annotations

import ctypes
import math
import os
import random
import signal
import time
from collections.abc import Callable
from concurrent.futures import Executor, ProcessPoolExecutor
from dataclasses import dataclass, replace
from multiprocessing import get_context
from typing import Any

from sctd.skill.catalog import StoredSkill
from sctd.task import Task, TaskError, find_task
from sctd_services.eval.evaluate import entries, evaluate, table
from sctd_services.eval.numerics import describe, numerics
from sctd_services.eval.trial import TaskSpec


def evaluable(task: str) -> Task | None:
    """The task a lockstep evaluation runs for a request naming ``task``, or None when
    sctd finds no such task or its file does not validate (the file gives the simulated
    scene and the user's intent). A learner request names its task over the wire
    (``sctd/<robot>/learner``): the name is resolved here, once, on arrival."""
    try:
        return find_task(task)
    except TaskError:
        return None


ALPHA = 0.38
"""The sequential test's bound on accepting a skill at its lower rate (a fixed rule of
at most one failure in ten trials accepts one of 80 % with probability 0.376)."""
BETA = 0.09
"""Its bound on rejecting a skill at its upper rate (that fixed rule rejects one of 95 %
with probability 0.086)."""


CHECK_SEED = 1000
"""The check's first trial seed by default: far from the seeds 0-19 that ``sctd eval``
and ``sctd suite`` measure skills on, so that a skill the gate passed is measured there
on trials it was not checked on (held out)."""


@dataclass(frozen=True)
class CheckSettings:
    """How a new skill is checked: lockstep trials from ``seed``, one after another, until
    a sequential test (:class:`SequentialRule`) decides whether its success rate is at
    least ``floor`` (and, when the active skill has a stored evaluation on the task, at
    least that rate minus ``tolerance``), at most ``trials`` of them. Only with
    ``allow_unchecked`` (set by whoever starts the learner) may a request skip it."""

    trials: int = 20
    floor: float = 0.9
    tolerance: float = 0.1
    seed: int = CHECK_SEED
    jobs: int = 2
    allow_unchecked: bool = False  # requests may skip the check (gate: false): the operator's call

    def __post_init__(self) -> None:
        if self.trials < 1 or self.jobs < 1 or self.seed < 0:
            raise ValueError("--trials and --jobs must be >= 1, --seed >= 0")
        if not 0.0 < self.floor < 1.0 or not 0.0 <= self.tolerance <= 1.0:
            raise ValueError("--floor must be within (0, 1), --tolerance within [0, 1]")


@dataclass(frozen=True)
class SequentialRule:
    """Wald's sequential probability ratio test of a skill's success rate: ``low`` (a skill
    that should be refused) against ``high`` (one that should pass), truncated at
    ``max_trials``.

    After ``s`` successes and ``f`` failures the evidence is the log-likelihood ratio
    ``s ln(high/low) + f ln((1-high)/(1-low))``; it accepts once that reaches
    ``ln((1-beta)/alpha)``, rejects once it falls to ``ln(beta/(1-alpha))``, and after
    ``max_trials`` trials decides by its sign. Wald's bounds make the chance of accepting a
    skill at ``low`` about ``alpha`` and of rejecting one at ``high`` about ``beta``;
    :meth:`operating_point` gives the exact figures of the truncated test. A skill that
    succeeds every time is accepted after the fewest trials whose evidence reaches the
    bound (6 for the defaults)."""

    low: float
    high: float
    max_trials: int
    alpha: float = ALPHA
    beta: float = BETA

    @classmethod
    def around(cls, floor: float, max_trials: int) -> SequentialRule:
        """The test for a floor of ``floor``: ``high`` half-way from it to 1, ``low`` as
        far below it as 1 is above (at least half the floor): 0.8 and 0.95 for 0.9."""
        return cls(max(2.0 * floor - 1.0, 0.5 * floor), 0.5 * (1.0 + floor), max_trials)

    def evidence(self, successes: int, failures: int) -> float:
        return (successes * math.log(self.high / self.low)
                + failures * math.log((1.0 - self.high) / (1.0 - self.low)))

    def decide(self, successes: int, failures: int) -> bool | None:
        """True: accept; False: reject; None: run another trial."""
        e = self.evidence(successes, failures)
        if e >= math.log((1.0 - self.beta) / self.alpha) - 1e-12:
            return True
        if e <= math.log(self.beta / (1.0 - self.alpha)) + 1e-12:
            return False
        if successes + failures >= self.max_trials:
            return e > 0.0
        return None

    def operating_point(self, p: float) -> tuple[float, float]:
        """For a skill whose trials succeed with probability ``p``, exactly: the chance the
        test accepts it, and the expected number of trials it runs."""
        alive = {0: 1.0}  # successes so far -> probability of still running, after n trials
        accept = trials = 0.0
        for n in range(1, self.max_trials + 1):
            nxt: dict[int, float] = {}
            for s, w in alive.items():
                for s2, q in ((s + 1, w * p), (s, w * (1.0 - p))):
                    d = self.decide(s2, n - s2)
                    if d is None:
                        nxt[s2] = nxt.get(s2, 0.0) + q
                    else:
                        accept += q if d else 0.0
                        trials += q * n
            alive = nxt
        return accept, trials

    def describe(self) -> str:
        return (f"success rate >= {self.high:.2f} against <= {self.low:.2f}, at most {self.max_trials} "
                f"trials")


def simulate(rule: SequentialRule, p: float, sequences: int, rng: random.Random) -> tuple[float, float]:
    """``rule`` run on ``sequences`` random sequences of trials that succeed with
    probability ``p``: the share accepted and the mean number of trials run."""
    accepted = trials = 0
    for _ in range(sequences):
        s = f = 0
        while (d := rule.decide(s, f)) is None:
            if rng.random() < p:
                s += 1
            else:
                f += 1
        accepted += d
        trials += s + f
    return accepted / sequences, trials / sequences


def rule_for(settings: CheckSettings, active: dict[str, Any] | None) -> SequentialRule:
    """The test a new skill must pass: around the floor, raised to the active skill's
    stored success rate minus the tolerance when that is higher (and below 1)."""
    floor = settings.floor
    if active is not None:
        floor = min(max(floor, active["success_rate"] - settings.tolerance), 0.99)
    return SequentialRule.around(floor, settings.trials)


def decided(per_trial: list[dict[str, Any]], settings: CheckSettings,
            active: dict[str, Any] | None) -> bool | None:
    """The sequential test's decision on the trials so far (in seed order): True, False,
    or None while it needs more."""
    ok = sum(1 for t in per_trial if t["outcome"] == "success")
    return rule_for(settings, active).decide(ok, len(per_trial) - ok)


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
    """The learner's pool of trial processes, started at once and kept warm: its ``jobs``
    processes start and import what a trial needs now, not when the first check's trials
    arrive (a second or two of CPU each, which a request would otherwise wait for)."""
    pool = ProcessPoolExecutor(jobs, mp_context=get_context("spawn"), initializer=_die_with_parent,
                               initargs=(os.getpid(),))
    for _ in range(jobs):  # (a pool starts a process per task given while none is idle)
        pool.submit(os.getpid)
    return pool


def evaluation(stored: StoredSkill, task: Task, settings: CheckSettings, seed: int,
               pool: Executor | None,
               progress: Callable[[int, int, str], None] | None = None,
               active: dict[str, Any] | None = None, stop_early: bool = True) -> dict[str, Any]:
    """``sctd eval --lockstep`` of a stored skill on ``task``: the figures of
    :func:`sctd_services.eval.evaluate.summarise` without the per-trial series, and the
    table's rows. With ``stop_early``, the trials end as soon as the sequential test
    decides (:func:`decided`; ``active``: the active skill's evaluation the test is raised
    to); without, all ``settings.trials`` run."""
    t0 = time.monotonic()
    until = (lambda per_trial: decided(per_trial, settings, active) is not None) if stop_early else None
    # one skill and no baseline: entries() writes no copy into the work folder
    ents = [replace(e, label=stored.ref)
            for e in entries([str(stored.path)], baseline=False, workdir=stored.path.parent)]
    [res] = evaluate(ents, TaskSpec.of(task), settings.trials, seed, jobs=settings.jobs,
                     progress=progress, pool=pool, until=until)
    res["per_trial"] = [{k: t[k] for k in ("seed", "outcome", "reason", "time_s", "readings")}
                        for t in res["per_trial"]]
    res.update(task=task.name, seed=seed, lockstep=True, wall_s=round(time.monotonic() - t0, 2),
               table=table([res]), numerics=numerics())
    return res


def verdict(ev: dict[str, Any] | None, task: str, settings: CheckSettings,
            active: dict[str, Any] | None) -> tuple[bool, str]:
    """Whether a skill with evaluation ``ev`` on ``task`` may replace the active one, and
    why: the sequential test's decision on its trials (:func:`rule_for`). ``active``: the
    active skill's stored evaluation on the task (None when it did not come from the
    store or was never evaluated on it)."""
    if ev is None:
        return False, (f"no lockstep evaluation for task {task!r} (no such task, or its file does not "
                       "validate: sctd tasks says which); send gate: false to swap it unchecked")
    rule = rule_for(settings, active)
    ok, n = ev["successes"], ev["trials"]
    d = rule.decide(ok, n - ok)
    got = f"{ok}/{n} trials succeeded"
    floor = f"the floor {settings.floor:.2f}"
    if active is not None and rule.high > SequentialRule.around(settings.floor, 1).high:
        floor = (f"the active skill's {active['success_rate']:.2f} minus the tolerance "
                 f"{settings.tolerance:.2f}")
    test = f"the sequential test ({rule.describe()}; {floor})"
    # the BLAS kernels the trials ran on, so that a verdict read on another machine says
    # where it came from (sctd bench kernels compares outcomes across kernels)
    on = f"; {describe(ev['numerics'])}" if ev.get("numerics") else ""
    if d is None:
        return False, f"{got}: too few for {test} to decide{on}"
    if not d:
        return False, f"{got}: rejected by {test}{on}"
    return True, f"{got}: accepted by {test}{on}"
