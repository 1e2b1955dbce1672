"""The skill's structure as plain data (``sctd inspect --json``, the skill query).

Each element summarises itself (its class's ``summary``); this module adds the
skill-level parts.
"""

from __future__ import annotations

from typing import Any

from .. import se3
from .fields import Field
from .model import Skill, State
from .registry import plain


def field_summary(f: Field) -> dict[str, Any]:
    """One vector field as plain data, for a person: its summary, a general field's
    centres counted rather than listed (a model file holds the whole summary)."""
    return f.brief()


def skill_summary(skill: Skill) -> dict[str, Any]:
    """Everything a person or program needs to see what a skill does."""
    fields: list[dict[str, Any]] = []
    seen: set[str] = set()
    for s in skill.states:
        for m in s.input_mappings:
            for rel, model in m.models():
                if rel not in seen:
                    seen.add(rel)
                    # With more than one state, each field names the (first) one it is in.
                    named = {"state": s.name} if len(skill.states) > 1 else {}
                    fields.extend(field_summary(f) | named for f in model.fields)
    return {
        "id": skill.id,
        "name": skill.name,
        "description": skill.description,
        "source": skill.source,
        "object": skill.object,
        "objects": list(skill.objects()),
        "start": skill.start,
        "end": skill.end,
        "limits": {"max_linear_speed": skill.limits.max_linear_speed,
                   "max_angular_speed": skill.limits.max_angular_speed},
        "frames": {n: {"parent": f.parent,
                       "pose": plain(se3.pose_from_transform(f.T_parent_frame))}
                   for n, f in skill.frames.items() if n not in ("ee", "object")},
        "states": [_state(s) for s in skill.states],
        "transitions": [t.summary() for t in skill.transitions],
        "min_dwell": skill.min_dwell,
        "fields": fields,
        "candidate_frames": list(skill.candidate_frames),
    }


def _state(s: State) -> dict[str, Any]:
    """A state's mappings and constraints, and its own object and gripper action where
    it has them."""
    out: dict[str, Any] = {"name": s.name, "input_mappings": [m.summary() for m in s.input_mappings],
                           "active_constraints": [c.summary() for c in s.active_constraints]}
    if s.object is not None:
        out["object"] = s.object
    if s.gripper is not None:
        out["gripper"] = s.gripper.to_yaml()
    return out
