"""Learned results -> skill bundles: the YAML text and model files, in memory.

The skill format is ``docs/skill-format.md``. :func:`skill_bundle` returns a
:class:`sctd.skill.Bundle`; :func:`sctd.skill.skill_from_bundle` validates it into a
:class:`sctd.skill.Skill`, and ``sctd learn`` writes its files next to each other.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import yaml

from ..skill import Bundle, VectorFieldModel, vector_field_model_to_bytes
from ..skill.summary import field_summary
from .linear import AXIS_NAMES
from .results import LinearResult, VectorFieldResult


def rounded(x: Any, nd: int = 6) -> Any:
    """Floats (also inside lists, tuples and arrays) rounded to ``nd`` digits, as the
    skill files store them; other values unchanged."""
    if isinstance(x, np.ndarray):
        return [rounded(v, nd) for v in x.tolist()]
    if isinstance(x, list | tuple):
        return [rounded(v, nd) for v in x]
    if isinstance(x, float | np.floating):
        return round(float(x), nd)
    return x


def state_name(k: int) -> str:
    """Name of the k-th learned state."""
    return f"s{k}"


def _dump(doc: dict, header: str) -> str:
    body = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)
    return "".join(f"# {line}\n" for line in header.splitlines()) + body


def _limits(result: LinearResult | VectorFieldResult) -> dict[str, float]:
    o = result.options
    return {"max_linear_speed": o.max_linear_speed, "max_angular_speed": o.max_angular_speed}


def linear_skill_doc(result: LinearResult, name: str) -> dict[str, Any]:
    """The skill document (a dict for YAML) of a linear-IM result."""
    L = result.learner
    states = {state_name(k): {"input_mapping": [
        {"type": "linear", "frame": st.label.frame, "matrix": rounded(st.label.matrix.tolist())}]}
        for k, st in enumerate(L.states_)}
    transitions = []
    for h in L.transitions_:
        a, b = state_name(h.source), state_name(h.target)
        n, o = rounded(h.normal, 6), round(float(h.offset), 6)
        transitions.append({"from": a, "to": b, "type": "hyperplane", "frame": h.frame,
                            "normal": n, "offset": o, "margin": h.margin})
        # The way back on the same plane: the margins leave a dead band between them.
        transitions.append({"from": b, "to": a, "type": "hyperplane", "frame": h.frame,
                            "normal": [-x for x in n], "offset": -o, "margin": h.margin})
    frames = {k: {"parent": "ee", "pose": rounded(v)} for k, v in result.frames.items()}
    doc: dict[str, Any] = {
        "sctd_skill": 1, "name": name,
        "description": (f"Learned by sctd learn --method linear from {len(result.prepared)} "
                        "demonstrations (linear IMs, alpha-beta swap, linear-SVM transitions)."),
        "object": result.options.object,
        "limits": _limits(result),
    }
    if frames:
        doc["frames"] = frames
    doc["fsm"] = {"start": state_name(0), "end": state_name(len(L.states_) - 1), "min_dwell": 0.1,
                  "transitions": transitions}
    doc["states"] = states
    return doc


def _linear_header(result: LinearResult) -> str:
    lines = ["Learned skill (sctd learn --method linear). States:"]
    for f in result.found_frames:
        lines.insert(0, f"Frame {f.name} found in the demonstrations: {f.kind}, ee offset "
                        f"{rounded(f.pose[:3], 4)}, spread {f.spread:.4f} m")
    for k, st in enumerate(result.learner.states_):
        axes = ", ".join(AXIS_NAMES[a] for a in st.label.axes)
        lines.append(f"  {state_name(k)}: {axes} in frame {st.label.frame}")
    for h in result.learner.transitions_:
        lines.append(f"  {state_name(h.source)} -> {state_name(h.target)}: hyperplane on "
                     f"{h.frame}, training accuracy {h.accuracy:.3f}, "
                     f"{'reachable' if h.reachable else 'NOT reachable by the IM'}")
    lines += [f"  {line}" for line in trap_lines(result)]
    return "\n".join(lines)


def trap_lines(result: LinearResult) -> list[str]:
    """One line per trap the check fixed and per transition without a way back by
    motion (sctd.learn.traps), for the skill's header and ``sctd learn``'s output."""
    out = []
    for f in result.traps:
        a, b = state_name(f.state), state_name(f.target)
        if f.added is not None:
            out.append(f"{a} trapped the user (reach {f.reach:.2f} of the plane to {b}): "
                       f"added {f.added}")
        if not f.way_back:
            out.append(f"{b} -> {a}: no way back by motion from where {b} is entered "
                       "(escape, button 2, returns)")
    return out


def vf_model(result: VectorFieldResult, fields: tuple[int, ...] | None = None) -> VectorFieldModel:
    """The model file's content: the fields (all, or those indexed by ``fields``) and the
    demonstration points (those the chosen fields explain)."""
    L = result.learner
    if not L.fields_:
        raise ValueError("no vector field was found in the demonstrations")
    if fields is None:
        return VectorFieldModel(fields=tuple(L.fields_), points=L.points_,
                                quaternions=L.quaternions_, responsibilities=L.responsibilities_)
    sel = np.isin(L.assignment_, fields)
    R = L.responsibilities_[sel][:, list(fields)]
    s = R.sum(axis=1, keepdims=True)
    R = np.where(s > 1e-12, R / np.maximum(s, 1e-12), 1.0 / len(fields))
    return VectorFieldModel(fields=tuple(L.fields_[m] for m in fields), points=L.points_[sel],
                            quaternions=L.quaternions_[sel], responsibilities=R)


def _vf_state(result: VectorFieldResult, model: str, fields: list) -> dict[str, Any]:
    """One state of a vector-field skill: a vector-field IM and a neighbour-orientation AC
    on the model file ``model`` (whose fields are ``fields``)."""
    p = result.field_options
    constraint: dict[str, Any] = {"type": "neighbour_orientation", "model": model, "frame": "ee",
                                  "max_n": p.vf_max_n, "max_d": p.max_d,
                                  "rotation_weight": p.vf_rotation_weight}
    pivots = [f for f in fields if f.pivot is not None]
    if pivots and p.vf_motion == "rigid":  # orientation pulled about the point the hand turned about
        constraint["pivot"] = rounded(max(pivots, key=lambda f: f.weight).pivot)
    return {"input_mapping": [{"type": "vector_field", "model": model, "frame": "ee", "mode": "scale",
                               "combine": p.vf_combine, "min_v": p.min_v, "k_s": p.k_s,
                               "max_n": p.vf_max_n, "max_d": p.max_d, "motion": p.vf_motion}],
            "active_constraints": [constraint]}


def vf_skill_doc(result: VectorFieldResult, name: str, model: str) -> dict[str, Any]:
    """The skill document of a vector-field result. Blended (the thesis): one state
    ``default`` with a vector-field IM and a neighbour-orientation AC on the model file
    ``model``. Sequential (``result.plan``): one state per field, in the order the
    demonstrations use them, each on its own model file (:func:`state_model_files`),
    with hyperplane transitions both ways between consecutive ones."""
    L, plan = result.learner, result.plan
    doc: dict[str, Any] = {
        "sctd_skill": 1, "name": name,
        "description": (f"Learned by sctd learn --method vf from {len(result.prepared)} "
                        "demonstrations (RANSAC + EM vector fields, neighbour orientation"
                        + (", one state per field in the order they are used)." if plan.sequential
                           else ").")),
        "object": result.options.object,
        "limits": _limits(result),
    }
    if not plan.sequential:
        doc["fsm"] = {"start": "default", "end": "default", "transitions": []}
        doc["states"] = {"default": _vf_state(result, model, list(L.fields_))}
    else:
        files = state_model_files(result, model)
        names = [state_name(k) for k in range(len(plan.order))]
        transitions = []
        for h in plan.transitions:  # on when the hand is where the demonstrations switched
            a, b = names[plan.order.index(h.source)], names[plan.order.index(h.target)]
            transitions.append({"from": a, "to": b, "type": "distance", "frame": "ee",
                                "point": rounded(h.point), "below": round(h.radius, 6), "margin": 0.0})
        doc["fsm"] = {"start": names[0], "end": names[-1], "min_dwell": 0.1, "transitions": transitions}
        doc["states"] = {nm: _vf_state(result, rel, [L.fields_[m]])
                         for nm, rel, m in zip(names, files, plan.order, strict=True)}
    doc["candidate_frames"] = L.candidate_frames_
    return doc


def state_model_files(result: VectorFieldResult, model: str) -> list[str]:
    """The model file of each state of a sequential vector-field skill: ``model`` with
    the state's name before its suffix (``pour-vf.npz`` -> ``pour-vf-s0.npz``)."""
    stem, dot, ext = model.rpartition(".")
    return [f"{stem}-{state_name(k)}{dot}{ext}" for k in range(len(result.plan.order))]


