"""The spatio-temporal coherence filter of EM (Ch. 4.2): a point counts for a field only
within a run of consecutive points of its demonstration that the field explains, and
with another such point near it."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

Array = NDArray[np.float64]
Mask = NDArray[np.bool_]


def coherent(assigned: Mask, demo: NDArray[np.int64], sample: NDArray[np.int64], points: Array,
             run: int, radius: float) -> Mask:
    """The points of ``assigned`` (n,) in runs of at least ``run`` consecutive samples
    (``sample``, (n,)) of one demonstration (``demo``, (n,)), with another such point
    within ``radius`` (m) of them (``points``, (n, 3))."""
    keep = assigned.copy()
    if run > 1:
        # Run lengths of consecutive assigned points within each demonstration.
        brk = np.ones(len(keep), dtype=bool)
        brk[1:] = (demo[1:] != demo[:-1]) | (sample[1:] != sample[:-1] + 1)
        run_id = np.cumsum(brk | np.r_[True, keep[1:] != keep[:-1]])
        lengths = np.bincount(run_id)
        keep &= lengths[run_id] >= run
    idx = np.flatnonzero(keep)
    if len(idx) > 1:
        d, _ = cKDTree(points[idx]).query(points[idx], k=2)
        keep[idx[d[:, 1] > radius]] = False
    return keep
