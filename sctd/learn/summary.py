"""What a learning run found, as plain data: ``summary.json`` of ``sctd learn`` and the
``report`` of the learner service's reply (no I/O here)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..skill import Skill
from ..skill.summary import field_summary, skill_summary
from .bundle import rounded, state_name, trap_lines
from .linear import AXIS_NAMES
from .results import LinearResult, VectorFieldResult


def _linear_summary(result: LinearResult) -> dict[str, Any]:
    L = result.learner
    return {
        "frames": {k: rounded(v) for k, v in result.frames.items()},
        "found_frames": [f.summary() for f in result.found_frames],
        "states": [{"name": state_name(k), "frame": st.label.frame,
                    "axes": [AXIS_NAMES[a] for a in st.label.axes], "support": st.support}
                   for k, st in enumerate(L.states_)],
        "transitions": [{"from": state_name(h.source), "to": state_name(h.target),
                         "frame": h.frame, "accuracy": round(h.accuracy, 4),
                         "reachable": h.reachable, "candidates": h.candidates}
                        for h in L.transitions_],
        "traps": [f.summary(state_name) for f in result.traps],
        "trap_notes": trap_lines(result),
        "energy": {"initial": L.energy_initial_, "final": L.energy_},
        "graph_labels": {p.name: [L.labels_[j].name for j in f]
                         for p, f in zip(result.prepared, L.graph_labels_, strict=True)},
        "fields": [],
        "candidate_frames": [],
    }


def _vf_summary(result: VectorFieldResult) -> dict[str, Any]:
    V = result.learner
    return {
        "fields": [field_summary(f) for f in V.fields_],
        "ransac_fields": [field_summary(f) | {"inliers": int(m.sum())}
                          for f, m in zip(V.ransac_fields_, V.ransac_inliers_, strict=True)],
        "field_labels": result.field_labels,
        "candidate_frames": V.candidate_frames_,
    }


def summary_dict(result: LinearResult | VectorFieldResult, skill: Skill,
                 demos_dir: str = "", settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """``summary.json``: hyperparameters (the run's, over the command line's
    ``settings`` when given), per-demo labels, fields, timings."""
    linear = isinstance(result, LinearResult)
    out: dict[str, Any] = {
        "method": "linear" if linear else "vf",
        "demos_dir": demos_dir,
        "skill": skill_summary(skill),
        "hyperparameters": {**(settings or {}), **result.hyperparameters()},
        "labels": result.labels,
        "timings": {k: round(v, 4) for k, v in result.timings.items()},
        "samples": {p.name: {"raw": p.n_raw, "kept": len(p.keep)} for p in result.prepared},
    }
    if isinstance(result, LinearResult):
        return out | _linear_summary(result)
    return out | _vf_summary(result)


def plain(o: Any) -> Any:
    """numpy arrays and scalars as plain Python (``json.dumps(default=plain)``)."""
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.integer | np.floating | np.bool_):
        return o.item()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")
