"""Simulated participants: a study folder filled by the simulated user in lockstep, to
try the analysis before people take part (``sctd study run --simulated N``).

Each simulated participant runs its schedule through the same writer API a real
runner calls (:class:`~.store.StudyStore`: :meth:`~.store.StudyStore.progress` says what
is next, so a killed run resumes where it stopped), and each trial is ``sctd eval
--lockstep``'s: the simulator, the runtime's tick and the simulated user in one process
in simulated time (:func:`~sctd_services.eval.lockstep.practise`). Within a block the
user keeps what it learned of the device from one trial to the next, practice trials
included, as a person practising does (a resumed run starts that learning afresh).
A skill-set block runs in the set's room (:func:`~sctd_services.eval.lockstep.run_set_trial`).

**The questionnaire answers are synthetic.** No simulated user has a workload or an
opinion; :func:`simulated_answers` derives them from the block's measured trials so
that the report has numbers in the right ranges that move with the trials: a load
index ``L = 0.15 + 0.35 (1 - success rate) + 0.3 min(1, duration / time limit) + 0.1
min(1, switches / 10) + 0.1 min(1, effort / time limit)``, clipped to [0, 1]; each TLX
subscale ``100 L`` (performance: ``100 (0.8 (1 - success rate) + 0.2 L)``) plus normal
noise (sd 8), on the 5-point grid; each SUS item from the usability ``1 - L`` (agreement
``1 + 4 (1 - L)`` for the positive items, reversed for the negative ones) plus normal
noise (sd 0.6), rounded to 1..5. The noise is seeded by the plan's seed, the participant
and the block. None of it measures a person.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from sctd.runtime.sets import goal_set
from sctd.task import Task
from sctd_services.eval.lockstep import practise, run_set_trial
from sctd_services.eval.trial import TaskSpec
from sctd_services.user.agent import Device

from .conditions import Block, block_of
from .questionnaires import SUS, SUS_ITEMS, TLX, TLX_STEP, TLX_SUBSCALES
from .store import StudyStore, TrialRow

Progress = Callable[[str, int, int], None]


def simulated_answers(rows: Sequence[TrialRow], time_limit: float,
                      rng: np.random.Generator) -> dict[str, Any]:
    """Synthetic TLX and SUS answers for a block from its measured ``rows`` (module doc)."""
    measured = [r for r in rows if not r.practice and not r.aborted]

    def mean(xs: list[float]) -> float:
        return float(np.mean(xs)) if xs else 0.0

    s = mean([1.0 if r.success else 0.0 for r in measured])
    dur = mean([r.duration_s or time_limit for r in measured]) / time_limit
    switches = mean([float(r.mode_switches or 0) for r in measured])
    effort = mean([r.effort or 0.0 for r in measured]) / time_limit
    load = float(np.clip(0.15 + 0.35 * (1 - s) + 0.3 * min(1.0, dur) + 0.1 * min(1.0, switches / 10)
                         + 0.1 * min(1.0, effort), 0.0, 1.0))

    def grid(x: float) -> int:
        return int(np.clip(TLX_STEP * round(x / TLX_STEP), 0, 100))

    tlx = {sc.key: grid(100 * (0.8 * (1 - s) + 0.2 * load if sc.key == "performance" else load)
                        + rng.normal(0, 8)) for sc in TLX_SUBSCALES}
    agree = 1 + 4 * (1 - load)
    sus = [int(np.clip(round((agree if i % 2 == 0 else 6 - agree) + rng.normal(0, 0.6)), 1, 5))
           for i in range(len(SUS_ITEMS))]
    return {TLX: tlx, SUS: sus}


def _trial(block: Block, seed: int, known: dict[str, Device]) -> tuple[dict[str, Any], dict[str, Device]]:
    """One lockstep trial of ``block`` from ``seed``: its result (with the trajectory) and
    what the user knows of the device after it."""
    task = block.task
    spec = TaskSpec.of(task, task.name)
    if block.skill_set is not None:
        res, _ = run_set_trial(goal_set(block.skill_set), task, spec, seed)
        return res.as_dict(with_trajectory=True), known
    assert block.skill is not None
    res, learned = practise(block.skill, spec, seed, task=task, known=known)
    return res.as_dict(with_trajectory=True), learned


def simulate_participant(store: StudyStore, participant: str, tasks: Mapping[str, Task],
                         progress: Progress | None = None) -> None:
    """Run ``participant``'s schedule from where its folder stands until it is done;
    ``tasks``: the plan's tasks by the names it gives them."""
    plan = store.plan
    blocks: dict[tuple[str, str], Block] = {}
    known: dict[tuple[str, str], dict[str, Device]] = {}
    index = [s.participant for s in plan.participants].index(participant)
    order = [(b.condition, b.task) for b in plan.schedule(participant).blocks]
    while True:
        p = store.progress(participant)
        if p.answers_due is not None:
            cond, task = p.answers_due
            block = blocks.get(p.answers_due) or block_of(plan, cond, tasks[task])
            rows = [r for r in store.trials(participant).rows if (r.condition, r.task) == p.answers_due]
            rng = np.random.default_rng([plan.seed, index, order.index(p.answers_due)])
            limit = block.task.outcome.time_limit
            store.record_answers(participant, cond, task, simulated_answers(rows, limit, rng))
            continue
        step = p.next_step
        if step is None:
            return
        key = (step.condition, step.task)
        if key not in blocks:
            blocks[key] = block_of(plan, step.condition, tasks[step.task])
        result, known[key] = _trial(blocks[key], step.seed, known.get(key, {}))
        log = {"simulated": True, "participant": participant, "step": step.index, "condition": step.condition,
               "task": step.task, "runs": blocks[key].label, "seed": step.seed, "practice": step.practice,
               "result": result}
        store.record_trial(participant, step.index, result, log)
        if progress is not None:
            progress(participant, p.done + 1, p.total)


def simulate_study(store: StudyStore, participants: int, tasks: Mapping[str, Task],
                   progress: Progress | None = None) -> list[str]:
    """Fill ``store`` with its plan's first ``participants`` participants, simulated
    (module doc; ``tasks`` as :func:`simulate_participant` takes them); returns their ids."""
    ids = [s.participant for s in store.plan.participants[:participants]]
    for pid in ids:
        simulate_participant(store, pid, tasks, progress)
    return ids
