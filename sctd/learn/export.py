"""Learned results -> skill YAML (+ model file) and the learning report.

The skill format is ``docs/skill-format.md``; every written skill is loaded back with
:func:`sctd.skill.load_skill` before this returns, so a learned skill that the runtime
would reject is an error here, not at run time.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ..skill import Skill, VectorFieldModel, load_skill, vector_field_model_to_bytes
from ..skill.summary import field_summary, skill_summary
from .linear import AXIS_NAMES
from .pipeline import LinearResult, VectorFieldResult


def _r(x: Any, nd: int = 6) -> Any:
    if isinstance(x, np.ndarray):
        return [_r(v, nd) for v in x.tolist()]
    if isinstance(x, list | tuple):
        return [_r(v, nd) for v in x]
    if isinstance(x, float | np.floating):
        return round(float(x), nd)
    return x


def _dump(doc: dict, header: str) -> str:
    body = yaml.safe_dump(doc, sort_keys=False, default_flow_style=None, width=100)
    return "".join(f"# {line}\n" for line in header.splitlines()) + body


def _write_and_validate(path: Path, text: str) -> Skill:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)
    return load_skill(path)


def state_name(k: int) -> str:
    return f"s{k}"


def linear_skill_doc(result: LinearResult, name: str) -> dict:
    """The skill document (a dict for YAML) of a linear-IM result."""
    L = result.learner
    p = result.params
    states = {}
    for k, st in enumerate(L.states_):
        states[state_name(k)] = {"input_mapping": [
            {"type": "linear", "frame": st.label.frame, "matrix": _r(st.label.matrix.tolist())}]}
    transitions = []
    for h in L.transitions_:
        a, b = state_name(h.source), state_name(h.target)
        n, o = _r(h.normal, 6), round(float(h.offset), 6)
        transitions.append({"from": a, "to": b, "type": "hyperplane", "frame": h.frame,
                            "normal": n, "offset": o, "margin": h.margin})
        # The way back on the same plane: the margins leave a dead band between them.
        transitions.append({"from": b, "to": a, "type": "hyperplane", "frame": h.frame,
                            "normal": [-x for x in n], "offset": -o, "margin": h.margin})
    frames = {k: {"parent": "ee", "pose": _r(v)} for k, v in result.frames.items()}
    doc: dict[str, Any] = {
        "sctd_skill": 1, "name": name,
        "description": (f"Learned by sctd learn --method linear from {len(result.prepared)} "
                        "demonstrations (linear IMs, alpha-beta swap, linear-SVM transitions)."),
        "object": p.object,
        "limits": {"max_linear_speed": p.max_linear_speed, "max_angular_speed": p.max_angular_speed},
    }
    if frames:
        doc["frames"] = frames
    doc["fsm"] = {"start": state_name(0), "end": state_name(len(L.states_) - 1), "min_dwell": 0.1,
                  "transitions": transitions}
    doc["states"] = states
    return doc


def write_linear_skill(result: LinearResult, out: str | Path) -> Skill:
    """Write the FSM of linear IMs as a skill YAML and validate it by loading it."""
    out = Path(out)
    doc = linear_skill_doc(result, out.stem)
    lines = ["Learned skill (sctd learn --method linear). States:"]
    for k, st in enumerate(result.learner.states_):
        axes = ", ".join(AXIS_NAMES[a] for a in st.label.axes)
        lines.append(f"  {state_name(k)}: {axes} in frame {st.label.frame}")
    for h in result.learner.transitions_:
        lines.append(f"  {state_name(h.source)} -> {state_name(h.target)}: hyperplane on "
                     f"{h.frame}, training accuracy {h.accuracy:.3f}, "
                     f"{'reachable' if h.reachable else 'NOT reachable by the IM'}")
    return _write_and_validate(out, _dump(doc, "\n".join(lines)))


def vf_model(result: VectorFieldResult) -> VectorFieldModel:
    L = result.learner
    if not L.fields_:
        raise ValueError("no vector field was found in the demonstrations")
    return VectorFieldModel(fields=tuple(L.fields_), points=L.points_,
                            quaternions=L.quaternions_, responsibilities=L.responsibilities_)


def write_vf_skill(result: VectorFieldResult, out: str | Path) -> Skill:
    """Write a one-state skill: a vector-field IM and a neighbour-orientation AC sharing
    one ``.npz`` model file next to the YAML; validate it by loading it."""
    out = Path(out)
    p = result.params
    rel = out.stem + ".npz"
    data = vector_field_model_to_bytes(vf_model(result), rel)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(rel + ".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, out.with_name(rel))
    constraint: dict[str, Any] = {"type": "neighbour_orientation", "model": rel, "frame": "ee",
                                  "max_n": p.vf_max_n, "max_d": p.max_d,
                                  "rotation_weight": p.vf_rotation_weight}
    pivots = [f for f in result.learner.fields_ if f.pivot is not None]
    if pivots and p.vf_motion == "rigid":  # orientation pulled about the point the hand turned about
        constraint["pivot"] = _r(max(pivots, key=lambda f: f.weight).pivot)
    doc = {
        "sctd_skill": 1, "name": out.stem,
        "description": (f"Learned by sctd learn --method vf from {len(result.prepared)} "
                        "demonstrations (RANSAC + EM vector fields, neighbour orientation)."),
        "object": p.object,
        "limits": {"max_linear_speed": p.max_linear_speed, "max_angular_speed": p.max_angular_speed},
        "fsm": {"start": "default", "end": "default", "transitions": []},
        "states": {"default": {
            "input_mapping": [{"type": "vector_field", "model": rel, "frame": "ee", "mode": "scale",
                               "combine": p.vf_combine, "min_v": p.min_v, "k_s": p.k_s,
                               "max_n": p.vf_max_n, "max_d": p.max_d, "motion": p.vf_motion}],
            "active_constraints": [constraint]}},
        "candidate_frames": result.learner.candidate_frames_,
    }
    lines = ["Learned skill (sctd learn --method vf). Fields:"]
    for f in result.learner.fields_:
        s = field_summary(f)
        lines.append("  " + ", ".join(f"{k}={_r(v, 4)}" for k, v in s.items()))
    return _write_and_validate(out, _dump(doc, "\n".join(lines)))


def summary_dict(result: LinearResult | VectorFieldResult, skill: Skill,
                 demos_dir: str = "") -> dict[str, Any]:
    """``summary.json``: hyperparameters, per-demo labels, fields, timings."""
    from dataclasses import asdict

    out: dict[str, Any] = {
        "method": "linear" if isinstance(result, LinearResult) else "vf",
        "demos_dir": demos_dir,
        "skill": skill_summary(skill),
        "hyperparameters": asdict(result.params),
        "labels": result.labels,
        "timings": {k: round(v, 4) for k, v in result.timings.items()},
        "samples": {p.name: {"raw": p.n_raw, "kept": len(p.keep)} for p in result.prepared},
    }
    if isinstance(result, LinearResult):
        L = result.learner
        out["frames"] = {k: _r(v) for k, v in result.frames.items()}
        out["states"] = [{"name": state_name(k), "frame": st.label.frame,
                          "axes": [AXIS_NAMES[a] for a in st.label.axes], "support": st.support}
                         for k, st in enumerate(L.states_)]
        out["transitions"] = [{"from": state_name(h.source), "to": state_name(h.target),
                               "frame": h.frame, "accuracy": round(h.accuracy, 4),
                               "reachable": h.reachable, "candidates": h.candidates}
                              for h in L.transitions_]
        out["energy"] = {"initial": L.energy_initial_, "final": L.energy_}
        out["graph_labels"] = {p.name: [L.labels_[j].name for j in f]
                               for p, f in zip(result.prepared, L.graph_labels_, strict=True)}
        out["fields"] = []
        out["candidate_frames"] = []
    else:
        V = result.learner
        out["fields"] = [field_summary(f) for f in V.fields_]
        out["ransac_fields"] = [field_summary(f) | {"inliers": int(m.sum())}
                                for f, m in zip(V.ransac_fields_, V.ransac_inliers_, strict=True)]
        out["field_labels"] = result.field_labels
        out["candidate_frames"] = V.candidate_frames_
    return out


def write_report(result: LinearResult | VectorFieldResult, skill: Skill,
                 report_dir: str | Path | None, demos_dir: str = "") -> dict[str, Any]:
    """Write ``summary.json`` and the PNG figures into ``report_dir`` (if given)."""
    summary = summary_dict(result, skill, demos_dir)
    if report_dir is None:
        return summary
    d = Path(report_dir)
    d.mkdir(parents=True, exist_ok=True)
    from . import plots

    figs = plots.linear_figures(result, d) if isinstance(result, LinearResult) \
        else plots.vf_figures(result, d)
    summary["figures"] = [f.name for f in figs]
    (d / "summary.json").write_text(json.dumps(summary, indent=1, default=_json_default) + "\n")
    return summary


def _json_default(o: Any) -> Any:
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.integer | np.floating | np.bool_):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