def _vf_header(result: VectorFieldResult) -> str:
    lines = ["Learned skill (sctd learn --method vf). Fields:"]
    plan = result.plan
    for m, f in enumerate(result.learner.fields_):
        s = field_summary(f)
        state = f"{state_name(plan.order.index(m))}: " if m in plan.order else ""
        lines.append("  " + state + ", ".join(f"{k}={rounded(v, 4)}" for k, v in s.items()))
    if plan.sequential:
        for h in plan.transitions:
            lines.append(f"  {state_name(plan.order.index(h.source))} -> "
                         f"{state_name(plan.order.index(h.target))}: the hand within "
                         f"{h.radius * 100:.1f} cm of {rounded(h.point, 3)}, where the "
                         f"demonstrations switched ({h.spread * 100:.1f} cm RMS apart); escape "
                         "(button 2) goes back")
    else:
        lines.append(f"  one state blends the fields ({plan.reason})")
    return "\n".join(lines)


def skill_bundle(result: LinearResult | VectorFieldResult, name: str) -> Bundle:
    """The learned skill as a bundle: ``name.yaml`` (a comment header summarising what
    was learned, then the document) and, for vector fields, the model ``name.npz``.

    Raises
    ------
    ValueError
        A vector-field result without any field.
    """
    if isinstance(result, LinearResult):
        text = _dump(linear_skill_doc(result, name), _linear_header(result))
        return Bundle(name=f"{name}.yaml", yaml_text=text, files={})
    rel = f"{name}.npz"
    if result.plan.sequential:
        files = {f: vector_field_model_to_bytes(vf_model(result, (m,)), f)
                 for f, m in zip(state_model_files(result, rel), result.plan.order, strict=True)}
    else:
        files = {rel: vector_field_model_to_bytes(vf_model(result), rel)}
    text = _dump(vf_skill_doc(result, name, rel), _vf_header(result))
    return Bundle(name=f"{name}.yaml", yaml_text=text, files=files)
