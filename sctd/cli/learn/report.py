"""Writing what ``sctd learn`` learned: the skill files, ``summary.json``, figures.

Every written skill is loaded back with :func:`sctd.skill.load_skill` before
:func:`write_skill` returns, so a learned skill that the runtime would reject is an
error here, not at run time.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from typing import Any

from ...learn import Demo, LinearResult, VectorFieldResult, skill_bundle
from ...learn.summary import plain, summary_dict
from ...skill import Skill, load_skill


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


VIEW_FILE = "skill.html"


def _write_view(skill: Skill, demos: list[Demo] | None, path: Path) -> str | None:
    """The skill's page (``sctd_services.view.page``) at ``path``: its name, or None
    (said on stderr) when Viser is not installed."""
    try:
        from sctd_services.view.page import skill_page
        from sctd_sim.view import ViewerUnavailable
    except ImportError as e:  # sctd without its services: the report has no view
        print(f"sctd learn: the report has no 3D view: {e}", file=sys.stderr)
        return None
    try:
        page = skill_page(skill, demos)
    except ViewerUnavailable as e:
        print(f"sctd learn: the report has no 3D view ({path.name}): {e}", file=sys.stderr)
        return None
    _replace(path, page.encode())
    return path.name


def write_report(result: LinearResult | VectorFieldResult, skill: Skill,
                 report_dir: str | Path | None, demos_dir: str = "",
                 settings: dict[str, Any] | None = None, demos: list[Demo] | None = None) -> dict[str, Any]:
    """Write ``summary.json``, the PNG figures and the skill's 3D view (``skill.html``,
    with ``demos``; when Viser is installed) into ``report_dir`` (if given); return the
    summary."""
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
    summary["view"] = _write_view(skill, demos, d / VIEW_FILE)
    (d / "summary.json").write_text(json.dumps(summary, indent=1, default=plain) + "\n")
    return summary
