"""The evaluation suite: every task x its skills x the competent baseline, in lockstep.

For each task (:func:`sctd.task.known_tasks`, or those asked for) the skills are the
shipped ones whose object is the task's object (a hand-written reference and the
learned ones), and the unassisted baseline runs once per set of their speed limits
with the task's control frame (:func:`~.evaluate.entries`). Every skill of a task runs
the same seeded trials. :func:`run_suite` returns one row per task and skill with the
figures a reader compares (success, time distribution, mode switches, effort, the time
against the baseline's); :func:`floor` is the time the task cannot be done under at the
skill's speed limits, whatever the assistance.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sctd.skill import WORLD_OBJECT, Limits, load_skill
from sctd.skill.catalog import shipped_skills
from sctd.skill.constraints import SpeedNear
from sctd.task import Task
from sctd.task.kinds import Floor
from sctd.task.model import Near
from sctd_services.user import DEFAULT_MODEL

from .evaluate import (
    TELEOP,
    Entry,
    baseline_for,
    entries,
    evaluate,
    lockstep_job,
    result_cap,
    strip_trajectories,
)
from .trial import TaskSpec

if TYPE_CHECKING:  # matplotlib is imported when the figure is drawn, not with sctd suite
    from matplotlib.figure import Figure


@dataclass
class TaskRun:
    """One task of the suite: its skills' results (the baseline's among them)."""

    task: Task
    skills: list[str]
    results: list[dict[str, Any]] = field(default_factory=list)
    user_model: str = DEFAULT_MODEL  # how the simulated user learned the device

    @property
    def baseline(self) -> dict[str, Any] | None:
        return next((r for r in self.results if r.get("baseline_of")), None)


def skills_for(task: Task, shipped: list[Path] | None = None) -> list[str]:
    """The shipped skills whose object is ``task``'s object, by file name."""
    out = []
    for p in sorted(shipped if shipped is not None else shipped_skills()):
        s = load_skill(p)
        if s.object != WORLD_OBJECT and s.object == task.object:
            out.append(str(p))
    return out


def floor(task: Task, limits: Limits, cap: SpeedNear | None = None) -> float:
    """A lower bound of the completion time at ``limits``: the way through the points
    each step's hand must pass (its kind's :meth:`~sctd.task.kinds.StepKind.floor_path`:
    the first reach's or press's frame to its goal, a button's face; a grasp's grip and
    lift, ...) from where the first of them starts, straight from one to the next, and
    every path a step adds besides (a joint's handle along its path to its threshold, a
    revolute joint's angle times its lever), at full linear speed; every turn (a tilt's)
    at full angular speed. The way to the first point starts where a ``near`` completion
    clock starts when that is nearer, as that step's part says (:class:`~sctd.task.kinds.Floor`).
    With ``cap`` (a skill's ``speed_near``, :func:`cap_of`) the part of the way to the
    first point within the cap's distance of the task object, and the turns when that
    point is there, go at the cap's speeds (the first step's frame taken for the cap's
    point: a cup's rim)."""
    sc = task.scene
    parts: list[Floor] = []
    for s in task.intent:
        parts.append(s.action.floor_path(task, tuple(parts)))
    lead = next(p for p in parts if p.points)
    held = sc.held.frames if sc.held is not None else {}
    start = (sc.start.T_world @ held.get(lead.frame, np.eye(4)))[:3, 3]
    points = [start, *(q for p in parts for q in p.points)]
    legs = [float(np.linalg.norm(b - a)) for a, b in itertools.pairwise(points)]
    goal, obj = points[1], sc.bodies[task.object].T_world
    clock = task.outcome.clock
    if isinstance(clock, Near) and lead.clock == "goal":  # within ``within`` of the goal
        if clock.to == task.object and clock.within < legs[0]:
            start = goal + (start - goal) * (clock.within / legs[0])
            legs[0] = clock.within
    elif isinstance(clock, Near) and clock.to in sc.bodies:  # on the sphere about its body
        origin = sc.bodies[clock.to].T_world[:3, 3]
        legs[0] = min(legs[0], max(0.0, clock.within - float(np.linalg.norm(goal - origin))))
    travel, spin = sum(legs), 0.0
    for p in parts:
        travel += p.along
        spin += p.radians
    slow = 0.0 if cap is None else _inside(start, goal, obj[:3, 3], cap.within)
    v_slow = limits.max_linear_speed if cap is None else min(limits.max_linear_speed, cap.max_linear_speed)
    near = cap is not None and float(np.linalg.norm(goal - obj[:3, 3])) < cap.within
    w = min(limits.max_angular_speed, cap.max_angular_speed) if near and cap is not None \
        else limits.max_angular_speed
    return (travel - slow) / limits.max_linear_speed + slow / v_slow + spin / w


