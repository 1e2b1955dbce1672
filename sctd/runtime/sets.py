"""A skill set file's running form: the :class:`~.goals.GoalSet` the tick driver runs, from
a :class:`~sctd.skill.skillset.SkillSet` (docs/skill-sets.md).

The set file's reader (:mod:`sctd.skill.skillset`) checks the file's structure and the
members' skills; what only the runtime knows is checked here, with the same errors
(``file: path.to.field: what is wrong``): the belief's fields and ranges
(:class:`~.goals.BeliefModel`), and that no skill of the set reacts to button 3, which
the set takes for choosing (a ``button`` transition on it would never fire). A skill
swapped into a running set is checked by :func:`check_swap` the same way.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

from ..skill import WORLD_OBJECT, Button, Skill, SkillEngine, SkillError
from ..skill.skillset import SkillSet
from ..wire.codec import BUTTON_CHOOSE
from .goals import TELEOP, BeliefModel, GoalSet, Member


def reserved_button(skill: Skill) -> str | None:
    """Why ``skill`` cannot be in a set (the field of its file and the problem), or None:
    a ``button`` transition on the choose button."""
    for k, t in enumerate(skill.transitions):
        if isinstance(t, Button) and t.button == BUTTON_CHOOSE:
            return (f"fsm.transitions[{k}].button: button {BUTTON_CHOOSE} is the skill set's "
                    "choose button: a set's skills cannot react to it")
    return None


def belief_model(spec: SkillSet) -> BeliefModel:
    """The set's :class:`~.goals.BeliefModel`: its file's ``belief`` over the defaults.

    Raises
    ------
    SkillError
        An unknown field or a value out of range, naming ``belief.<field>``.
    """
    known = {f.name for f in dataclasses.fields(BeliefModel)}
    for key in spec.belief:
        if key not in known:
            raise SkillError(spec.source, f"belief.{key}",
                             f"unknown field (allowed: {', '.join(sorted(known))})")
    try:
        return BeliefModel(**spec.belief)
    except ValueError as e:  # "<field>: <problem>"
        key, _, problem = str(e).partition(": ")
        raise SkillError(spec.source, f"belief.{key}", problem or str(e)) from None


def goal_set(spec: SkillSet, engines: Sequence[SkillEngine] | None = None) -> GoalSet:
    """The running set of ``spec``: its members with their settings (the rest
    :class:`~.goals.Member`'s defaults), its teleoperation and its belief model.

    Raises
    ------
    SkillError
        Naming the set file and the field (module doc).
    """
    problem = reserved_button(spec.teleop)
    if problem is not None:
        raise SkillError(spec.source, "teleop", f"{spec.teleop.source}: {problem}")
    for i, m in enumerate(spec.members):
        problem = reserved_button(m.skill)
        if problem is not None:
            raise SkillError(spec.source, f"members[{i}].skill", f"{m.skill.source}: {problem}")
    model = belief_model(spec)
    members = [Member(m.skill, **m.settings) for m in spec.members]
    return GoalSet(members, spec.teleop, model, engines)


def check_swap(goals: GoalSet, skill: Skill, member: str | None) -> str:
    """The member of the running set ``skill`` replaces: ``member`` when given, else the
    member of the skill's own name.

    Raises
    ------
    SkillError
        No such member, none of that name, a name another member (or teleoperation)
        has, or a skill that reacts to the choose button.
    """
    names = [m.name for m in goals.members]
    where = skill.source or "<bundle>"
    if member is None:
        if skill.name not in names:
            raise SkillError(where, "name", f"{skill.name!r} is no member of the running skill set "
                                            f"(members: {', '.join(names)}): name the member it "
                                            "replaces (skill/swap?member=NAME)")
        member = skill.name
    elif member not in names:
        raise SkillError(where, "", f"member {member!r}: no such member of the running skill set "
                                    f"(members: {', '.join(names)})")
    taken = [n for n in names if n != member] + [goals.teleop.name]
    if skill.name in taken:
        raise SkillError(where, "name", f"{skill.name!r} is the name of another skill of the running "
                                        f"set (its skills: {', '.join(taken)})")
    if skill.object == WORLD_OBJECT:
        raise SkillError(where, "object", f"a member of a skill set is tied to its task object, not "
                                          f"{WORLD_OBJECT!r}")
    problem = reserved_button(skill)
    if problem is not None:
        raise SkillError(where, "", problem)
    return member


def set_summary(name: str, goals: GoalSet) -> dict[str, Any]:
    """The set's part of the ``skill`` summary (docs/wire-contract.md): its name, the
    engaged member (``teleop`` while none is), teleoperation's and each member's id, name
    and object, with the member's start region settings."""
    def brief(s: Skill) -> dict[str, Any]:
        return {"id": s.id, "name": s.name, "object": s.object}
    engaged = goals.engaged
    return {"name": name,
            "engaged": TELEOP if engaged is None else goals.members[engaged].name,
            "teleop": brief(goals.teleop),
            "members": [brief(m.skill) | {"point": list(m.point), "reach": m.reach,
                                          "position_tolerance": m.position_tolerance,
                                          "angle_tolerance": m.angle_tolerance}
                        for m in goals.members]}
