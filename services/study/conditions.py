"""A study's conditions resolved by the names ``sctd skills`` lists, and what runs for
each block (its task resolved by the caller, where the program starts).

A condition is one of

- ``teleop``: the **competent baseline** (``sctd eval``'s, :func:`~sctd_services.eval.
  evaluate.competent_baseline`): the shipped mode-switching teleoperation with the speed
  limits (and ``speed_near`` cap) of the study's first assisted condition for that task
  and the task's control frame, so that an assisted and the teleoperated block differ in
  the assistance alone; with no assisted condition for a task, its own limits;
- a skill: as ``--skill`` takes it (a path, a stored skill, a shipped name:
  :func:`~sctd.skill.catalog.find_skill`); its object must be in each task's scene;
- a skill set: ``set:NAME`` or a set's name or file (:func:`~sctd.skill.catalog.
  find_skill_set`) when no skill has that name; each task must be one of its members'
  tasks, and a block runs in the set's room, the task's goal first
  (:func:`~sctd.task.compose.room`), with the set's inference choosing the skill.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from sctd.skill import Skill, SkillError, bundle_from_file, load_skill, skill_from_bundle
from sctd.skill.catalog import find_skill, find_skill_set
from sctd.skill.skillset import SkillSet, load_skill_set
from sctd.task import Task
from sctd.task.compose import room
from sctd_services.eval.evaluate import TELEOP as TELEOP_FILE
from sctd_services.eval.evaluate import competent_baseline, control_frame, restyled, task_of
from sctd_services.eval.goals import tasks_of

from .errors import StudyError
from .plan import TELEOP, Condition, Plan

SET_PREFIX = "set:"


def resolve_condition(name: str) -> Condition:
    """The :class:`~.plan.Condition` ``name`` names (module doc); a :class:`StudyError`
    naming ``--condition`` and the value when it names nothing."""
    if name == TELEOP:
        return Condition(name, "teleop", "competent teleoperation baseline: the shipped mode-switching "
                         "teleoperation with the assisted condition's speed limits and the task's "
                         "control frame")
    if not name.startswith(SET_PREFIX):
        try:
            skill = load_skill(find_skill(name))
            about = f"assisted: skill {skill.name} (id {skill.id}, object {skill.object})"
            return Condition(name, "skill", about)
        except SkillError as skill_error:
            try:
                find_skill_set(name)
            except SkillError:
                raise StudyError(f"--condition: {skill_error}; nor a skill set "
                                 "(sctd skills lists both; `teleop` is the baseline)") from None
    try:
        s = load_skill_set(find_skill_set(name.removeprefix(SET_PREFIX)))
    except SkillError as e:
        raise StudyError(f"--condition: {e}") from None
    return Condition(name, "set", f"skill set {s.name} (members {', '.join(m.name for m in s.members)}; "
                     "teleoperation until the set's inference engages a member)")


def _skill_set(c: Condition) -> SkillSet:
    return load_skill_set(find_skill_set(c.name.removeprefix(SET_PREFIX)))


def check_fits(conditions: Sequence[Condition], tasks: Sequence[tuple[str, Task]]) -> None:
    """Every condition can run every task: a skill's object is in the task's scene, a
    set has a member for the task. A :class:`StudyError` names both otherwise."""
    for c in conditions:
        for ref, task in tasks:
            if c.kind == "skill":
                try:
                    task_of([load_skill(find_skill(c.name))], task, ref)
                except ValueError as e:
                    raise StudyError(f"--condition: {c.name}: cannot run --task {ref}: {e}") from None
            elif c.kind == "set":
                names = [t.name for t in tasks_of([m.skill for m in _skill_set(c).members])]
                if task.name not in names:
                    raise StudyError(f"--condition: {c.name}: cannot run --task {ref}: the set's members "
                                     f"are skills for {', '.join(names)}")


@dataclass(frozen=True)
class Block:
    """What runs for one condition on one task: ``task`` the trial is judged on (for a
    set, its room with the task's goal first), and ``skill`` (a skill or the baseline)
    or ``skill_set``; ``label`` says which, for the logs."""

    condition: Condition
    task: Task
    label: str
    skill: Skill | None = None
    skill_set: SkillSet | None = None


def _reference(plan: Plan, task: Task) -> Skill | None:
    """The assisted skill whose limits the baseline takes on ``task``: the first skill
    condition's, else the first set's member for the task."""
    for c in plan.conditions:
        if c.kind == "skill":
            return load_skill(find_skill(c.name))
    for c in plan.conditions:
        if c.kind == "set":
            members = [m.skill for m in _skill_set(c).members]
            names = [t.name for t in tasks_of(members)]
            if task.name in names:
                return members[names.index(task.name)]
    return None


def block_of(plan: Plan, condition: str, task: Task) -> Block:
    """What runs for ``condition`` (as the plan names it) on ``task`` (one of the plan's,
    resolved where the program starts)."""
    c = plan.condition(condition)
    if c.kind == "skill":
        skill = load_skill(find_skill(c.name))
        return Block(c, task, skill.name, skill=skill)
    if c.kind == "set":
        s = _skill_set(c)
        return Block(c, room(tasks_of([m.skill for m in s.members]), task.name), s.name, skill_set=s)
    ref = _reference(plan, task)
    teleop = bundle_from_file(TELEOP_FILE)
    if ref is None:
        own = load_skill(TELEOP_FILE)
        bundle = restyled(teleop, own.limits, control_frame(task))
        return Block(c, task, "teleop (own limits)", skill=skill_from_bundle(bundle))
    bundle, label = competent_baseline(teleop, ref, task)
    return Block(c, task, label, skill=skill_from_bundle(bundle))
