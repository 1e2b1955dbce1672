"""Goal inference in a room of several tasks (``sctd eval --set``): the skill set against
the right skill pre-selected and against teleoperation, trial by trial.

The room is the members' tasks composed into one scene (:func:`~sctd.task.compose.room`), laid out
once in the set's order (the first member's task gives the hand's start), so that every
trial's room is the same whatever the user goes for. Each trial draws the user's goal
at random from its seed (:func:`goal_of`) and runs three lockstep trials from the same
seeded start with the same simulated user (:class:`~sctd_services.user.SetUser` under
the set; it does not know about the inference and escapes a skill for another object
than its own):

- **set**: the tick driver with the skill set (:mod:`sctd.runtime.goals`): teleoperation
  until a member engages;
- **preselected**: the goal task's member alone, as if a person had picked it from a
  menu before starting;
- **teleop**: the competent baseline for the goal (:func:`~.evaluate.competent_baseline`):
  the set's teleoperation with the goal member's speed limits and ``speed_near`` cap and
  the goal task's control frame, as ``sctd eval`` and ``sctd suite`` compare a skill
  with. (Under **set**, the set's own teleoperation runs until a member engages, as its
  file says: the report names both.)

With ``practice``, the user is practised (:class:`~sctd_services.user.SimulatedUser`):
before the trials it did the goal's task once with the goal's skill and once with
teleoperation (from a start no measured trial has, :data:`PRACTICE_SEED`), and starts
every condition knowing what the stick does in the modes it used there, as the
participants of a user study trained on each condition before they are measured.

With ``detour``, the user changes its mind (:class:`~sctd_services.user.SetUser`): it
first goes for another task of the room (:func:`detour_of`), and once there decides for
its goal; such trials run the set and teleoperation with the same person (a pre-selected
skill would have been the first task's).

Per trial: the goal, every engagement and disengagement, the belief over time (10 Hz),
whether the first skill engaged was the one the user wanted then and whether the goal's
was engaged at all, the time from the start to the goal's engagement, the wrong
engagements and how long each took to undo, with a change of mind how long a skill
still engaged then took to leave, and each condition's outcome and time
(:func:`summarise_set` puts them together).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from contextlib import ExitStack
from dataclasses import dataclass, replace
from multiprocessing import get_context
from typing import Any

import numpy as np

from sctd.runtime.sets import belief_model, goal_set
from sctd.skill import Skill, skill_from_bundle
from sctd.skill.skillset import SkillSet, load_skill_set
from sctd.task import Task, task_for_object
from sctd.task.compose import room
from sctd_services.user import DEFAULT_MODEL
from sctd_services.user.agent import Device

from .evaluate import competent_baseline
from .lockstep import practise, run_set_trial, run_trial
from .numerics import describe, numerics
from .trial import TaskSpec

CONDITIONS = ("set", "preselected", "teleop")
DETOUR_STUCK = 20.0
"""s added to a trial's ``stuck_after`` when the user goes for another task first (its
goal makes no progress meanwhile)."""
PRACTICE_SEED = 999_983  # the practice runs' start (measured trials count up from their seed)


@dataclass(frozen=True)
class SetSpec:
    """What every trial of a set's evaluation shares: the set file (docs/skill-sets.md;
    the room's tasks are its members', in its order), the user's profile and the limits
    of a trial (s)."""

    set_file: str
    profile: str = "pausing"
    user_model: str = DEFAULT_MODEL
    time_limit: float | None = None  # s per trial; None: the goal task file's own
    stuck_after: float = 10.0
    conditions: tuple[str, ...] = CONDITIONS
    practice: bool = False
    detour: bool = False  # the user first goes for another task, then changes their mind
    belief: tuple[tuple[str, float], ...] = ()  # the belief's parameters over the file's

    @property
    def runs(self) -> tuple[str, ...]:
        """The conditions a trial runs: with a change of mind, no pre-selected skill (the
        person would have picked the first task's from the menu)."""
        return tuple(c for c in self.conditions if not (self.detour and c == "preselected"))

    def skill_set(self) -> SkillSet:
        """The set file read, with ``belief`` over its belief's parameters (checked when
        the set is made to run, :func:`~sctd.runtime.sets.goal_set`)."""
        s = load_skill_set(self.set_file)
        return replace(s, belief={**s.belief, **dict(self.belief)}) if self.belief else s


def tasks_of(skills: Sequence[Skill]) -> list[Task]:
    """The task of each member (the known task whose object its object is).

    Raises
    ------
    ValueError
        Naming a skill whose object no known task has, or two members of one task.
    """
    tasks = []
    for s in skills:
        t = task_for_object(s.object)
        if t is None:
            raise ValueError(f"skill {s.name!r}: no known task has the object {s.object!r} "
                             "(sctd tasks lists them)")
        tasks.append(t)
    names = [t.name for t in tasks]
    if len(set(names)) != len(names):
        raise ValueError(f"two members are skills for one task ({', '.join(names)}): a room holds "
                         "each task once")
    return tasks


def goal_members(set_file: str) -> tuple:
    """The members of the set file (:class:`~sctd.skill.skillset.SetMember`), read and
    checked."""
    return load_skill_set(set_file).members


def goal_of(seed: int, names: Sequence[str]) -> str:
    """The task the user of trial ``seed`` goes for (uniform, from the seed alone)."""
    return names[int(np.random.default_rng([seed, 31]).integers(len(names)))]


def detour_of(seed: int, names: Sequence[str]) -> str:
    """The task the user of trial ``seed`` goes for first when it changes its mind: one
    of the others than its goal (uniform, from the seed alone)."""
    goal = goal_of(seed, names)
    others = [n for n in names if n != goal]
    return others[int(np.random.default_rng([seed, 32]).integers(len(others)))]


def set_job(spec: SetSpec, seed: int) -> dict[str, Any]:
    """Trial ``seed``: the user's goal, and each condition's run (module doc)."""
    skill_set = spec.skill_set()
    skills = [m.skill for m in skill_set.members]
    tasks = tasks_of(skills)
    names = [t.name for t in tasks]
    goal = goal_of(seed, names)
    task = room(tasks, goal)
    stuck = spec.stuck_after + (DETOUR_STUCK if spec.detour else 0.0)
    tspec = TaskSpec(goal, profile=spec.profile, user_model=spec.user_model, time_limit=spec.time_limit,
                     stuck_after=stuck)
    right = skills[names.index(goal)]
    out: dict[str, Any] = {"seed": seed, "goal": goal, "skill": right.name}
    known: dict[str, dict[str, Device]] = {"preselected": {}, "teleop": {}, "set_teleop": {}}
    if spec.practice:  # (the set's own teleoperation, and the baseline's, each practised)
        for c, index in (("preselected", names.index(goal)), ("set_teleop", SET_TELEOP),
                         ("teleop", BASELINE)):
            if c != "set_teleop" or "set" in spec.runs:
                known[c] = _practised(spec.set_file, goal, index, spec.profile, spec.user_model)
    detour = detour_skill = None
    if spec.detour:
        first = detour_of(seed, names)
        detour, detour_skill = room(tasks, first), skills[names.index(first)].name
        out.update(detour=first, detour_skill=detour_skill)
    if "set" in spec.runs:
        goals = goal_set(skill_set)
        shown = {f"{right.name}:{m}": d for m, d in known["preselected"].items()}
        shown.update({f"{skill_set.teleop.name}:{m}": d for m, d in known["set_teleop"].items()})
        res, watch = run_set_trial(goals, task, tspec, seed, known=shown, detour=detour)
        if spec.practice:
            out["practised_modes"] = sorted(shown)
        out["set"] = res.as_dict(with_trajectory=False)
        out.update(engagements(watch.changes, right.name, goals.teleop.name, detour_skill, watch.changed_at))
        out.update(escapes=goals.counters.escapes, changed_at=watch.changed_at,
                   belief_trace=watch.belief)
    if "preselected" in spec.runs:
        out["preselected"] = run_trial(right, tspec, seed, task=task, known=known["preselected"],
                                       detour=detour).as_dict(with_trajectory=False)
    if "teleop" in spec.runs:
        baseline, out["baseline"] = competent_baseline(skill_set.teleop_bundle, right, task)
        out["teleop"] = run_trial(skill_from_bundle(baseline), tspec, seed, task=task, known=known["teleop"],
                                  detour=detour).as_dict(with_trajectory=False)
    return out


SET_TELEOP, BASELINE = -1, -2  # _practised's members other than the set's skills


@functools.lru_cache(maxsize=64)
def _practised(set_file: str, goal: str, member: int, profile: str, user_model: str = DEFAULT_MODEL
               ) -> dict[str, Device]:
    """What the user learned of the device doing ``goal``'s task once from
    :data:`PRACTICE_SEED` with member ``member``'s skill (:data:`SET_TELEOP`: the set's
    teleoperation; :data:`BASELINE`: the goal's competent baseline), by mode (once per
    process: every trial of an evaluation starts from the same practice)."""
    skill_set = load_skill_set(set_file)
    tasks = tasks_of([m.skill for m in skill_set.members])
    place = room(tasks, goal)
    right = skill_set.members[[t.name for t in tasks].index(goal)].skill
    if member == BASELINE:
        skill = skill_from_bundle(competent_baseline(skill_set.teleop_bundle, right, place)[0])
    else:
        skill = skill_set.teleop if member == SET_TELEOP else skill_set.members[member].skill
    spec = TaskSpec(goal, profile=profile, user_model=user_model)
    return practise(skill, spec, PRACTICE_SEED, task=place)[1]


def engagements(changes: Sequence[tuple[float, str, str]], right: str, teleop: str,
                detour: str | None = None, changed_at: float | None = None) -> dict[str, Any]:
    """What the changes of the running skill (time, from, to) of a trial say: the first
    member engaged, whether it was the one the user wanted then, whether ``right`` (the
    goal's) was ever engaged and when first, the wrong engagements (of a member the user
    did not want then) and the seconds each took to undo (None: never undone).

    With a change of mind (``detour``: the skill of the task the user went for first,
    until ``changed_at``), that skill is the one wanted before the change; one still
    engaged at the change is undone ``after_change_s`` after it (None: none was engaged;
    NaN: never undone)."""
    def wanted(t: float) -> str:
        return detour if detour is not None and (changed_at is None or t < changed_at) else right

    engaged = [(t, to) for t, _, to in changes if to != teleop]
    first = engaged[0] if engaged else None
    t_right = next((t for t, to in engaged if to == right), None)
    recovery: list[float | None] = []
    for k, (t, _, to) in enumerate(changes):
        if to == teleop or to == wanted(t):
            continue
        out = next((t2 for t2, f2, _ in changes[k + 1:] if f2 == to), None)
        recovery.append(None if out is None else round(out - t, 3))
    after: float | None = None
    if detour is not None and changed_at is not None:
        running = next((to for t, _, to in reversed(changes) if t < changed_at), teleop)
        if running == detour:
            left = next((t for t, f, _ in changes if t >= changed_at and f == detour), None)
            after = math.nan if left is None else round(left - changed_at, 3)
    return {"first_engaged": None if first is None else first[1],
            "right_first": first is not None and first[1] == wanted(first[0]),
            "right_engaged": t_right is not None,
            "t_engaged": None if t_right is None else round(t_right, 3), "wrong": len(recovery),
            "recovery_s": recovery, "after_change_s": after,
            "changes": [(round(t, 3), f, to) for t, f, to in changes]}


def evaluate_set(spec: SetSpec, trials: int, seed: int = 0, jobs: int = 1,
                 progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """``trials`` trials (seeds ``seed ..``), in ``jobs`` spawned processes; their
    summary (:func:`summarise_set`) with ``per_trial``."""
    seeds = list(range(seed, seed + trials))
    per_trial: list[dict[str, Any]] = []
    with ExitStack() as stack:
        n = max(1, min(jobs, trials))
        if n > 1:
            pool = stack.enter_context(ProcessPoolExecutor(n, mp_context=get_context("spawn")))
            runs = (f.result() for f in [pool.submit(set_job, spec, s) for s in seeds])
        else:
            runs = (set_job(spec, s) for s in seeds)
        for r in runs:
            per_trial.append(r)
            if progress:
                progress(len(per_trial), trials)
    skill_set = spec.skill_set()
    out = summarise_set(per_trial, spec.runs)
    out.update(set=skill_set.name, set_file=spec.set_file, members=[m.name for m in skill_set.members],
               room=[t.name for t in tasks_of([m.skill for m in skill_set.members])],
               teleop=skill_set.teleop.name,
               baselines={r["goal"]: r["baseline"] for r in per_trial if "baseline" in r},
               profile=spec.profile, user_model=spec.user_model,
               practice=spec.practice, detour=spec.detour, seed=seed,
               belief=dataclasses.asdict(belief_model(skill_set)), numerics=numerics(),
               per_trial=per_trial)
    return out


def _median(xs: Sequence[float]) -> float | None:
    return round(float(np.median(xs)), 3) if xs else None


def summarise_set(per_trial: Sequence[dict[str, Any]], conditions: Sequence[str] = CONDITIONS
                  ) -> dict[str, Any]:
    """The evaluation's figures: the share of trials whose goal's skill was engaged
    (first, and at all), the time to that engagement, the wrong engagements and their
    recovery, each condition's successes and median time, and the set's time against
    each other condition (the median of per-trial ratios over trials both finished;
    ``duration_s``: from the start to the task done, inference included), overall and
    per goal."""
    out: dict[str, Any] = {"trials": len(per_trial), "overall": _figures(per_trial, conditions)}
    goals = sorted({r["goal"] for r in per_trial})
    out["by_goal"] = {g: _figures([r for r in per_trial if r["goal"] == g], conditions) for g in goals}
    return out


def _figures(rows: Sequence[dict[str, Any]], conditions: Sequence[str]) -> dict[str, Any]:
    out: dict[str, Any] = {"trials": len(rows)}
    for c in conditions:
        ok = [r[c]["duration_s"] for r in rows if r[c]["outcome"] == "success"]
        out[c] = {"successes": len(ok), "median_s": _median(ok)}
    if "set" not in conditions or not rows:
        return out
    recov = [x for r in rows for x in r["recovery_s"] if x is not None]
    out.update(
        right_first=round(sum(r["right_first"] for r in rows) / len(rows), 4),
        right_engaged=round(sum(r["right_engaged"] for r in rows) / len(rows), 4),
        t_engaged_median=_median([r["t_engaged"] for r in rows if r["t_engaged"] is not None]),
        wrong=sum(r["wrong"] for r in rows), wrong_undone=len(recov), recovery_median_s=_median(recov))
    stale = [r["after_change_s"] for r in rows if r.get("after_change_s") is not None]
    undone = [x for x in stale if not math.isnan(x)]
    if any("detour" in r for r in rows):
        out.update(engaged_at_change=len(stale), undone_after_change=len(undone),
                   after_change_median_s=_median(undone))
    for c in conditions:
        if c == "set":
            continue
        both = [r for r in rows if r["set"]["outcome"] == "success" and r[c]["outcome"] == "success"]
        ratios = [r["set"]["duration_s"] / r[c]["duration_s"] for r in both if r[c]["duration_s"] > 0]
        out[f"set_vs_{c}"] = _median(ratios)
        out[f"set_vs_{c}_pairs"] = len(ratios)
    return out


def format_set_report(r: dict[str, Any]) -> str:
    """Human-readable table of :func:`evaluate_set`'s result."""
    practised = " (practised)" if r.get("practice") else ""
    lines = [f"skill set {r['set']}: {', '.join(r['members'])} (teleoperation until a member engages: "
             f"{r['teleop']}) in a room of {', '.join(r['room'])}; user {r['profile']}{practised}, "
             f"{r['trials']} lockstep trials from seed {r['seed']}",
             "goal            trials  right first  right at all  t engaged [s]  wrong (undone, median s)  "
             "success set/pre/teleop  median s set/pre/teleop  set/pre  set/teleop"]
    rows = [*(("all", r["overall"]),), *r["by_goal"].items()]
    for name, f in rows:
        if "right_first" not in f:
            continue
        succ = "/".join(str(f[c]["successes"]) if c in f else "-" for c in CONDITIONS)
        med = "/".join(_fmt(f[c]["median_s"]) if c in f else "-" for c in CONDITIONS)
        lines.append(f"{name:<15} {f['trials']:>6}  {f['right_first']:>11.0%}  {f['right_engaged']:>12.0%}  "
                     f"{_fmt(f['t_engaged_median']):>13}  {f['wrong']:>5} ({f['wrong_undone']}, "
                     f"{_fmt(f['recovery_median_s'])}){'':<9}  {succ:>22}  {med:>23}  "
                     f"{_fmt(f.get('set_vs_preselected')):>7}  {_fmt(f.get('set_vs_teleop')):>10}")
    o = r["overall"]
    if "engaged_at_change" in o:
        lines.append(f"change of mind: the first task's skill was engaged when the user changed its "
                     f"mind in {o['engaged_at_change']} of {o['trials']} trials, escaped in "
                     f"{o['undone_after_change']}, median {_fmt(o['after_change_median_s'])} s after "
                     "the change")
    for goal, label in sorted(r.get("baselines", {}).items()):
        lines.append(f"teleop for {goal}: {label}")
    if "numerics" in r:
        lines.append(describe(r["numerics"]))
    return "\n".join(lines)


def _fmt(x: float | None) -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else f"{x:.2f}"