def _inside(a: np.ndarray, b: np.ndarray, centre: np.ndarray, radius: float) -> float:
    """The length of the segment from a to b inside the ball about ``centre``."""
    d = b - a
    L = float(np.linalg.norm(d))
    if L <= 0.0:
        return 0.0
    u = d / L
    t = float((centre - a) @ u)  # the segment's point nearest the centre, along it
    h2 = radius * radius - float(np.linalg.norm(a + t * u - centre)) ** 2
    if h2 <= 0.0:
        return 0.0
    h = math.sqrt(h2)
    return max(0.0, min(L, t + h) - max(0.0, t - h))


def run_suite(tasks: list[tuple[str, Task]], trials: int, seed: int, jobs: int, workdir: Path,
              progress: Callable[[int, int, str], None] | None = None,
              user_models: Sequence[str] = (DEFAULT_MODEL,), starts: str = "own") -> list[TaskRun]:
    """Every task's skills and its competent baseline, ``trials`` lockstep trials each
    from seed ``seed``, once per user model (:data:`~sctd_services.user.USER_MODELS`:
    the same trials with a person who learns the device another way); a task with no
    shipped skill runs the baseline alone. ``tasks``: (how the task was named: a name or
    a file, the task); ``starts``: where the hands start (:data:`~sctd.task.starts.STARTS`)."""
    runs = []
    for (ref, task), model in itertools.product(tasks, user_models):
        skills = skills_for(task)
        paths = skills or [str(TELEOP)]
        ents = entries(paths, baseline=bool(skills), workdir=workdir / task.name, task=task)
        if not skills:  # the baseline alone (with the task's control frame: entries)
            ents = [Entry("teleop", e.path, e.skill, "-") for e in ents]
        spec = TaskSpec.of(task, ref, user_model=model, starts=starts)
        results = evaluate(ents, spec, trials, seed, lockstep_job, jobs, progress=progress)
        runs.append(TaskRun(task, skills, strip_trajectories(results), model))
    return runs


def rows(runs: list[TaskRun]) -> list[dict[str, Any]]:
    """One row per task and skill: what the table and the figures show. A baseline's
    row is named after the skill whose speed limits it ran with; a skill's time is
    compared with the baseline's of the same limits."""
    out = []
    for run in runs:
        names = {r["skill"]: r["name"] for r in run.results}
        for r in run.results:
            lim = Limits(**r["limits"])
            median = r["time_s"]["median"]
            base = baseline_for(r, run.results)
            b = base["time_s"]["median"] if base is not None and base is not r else None
            of = r.get("baseline_of")
            skill = r["name"] if not of else "baseline" if of not in names else f"baseline ({names[of]})"
            out.append({
                "task": run.task.name, "skill": skill, "user_model": run.user_model, "label": r["skill"],
                "trials": r["trials"],
                "successes": r["successes"], "success_rate": r["success_rate"], "median_s": median,
                "times_s": [t["time_s"] for t in r["per_trial"] if t["outcome"] == "success"],
                "vs_baseline": round(median / b, 3) if median is not None and b else None,
                "floor_s": round(floor(run.task, lim, result_cap(r)), 2),
                "mode_switches": r["mode_switches_mean"], "effort": r["effort_mean"],
                "stuck": r["stuck"], "limited_median_s": r["time_s_limited_median"],
                "failures": _failures(r["per_trial"], run.task.name),
                "started_outside_region": sum(1 for t in r["per_trial"] if t.get("outside_region")),
                "failed_at_joint_limit": sum(1 for t in r["per_trial"]
                                             if t["outcome"] != "success" and t.get("joint_limits")),
                "where_baseline_finished": None if base is None or base is r else _paired(r, base),
            })
    return out


def _paired(r: dict[str, Any], base: dict[str, Any]) -> list[int]:
    """[successes, trials] of ``r`` over the seeds from which its baseline finished the
    task: the starts from which the same person reached the goal unassisted."""
    finished = {t["seed"] for t in base["per_trial"] if t["outcome"] == "success"}
    mine = [t for t in r["per_trial"] if t["seed"] in finished]
    return [sum(t["outcome"] == "success" for t in mine), len(mine)]


def _failures(per_trial: list[dict[str, Any]], task: str) -> dict[str, int]:
    out: dict[str, int] = {}
    for t in per_trial:
        if t["outcome"] != "success":
            why = str(t.get("reason") or t["outcome"])
            if t.get("start_of") and t["start_of"] != task:
                why += f" (from {t['start_of']}'s start)"
            if t.get("outside_region"):
                why += " [out of region]"
            if t.get("joint_limits"):
                why += f" [joint {', '.join(map(str, t['joint_limits']))} at its limit]"
            out[why] = out.get(why, 0) + 1
    return out


