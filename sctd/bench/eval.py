"""Lockstep evaluation speed: ``sctd bench eval``.

Runs ``--trials`` lockstep trials (:func:`sctd_services.eval.lockstep.run_trial`, what
``sctd eval --lockstep`` runs in each job) one after the other in this process and prints
the simulated time, the wall time, their ratio (the real-time factor) and the wall time
per 1 kHz step. The trials' outcomes do not depend on the host; the times do (a busy
machine slows them by tens of percent), so compare figures taken side by side.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import Counter
from typing import Any

from sctd.app.defaults import defaults
from sctd.app.errors import fail
from sctd.app.options import SKILL_HELP, TASK_HELP
from sctd.skill import load_skill
from sctd.skill.catalog import find_skill
from sctd.task import Task, find_task
from sctd_services.eval.evaluate import task_of
from sctd_services.eval.lockstep import run_trial
from sctd_services.eval.trial import TaskSpec

RATE = 1000.0  # Hz: the lockstep simulation's cycle (Simulation's default)


def measure(skill: str, task: Task | None = None, trials: int = 3, seed: int = 0,
            time_limit: float | None = None) -> dict[str, Any]:
    """Time ``trials`` lockstep trials of ``skill`` (seeds ``seed ..``) on ``task`` (default:
    the task of the skill's object), each ending at ``time_limit`` s at the latest.

    Returns
    -------
    dict
        ``skill``, ``task``, ``trials``, ``seed``, ``sim_s`` (simulated seconds, summed),
        ``wall_s`` and ``cpu_s`` (this process's CPU time) of the trials, ``rtf``
        (``sim_s / wall_s``), ``steps``, ``ms_per_step`` (wall), ``outcomes`` (counts).
    """
    path = find_skill(skill)
    loaded = load_skill(path)
    found = task_of([loaded], task)
    spec = TaskSpec.of(found, time_limit=time_limit)
    sim_s, outcomes = 0.0, Counter[str]()
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for k in range(trials):
        r = run_trial(loaded, spec, seed + k, task=found)
        sim_s += r.duration_s
        outcomes[r.outcome] += 1
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    steps = round(sim_s * RATE)  # a trial ends on a step: duration_s is steps / rate
    return {"skill": str(path), "task": spec.task, "trials": trials, "seed": seed,
            "sim_s": round(sim_s, 3), "wall_s": round(wall, 3), "cpu_s": round(cpu, 3),
            "rtf": round(sim_s / wall, 3), "steps": steps,
            "ms_per_step": round(1e3 * wall / max(1, steps), 4), "outcomes": dict(outcomes)}


def format_report(r: dict[str, Any]) -> str:
    """Human-readable report of :func:`measure`'s result."""
    last = r["seed"] + r["trials"] - 1
    outcomes = ", ".join(f"{n} {k}" for k, n in sorted(r["outcomes"].items()))
    n = r["trials"]
    return (f"{r['skill']} on {r['task']}: {n} lockstep trial{'s' if n != 1 else ''} (seeds "
            f"{r['seed']}-{last}) in this process\n"
            f"simulated {r['sim_s']:.1f} s in {r['wall_s']:.1f} s wall (cpu {r['cpu_s']:.1f} s): "
            f"real-time factor {r['rtf']:.2f}, {r['ms_per_step']:.3f} ms per step "
            f"({r['steps']} steps)\noutcomes: {outcomes}")


def add_bench_eval_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``sctd bench eval``."""
    p.add_argument("--skill", default=defaults().learned_skill,
                   help=SKILL_HELP + " (default %(default)s)")
    p.add_argument("--task", metavar="NAME|FILE",
                   help=TASK_HELP + " (default: the task whose object is the skill's)")
    p.add_argument("--trials", type=int, default=3, help="trials, run one after the other "
                                                         "(default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="first trial seed (default %(default)s)")
    p.add_argument("--time-limit", type=float, default=None,
                   help="s per trial (default: the task file's time_limit)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def main_bench_eval(args: argparse.Namespace) -> int:
    if args.trials < 1:
        return fail("bench eval", "--trials: must be >= 1")
    if args.time_limit is not None and not args.time_limit > 0:
        return fail("bench eval", "--time-limit: must be > 0")
    try:
        task = find_task(args.task) if args.task is not None else None
        r = measure(args.skill, task, args.trials, args.seed, args.time_limit)
    except ValueError as e:  # a skill that does not load (SkillError), a task that does not (TaskError)
        return fail("bench eval", str(e))
    print(json.dumps(r) if args.json else format_report(r))
    return 0
