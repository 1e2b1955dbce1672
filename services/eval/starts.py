"""Where a trial's hand starts (:mod:`sctd.task.starts`), with the other tasks the
shipped and added task folders hold, as far as the arm reaches their starts."""

from __future__ import annotations

import functools

from sctd.task import Task, known_tasks, load_task
from sctd.task.starts import STARTS, trial_start
from sctd_sim.simulation import load_arm_model, start_posture

__all__ = ["STARTS", "reachable_others", "starts_task"]


@functools.lru_cache(maxsize=1)
def reachable_others() -> tuple[Task, ...]:
    """Every known task whose hand start (as its file puts it) the shipped arm reaches
    (once per process)."""
    arm = load_arm_model()
    out = []
    for known in known_tasks():
        task = load_task(known.path)
        try:
            start_posture(arm, task.scene.start.T_world)
        except RuntimeError:
            continue
        out.append(task)
    return tuple(out)


def starts_task(task: Task, starts: str, seed: int) -> tuple[Task, str]:
    """The task trial ``seed`` runs in with ``starts`` (:data:`STARTS`), and whose start
    it is."""
    return trial_start(task, starts, seed, reachable_others() if starts == "foreign" else ())