def table(rows_: list[dict[str, Any]], paired: bool = False) -> list[str]:
    """The suite's table, one line per task and skill (the columns as wide as the longest
    task and skill names); ``paired``: with each skill's success over the starts its
    baseline finished from (:func:`_paired`)."""
    tw = max([14, *(len(r["task"]) for r in rows_)])
    sw = max([24, *(len(r["skill"]) for r in rows_)])
    users = _several_users(rows_)
    user = f"{'user':<9}" if users else ""
    pair = f" {'base done':>9}" if paired else ""
    head = (f"{'task':<{tw}} {user}{'skill':<{sw}} {'success':>9}{pair} {'median [s]':>10} {'vs base':>8} "
            f"{'floor [s]':>9} {'switches':>8} {'effort':>7}  failures")
    lines = [head, "-" * len(head)]
    for r in rows_:
        med = "-" if r["median_s"] is None else f"{r['median_s']:.2f}"
        vs = "-" if r["vs_baseline"] is None else f"{r['vs_baseline']:.2f}"
        why = ", ".join(f"{k} x{v}" for k, v in r["failures"].items())
        user = f"{r['user_model']:<9}" if users else ""
        pair = f" {_pair_text(r):>9}" if paired else ""
        lines.append(f"{r['task']:<{tw}} {user}{r['skill']:<{sw}} {r['successes']:>4}/{r['trials']:<4}{pair} "
                     f"{med:>10} {vs:>8} {r['floor_s']:>9.2f} {r['mode_switches']:>8.1f} "
                     f"{r['effort']:>7.2f}  {why}")
    return lines


def _several_users(rows_: list[dict[str, Any]]) -> bool:
    """Whether the rows are of more than one user model (a column says which)."""
    return len({r.get("user_model", DEFAULT_MODEL) for r in rows_}) > 1


def _pair_text(r: dict[str, Any]) -> str:
    p = r.get("where_baseline_finished")
    return "-" if p is None else f"{p[0]}/{p[1]}"


def markdown(rows_: list[dict[str, Any]], paired: bool = False) -> str:
    """The table as Markdown, for the docs (``paired``: as :func:`table`'s)."""
    users = _several_users(rows_)
    user = " user |" if users else ""
    pair = " where the baseline finished |" if paired else ""
    out = [f"| task |{user} skill | success |{pair} median time [s] | vs baseline | floor [s] | "
           "mode switches | effort |",
           "|---|" + ("---|" if users else "") + ("---|" if paired else "") + "---|---|---|---|---|---|---|"]
    for r in rows_:
        med = "-" if r["median_s"] is None else f"{r['median_s']:.2f}"
        vs = "-" if r["vs_baseline"] is None else f"{r['vs_baseline']:.2f}"
        user = f" {r['user_model']} |" if users else ""
        pair = f" {_pair_text(r)} |" if paired else ""
        out.append(f"| {r['task']} |{user} {r['skill']} | {r['successes']}/{r['trials']} |{pair} {med} | "
                   f"{vs} | {r['floor_s']:.2f} | {r['mode_switches']:.1f} | {r['effort']:.2f} |")
    return "\n".join(out) + "\n"


def figure(rows_: list[dict[str, Any]]) -> Figure:
    """Success, completion times (each task's floor marked) and mode switches and effort
    per task and skill, one above the other on the same rows: the suite at a glance."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(max(8.0, 0.42 * len(rows_) + 2.0), 11))  # (wider with more rows)
    ax_s, ax_t, ax_e = fig.subplots(3, 1, sharex=True)
    users = _several_users(rows_)
    labels = [f"{r['task']}: {r['skill']}" + (f" [{r['user_model']}]" if users else "") for r in rows_]
    x = np.arange(len(rows_))
    colours = [_COLOURS[sorted({r['task'] for r in rows_}).index(r["task"]) % len(_COLOURS)] for r in rows_]
    ax_s.bar(x, [100 * r["success_rate"] for r in rows_], color=colours)
    ax_s.axhline(90, color="k", lw=0.8, ls="--")
    ax_s.set(title="success [%] (dashed: 90 %)", ylim=(0, 105))
    data = [r["times_s"] or [math.nan] for r in rows_]
    ax_t.boxplot(data, positions=x, widths=0.6)
    ax_t.scatter(x, [r["floor_s"] for r in rows_], marker="_", s=300, color="r", label="floor")
    ax_t.set(title="completion time of successful trials [s]")
    ax_t.legend(loc="upper left")
    ax_e.bar(x - 0.2, [r["mode_switches"] for r in rows_], width=0.4, color=colours, label="mode switches")
    ax_e.bar(x + 0.2, [r["effort"] / 10 for r in rows_], width=0.4, color="0.6", label="effort / 10")
    ax_e.set(title="mode switches and effort (per trial)")
    ax_e.legend(loc="upper left")
    ax_e.set_xticks(x, labels, rotation=60, ha="right", fontsize=7)  # (the panels share them)
    fig.tight_layout()
    return fig


_COLOURS = ("tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple", "tab:brown", "tab:olive",
            "tab:cyan", "tab:pink", "tab:gray")
