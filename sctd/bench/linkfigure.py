"""The figure of ``sctd bench link`` (``--figure FILE``): the sweep at a glance.

One column of panels per task, three panels a column: the success rate, the median
completion time of the successful trials and the hand's worst unintended motion, each per point of
the sweep (in its order, the mildest fault of each kind first), the assisted condition
beside the baseline. A grey line parts the kinds of fault; a point where assistance stops
helping (:func:`~sctd.bench.link.stops_helping`) is marked under its label.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from matplotlib.figure import Figure

FORMATS = (".png", ".svg", ".pdf")  # what --figure may write (matplotlib's own writers)
_COLOURS = {"assisted": "tab:blue"}  # any other condition (the baseline): grey
_PANELS = (("success", "success [%]", 100.0), ("time_s", "median time of the successes [s]", 1.0),
           ("wander_mm", "worst unintended motion [mm]", 1.0))


def figure(rows: list[dict[str, Any]], points: list[str], kinds: dict[str, str],
           stops: dict[str, dict[str, str | None]]) -> Figure:
    """The sweep's rows (:func:`~sctd.bench.link.summarise`) as panels: ``points`` the
    sweep's point names in order, ``kinds`` each point's kind of fault, ``stops`` where
    assistance stops helping per task and kind."""
    tasks = list(dict.fromkeys(r["task"] for r in rows))
    conditions = list(dict.fromkeys(r["condition"] for r in rows))
    shown = [p for p in points if any(r["point"] == p for r in rows)]
    fig = Figure(figsize=(max(6.0, 0.6 * len(shown)) * len(tasks) + 1.0, 10.0))
    axes = fig.subplots(len(_PANELS), len(tasks), squeeze=False).T  # a column per task
    by = {(r["task"], r["point"], r["condition"]): r for r in rows}
    x = np.arange(len(shown))
    width = 0.8 / max(1, len(conditions))
    for row, task in zip(axes, tasks, strict=True):
        stopped = {p for p in (stops.get(task) or {}).values() if p}
        for ax, (key, title, scale) in zip(row, _PANELS, strict=True):
            for i, cond in enumerate(conditions):
                ys = [_value(by.get((task, p, cond)), key, scale) for p in shown]
                ax.bar(x + (i - (len(conditions) - 1) / 2) * width, ys, width,
                       color=_COLOURS.get(cond, "0.6"), label=cond)
            for k in range(1, len(shown)):
                if kinds[shown[k]] != kinds[shown[k - 1]]:
                    ax.axvline(k - 0.5, color="0.8", lw=0.8)
            if key == "success":
                ax.axhline(90.0, color="k", lw=0.6, ls="--")
                ax.set_ylim(0, 105)
            ax.set_title(f"{task}: {title}", fontsize=9)
            ax.set_xticks(x, [p + (" *" if p in stopped else "") for p in shown], rotation=60, ha="right",
                          fontsize=7)
        row[0].legend(loc="lower left", fontsize=7)
    fig.suptitle("sctd bench link: real-time trials through faulted links\n(* assistance stops helping; "
                 "dashed: 90 %)", fontsize=10)
    fig.tight_layout()
    return fig


def _value(r: dict[str, Any] | None, key: str, scale: float) -> float:
    """A row's figure for a panel (NaN, no bar, when the row or its figure is missing:
    a point with no success has no time)."""
    if r is None or r.get(key) is None:
        return math.nan
    return float(r[key]) * scale
