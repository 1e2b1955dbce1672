"""The skill's structure as plain data (``sctd inspect --json``, the skill query)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .. import se3
from .model import (
    Band,
    Box,
    Field,
    LinearMapping,
    NeighbourOrientation,
    Skill,
    TiltCone,
    Transition,
    VectorFieldMapping,
)


def _list(a: np.ndarray | None) -> list | None:
    return None if a is None else np.asarray(a, dtype=float).round(12).tolist()


def field_summary(f: Field) -> dict[str, Any]:
    out: dict[str, Any] = {"type": f.type, "inliers": f.inliers, "weight": f.weight,
                           "sigma": f.sigma}
    if f.type == "translation":
        out["direction"] = _list(f.direction)
    elif f.type == "cylinder":
        out["point"] = _list(f.point)
        out["axis"] = _list(f.axis)
    else:
        out["centre"] = _list(f.centre)
        if f.radius is not None:
            out["radius"] = f.radius
    if f.pivot is not None:
        out["pivot"] = _list(f.pivot)
    return out


def _mapping(m) -> dict[str, Any]:
    if isinstance(m, LinearMapping):
        return {"type": "linear", "frame": m.frame, "translation": m.translation, "rotation": m.rotation,
                "matrix": _list(m.matrix)}
    assert isinstance(m, VectorFieldMapping)
    return {"type": "vector_field", "frame": m.frame, "model": m.model_file, "mode": m.mode,
            "combine": m.combine, "intent_kappa": m.intent_kappa, "min_v": m.min_v, "k_s": m.k_s,
            "max_n": m.max_n, "max_d": m.max_d, "blend": m.blend, "motion": m.motion,
            "fields": len(m.model.fields)}


def _constraint(c) -> dict[str, Any]:
    if isinstance(c, TiltCone):
        return {"type": c.type, "frame": c.frame, "axis": _list(c.axis),
                "reference": _list(c.reference), "max_angle": c.max_angle}
    if isinstance(c, Band):
        return {"type": c.type, "frame": c.frame, "normal": _list(c.normal),
                "point": _list(c.point), "lower": c.lower, "upper": c.upper}
    if isinstance(c, Box):
        return {"type": c.type, "frame": c.frame, "lower": _list(c.lower), "upper": _list(c.upper)}
    assert isinstance(c, NeighbourOrientation)
    out = {"type": c.type, "frame": c.frame, "model": c.model_file, "max_n": c.max_n,
           "max_d": c.max_d, "rotation_weight": c.rotation_weight, "points": len(c.model.points)}
    if c.pivot is not None:
        out["pivot"] = _list(c.pivot)
    return out


def _transition(t: Transition) -> dict[str, Any]:
    out: dict[str, Any] = {"from": t.source, "to": t.target, "type": t.type}
    if t.type == "hyperplane":
        out.update(frame=t.frame, normal=_list(t.normal), offset=t.offset, margin=t.margin)
    elif t.type == "distance":
        out.update(frame=t.frame, point=_list(t.point), margin=t.margin)
        out[t.direction] = t.threshold
    elif t.type == "timeout":
        out["after"] = t.threshold
    elif t.type == "button":
        out["button"] = t.button
    else:
        out.update(above=t.threshold, axis=_list(t.axis), margin=t.margin)
    return out


def skill_summary(skill: Skill) -> dict[str, Any]:
    """Everything a person or program needs to see what a skill does."""
    fields: list[dict[str, Any]] = []
    seen: set[int] = set()
    for s in skill.states:
        for m in s.input_mappings:
            if isinstance(m, VectorFieldMapping) and id(m.model) not in seen:
                seen.add(id(m.model))
                fields.extend(field_summary(f) for f in m.model.fields)
    return {
        "id": skill.id,
        "name": skill.name,
        "description": skill.description,
        "source": skill.source,
        "object": skill.object,
        "start": skill.start,
        "end": skill.end,
        "limits": {"max_linear_speed": skill.limits.max_linear_speed,
                   "max_angular_speed": skill.limits.max_angular_speed},
        "frames": {n: {"parent": f.parent, "pose": _list(se3.pose_from_transform(f.T_parent_frame))}
                   for n, f in skill.frames.items() if n not in ("ee", "object")},
        "states": [{"name": s.name,
                    "input_mappings": [_mapping(m) for m in s.input_mappings],
                    "active_constraints": [_constraint(c) for c in s.active_constraints]}
                   for s in skill.states],
        "transitions": [_transition(t) for t in skill.transitions],
        "min_dwell": skill.min_dwell,
        "fields": fields,
        "candidate_frames": list(skill.candidate_frames),
    }
