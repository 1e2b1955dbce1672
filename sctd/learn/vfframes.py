"""Candidate feature frames from vector fields (Ch. 4.2.7): sphere centres and cylinder
axis points, with the centre's mean offset in the ee frame over the points the field
explains (for the pour: the bottle tip)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from .. import se3
from ..skill.fields import CylinderField, Field, SphereField

Array = NDArray[np.float64]


def candidate_frames(fields: list[Field], assignment: NDArray[np.int64], points: Array,
                     quaternions: Array, pivot_spread: float) -> tuple[list[dict], list[Field]]:
    """One candidate frame per sphere or cylinder of ``fields``, named by kind and
    number (``sphere0``, ``cylinder0``, ...): its position (and axis), and where the
    points it explains (``assignment``, (n,)) have the ee (``points`` (n, 3),
    ``quaternions`` (n, 4)), its mean offset in the ee frame and that offset's RMS
    spread. Returns the frames and the fields, a field whose offset spreads less than
    ``pivot_spread`` (m) given that point of the hand as its ``pivot`` (the
    demonstrations turned about it: a bottle's opening)."""
    out = []
    fields = list(fields)
    counts = {"sphere": 0, "cylinder": 0}
    for m, f in enumerate(fields):
        if isinstance(f, SphereField):
            pos = f.centre
        elif isinstance(f, CylinderField):
            pos = f.point
        else:
            continue
        name = f"{f.type}{counts[f.type]}"
        counts[f.type] += 1
        sel = assignment == m
        entry: dict = {"name": name, "position": [round(float(x), 6) for x in pos], "kind": f.type}
        if isinstance(f, CylinderField):
            entry["axis"] = [round(float(x), 6) for x in f.axis]
        if sel.any():
            R = se3.matrix_from_quaternion(quaternions[sel])
            off = np.einsum("nji,nj->ni", R, pos - points[sel])
            mean = off.mean(axis=0)
            spread = float(np.sqrt(np.mean(np.sum((off - mean) ** 2, axis=1))))
            entry["ee_offset"] = [round(float(x), 6) for x in mean]
            entry["ee_offset_spread"] = round(spread, 6)
            if spread < pivot_spread:  # the demonstrations turned about a point of the hand
                fields[m] = replace(f, pivot=mean)
        out.append(entry)
    return out, fields
