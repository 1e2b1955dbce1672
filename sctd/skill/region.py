"""Where a skill knows what to do: the region of its demonstrations.

A learned skill is taught from demonstrations that start where the task put the hand
and go where the person went. Far from them a learned mapping extrapolates, and may
hold the hand still (stuck) or move it the wrong way. A skill file's ``region`` says
where its demonstrations went: an axis-aligned box in the skill's object frame around
every position the hand's origin took in them, widened by a margin, in the frame of the
body the demonstrations were learned in (``frame``: the skill's object, or the body a
pick-and-place skill's states move relative to). The daemon tells
the person on ``status.region`` when the hand is outside it, and by how much, from the
first tick on (docs/wire-contract.md): an explicit "out of my region" rather than a
skill that is stuck. It never changes a command.

Pure: numbers in, numbers out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

MARGIN = 0.05  # m the learner widens the demonstrations' box by on every side


@dataclass(frozen=True)
class Region:
    """A box ``centre`` +- ``half_extents`` (m, each > 0) in the frame of the body
    ``frame``, and how many demonstrations it was drawn around."""

    frame: str
    centre: tuple[float, float, float]
    half_extents: tuple[float, float, float]
    demonstrations: int = 0

    @classmethod
    def around(cls, frame: str, points: ArrayLike, margin: float = MARGIN, demonstrations: int = 0) -> Region:
        """The box around ``points`` (n, 3), widened by ``margin`` m on every side."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        if len(p) == 0 or not np.all(np.isfinite(p)):
            raise ValueError("points: at least one, every coordinate finite")
        lo, hi = p.min(axis=0) - margin, p.max(axis=0) + margin
        centre = tuple(round(float(x), 4) for x in 0.5 * (lo + hi))
        half = tuple(round(max(float(x), 1e-3), 4) for x in 0.5 * (hi - lo))
        return cls(frame, centre, half, demonstrations)  # type: ignore[arg-type]

    def outside_by(self, p: Sequence[float]) -> float:
        """How far (m) the point ``p`` (object frame) is from the box; 0 inside it."""
        d2 = 0.0
        for x, c, h in zip(p, self.centre, self.half_extents, strict=True):
            e = abs(x - c) - h
            if e > 0.0:
                d2 += e * e
        return math.sqrt(d2)

    def to_yaml(self) -> dict[str, Any]:
        out: dict[str, Any] = {"frame": self.frame, "centre": list(self.centre),
                               "half_extents": list(self.half_extents)}
        if self.demonstrations:
            out["demonstrations"] = self.demonstrations
        return out
