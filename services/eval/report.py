"""``sctd eval --report DIR``: figures like the thesis' Figs. 5.2 and 5.5, and the JSON.

Per skill: the hand's trajectories relative to the task object projected on a vertical
plane (the object frame's x-z plane), one line per trial; for vector-field skills, the
influence of each field (its membership) and the scaling factor over time, as mean and
spread over the trials (recorded in lockstep, where the engine's internals are at hand).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # matplotlib is imported when a report is drawn, not with sctd eval
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("_") or "skill"


def write_report(results: list[dict[str, Any]], directory: Path, header: dict[str, Any]) -> list[Path]:
    """Write ``evaluation.json`` and one PNG per skill; returns the files written.

    Figures are drawn on :class:`matplotlib.figure.Figure` directly (no pyplot, so no
    backend is chosen or switched for the whole process)."""
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for r in results:
        out = directory / f"{_safe(r['skill'])}.png"
        _figure(r).savefig(out, dpi=100)
        written.append(out)
    js = directory / "evaluation.json"
    js.write_text(json.dumps({**header, "results": results}))
    written.append(js)
    return written


def _figure(r: dict[str, Any]) -> Figure:
    """One skill's figure: trajectories, and for vector fields influence and scaling."""
    trials = r["per_trial"]
    vf = any(any(not np.isnan(x) for x in t.get("series", {}).get("vf_scale", []) if x is not None)
             for t in trials)
    n = 3 if vf else 1
    from matplotlib.figure import Figure

    fig = Figure(figsize=(5 * n, 4))
    axes = fig.subplots(1, n, squeeze=False)[0]
    _trajectories(axes[0], r)
    if vf:
        grid = np.linspace(0.0, max(t["duration_s"] for t in trials) or 1.0, 200)
        members, scales = _vf_series(trials, grid)
        _influence(axes[1], grid, members)
        _scaling(axes[2], grid, scales)
    fig.tight_layout()
    return fig


def _trajectories(ax: Axes, r: dict[str, Any]) -> None:
    """The hand's trajectories in the object frame's x-z plane (Fig. 5.2)."""
    for t in r["per_trial"]:
        traj = np.asarray(t.get("trajectory") or [])
        if len(traj):
            ax.plot(traj[:, 1], traj[:, 3], "-" if t["outcome"] == "success" else ":", lw=1)
    ax.plot([0], [0], "k+", ms=12)
    ax.set_xlabel("x in the object frame [m]")
    ax.set_ylabel("z in the object frame [m]")
    ax.set_title(f"{r['name']}: {r['successes']}/{r['trials']} (dotted: not a success)")
    ax.set_aspect("equal", adjustable="datalim")


def _vf_series(trials: list[dict[str, Any]], grid: np.ndarray) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Per trial, the fields' membership (len(grid), n fields) and the scaling factor
    (len(grid),), resampled on ``grid``."""
    members, scales = [], []
    for t in trials:
        s = t.get("series", {})
        tt = np.asarray(s.get("t", []), dtype=float)
        raw = s.get("membership", [])
        have = [i for i, x in enumerate(raw) if x]  # before the first command: none
        if len(tt) == len(raw) and have:
            M = np.asarray([raw[i] for i in have], dtype=float)
            tm = tt[have]
            members.append(np.stack([np.interp(grid, tm, M[:, k]) for k in range(M.shape[1])], 1))
        sc = np.asarray(s.get("vf_scale", []), dtype=float)
        if len(tt) and len(sc) == len(tt):
            scales.append(np.interp(grid, tt, np.nan_to_num(sc, nan=0.0)))
    return members, scales


def _influence(ax: Axes, grid: np.ndarray, members: list[np.ndarray]) -> None:
    if members:
        A = np.stack(members)
        for k in range(A.shape[2]):
            mu, sd = A[:, :, k].mean(0), A[:, :, k].std(0)
            ax.plot(grid, mu, label=f"field {k}")
            ax.fill_between(grid, mu - sd, mu + sd, alpha=0.2)
        ax.legend()
    ax.set_xlabel("time [s]")
    ax.set_title("field influence (membership the engine used)")


def _scaling(ax: Axes, grid: np.ndarray, scales: list[np.ndarray]) -> None:
    if scales:
        S = np.stack(scales)
        ax.plot(grid, S.mean(0))
        ax.fill_between(grid, S.mean(0) - S.std(0), S.mean(0) + S.std(0), alpha=0.2)
    ax.set_xlabel("time [s]")
    ax.set_title("scaling of the command (eq. 4.33)")
