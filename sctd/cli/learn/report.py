"""Writing what ``sctd learn`` learned: the skill files, ``summary.json``, figures.

Every written skill is loaded back with :func:`sctd.skill.load_skill` before
:func:`write_skill` returns, so a learned skill that the runtime would reject is an
error here, not at run time.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from ...learn import LinearResult, VectorFieldResult, skill_bundle
from ...learn.bundle import rounded, state_name
from ...learn.linear import AXIS_NAMES
from ...skill import Skill, load_skill
from ...skill.summary import field_summary, skill_summary


def _replace(path: Path, data: bytes) -> None:
    """Write ``path`` atomically (a temporary file next to it, then a rename)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


def write_skill(result: LinearResult | VectorFieldResult, out: str | Path) -> Skill:
    """Write the skill YAML ``out`` (named after its stem) and its model files next to
    it, model files first; validate it by loading it back."""
    out = Path(out)
    bundle = skill_bundle(result, out.stem)
    out.parent.mkdir(parents=True, exist_ok=True)
    for rel, data in bundle.files.items():
        _replace(out.with_name(rel), data)
    _replace(out, bundle.yaml_text.encode())
    return load_skill(out)


def _linear_summary(result: LinearResult) -> dict[str, Any]:
    L = result.learner
    return {
        "frames": {k: rounded(v) for k, v in result.frames.items()},
        "states": [{"name": state_name(k), "frame": st.label.frame,
                    "axes": [AXIS_NAMES[a] for a in st.label.axes], "support": st.support}
                   for k, st in enumerate(L.states_)],
        "transitions": [{"from": state_name(h.source), "to": state_name(h.target),
                         "frame": h.frame, "accuracy": round(h.accuracy, 4),
                         "reachable": h.reachable, "candidates": h.candidates}
                        for h in L.transitions_],
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


def write_report(result: LinearResult | VectorFieldResult, skill: Skill,
                 report_dir: str | Path | None, demos_dir: str = "",
                 settings: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write ``summary.json`` and the PNG figures into ``report_dir`` (if given); return
    the summary."""
    summary = summary_dict(result, skill, demos_dir, settings)
    if report_dir is None:
        return summary
    d = Path(report_dir)
    d.mkdir(parents=True, exist_ok=True)
    # matplotlib is imported when a report is asked for, not with the sctd command:
    # every other subcommand (sctd run among them) starts without its import time.
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
