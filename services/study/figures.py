"""The report's figures: one PNG per metric, a panel per task, a box per condition over
the participants' values with each participant's value drawn on it (matplotlib; drawn
on :class:`~matplotlib.figure.Figure` directly, so no pyplot backend is chosen)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from .report import METRICS, Metric


def metric_figure(r: dict[str, Any], metric: Metric) -> Figure:
    """Box plots of ``metric`` per condition, one panel per task of the report ``r``."""
    tasks, conds = r["tasks"], r["conditions"]
    fig = Figure(figsize=(1.2 + 1.3 * len(conds) * len(tasks), 3.6), layout="constrained")
    axes = fig.subplots(1, len(tasks), squeeze=False)[0]
    for ax, task in zip(axes, tasks, strict=True):
        values = r["per_participant"][task]
        data = [[v for v in values[c][metric.key].values() if v is not None] for c in conds]
        filled = [i for i, d in enumerate(data) if d]
        if filled:
            ax.boxplot([data[i] for i in filled], positions=[i + 1 for i in filled], widths=0.5)
        for i, d in enumerate(data):
            offsets = np.linspace(-0.12, 0.12, len(d)) if len(d) > 1 else np.zeros(len(d))
            ax.plot(i + 1 + offsets, d, "o", color="tab:blue", alpha=0.6, markersize=4)
        ax.set_xticks(range(1, len(conds) + 1), conds, rotation=20, ha="right")
        ax.set_xlim(0.4, len(conds) + 0.6)
        ax.set_title(f"{task}", fontsize=10)
        ax.set_ylabel(f"{metric.label} ({metric.better} is better)", fontsize=9)
        ax.grid(axis="y", alpha=0.3)
    fig.suptitle(f"{metric.label}: per participant, {len(r['participants'])} participants", fontsize=10)
    return fig


def write_figures(r: dict[str, Any], directory: Path) -> list[Path]:
    """``<metric>.png`` for every metric in ``directory``; returns the files written."""
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for m in METRICS:
        out = directory / f"{m.key}.png"
        metric_figure(r, m).savefig(out, dpi=100)
        written.append(out)
    return written
