"""Nearest demonstration points of a vector-field model, for the tick (Ch. 4.2.5)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from .model import VectorFieldModel

Array = NDArray[np.float64]

POSE_CANDIDATES = 8  # points within max_d a pose query ranks, per neighbour it keeps

# A neighbour query is reused while the frame stays this close to where it was made: well
# below the spacing of the demonstrations' points (sampled at 50 Hz, 1-2 mm apart at the
# demonstrated speeds), so the field does not change for it, and at the speed limits a
# KD-tree query then runs every few ticks rather than every tick.
REUSE_DISTANCE = 5e-4  # m
REUSE_ANGLE = 5e-3  # rad (pose queries)


class Neighbours:
    """KD-tree over a vector-field model's demonstration points (Ch. 4.2.5), with the
    last answer to each kind of query kept for reuse (see ``REUSE_DISTANCE``).

    Per-engine data: one per model file of a skill, shared by the elements that read it.

    Parameters
    ----------
    model : VectorFieldModel
    """

    def __init__(self, model: VectorFieldModel):
        self.model = model
        self.tree = cKDTree(model.points)
        w = np.array([f.weight for f in model.fields], dtype=float)
        self.prior = w / w.sum() if w.sum() > 0 else np.full(len(w), 1.0 / len(w))
        self._last: dict[tuple, tuple] = {}
        self.queries = 0  # KD-tree queries made (the rest were reused)
        self._mean_of: tuple[Array, Array] | None = None  # the answer _mean is of
        self._mean: tuple[float, float, float, float] | None = None

    def _reuse(self, key: tuple, p: Sequence[float], q: Sequence[float] | None = None):
        """The kept answer for ``key`` if it was made within the reuse distance (and
        angle) of position ``p`` (and quaternion ``q``), else None."""
        last = self._last.get(key)
        if last is None:
            return None
        (x, y, z), q_last, answer = last
        px, py, pz = p
        if (px - x) ** 2 + (py - y) ** 2 + (pz - z) ** 2 > REUSE_DISTANCE ** 2:
            return None
        if q is not None:
            c = abs(q[0] * q_last[0] + q[1] * q_last[1] + q[2] * q_last[2] + q[3] * q_last[3])
            if 2.0 * math.acos(min(1.0, c)) > REUSE_ANGLE:
                return None
        return answer

    def _keep(self, key: tuple, p: Sequence[float], q: Sequence[float] | None, answer):
        self._last[key] = (tuple(p), q, answer)
        self.queries += 1
        return answer

    def query(self, p: Sequence[float], max_n: int, max_d: float) -> tuple[Array, Array]:
        """Indices and distance weights of up to ``max_n`` points within ``max_d`` of the
        position ``p`` (3 floats, or shape (3,))."""
        key = ("query", max_n, max_d)
        answer = self._reuse(key, p)
        return answer if answer is not None else self._keep(key, p, None, self._query(p, max_n, max_d))

    def _query(self, p: Sequence[float], max_n: int, max_d: float) -> tuple[Array, Array]:
        d, i = self.tree.query(p, k=max_n, distance_upper_bound=max_d)
        d = np.atleast_1d(d)
        i = np.atleast_1d(i)
        ok = np.isfinite(d)
        d, i = d[ok], i[ok]
        w = 1.0 / (d + 1e-3)
        return i, w / w.sum() if len(w) else w

    def query_pose(self, p: Sequence[float], q: Sequence[float], max_n: int, max_d: float,
                   rotation_weight: float) -> tuple[Array, Array]:
        """Like :meth:`query`, but the ``max_n`` nearest in pose: of the points within
        ``max_d`` (at most ``POSE_CANDIDATES * max_n`` of them), those with the smallest
        ``sqrt(|dp|^2 + (rotation_weight * angle)^2)`` to position ``p`` and unit
        quaternion ``q`` [x, y, z, w]."""
        key = ("pose", max_n, max_d, rotation_weight)
        answer = self._reuse(key, p, q)
        if answer is None:
            answer = self._keep(key, p, tuple(q), self._query_pose(p, q, max_n, max_d, rotation_weight))
        return answer

    def _query_pose(self, p: Sequence[float], q: Sequence[float], max_n: int, max_d: float,
                    rotation_weight: float) -> tuple[Array, Array]:
        d, i = self.tree.query(p, k=POSE_CANDIDATES * max_n, distance_upper_bound=max_d)
        d, i = np.atleast_1d(d), np.atleast_1d(i)
        ok = np.isfinite(d)
        d, i = d[ok], i[ok]
        if len(i) == 0:
            return i, d
        c = np.abs(self.model.quaternions[i] @ np.asarray(q, dtype=float))
        angle = 2.0 * np.arccos(np.clip(c, 0.0, 1.0))
        dist = np.sqrt(d * d + (rotation_weight * angle) ** 2)
        best = np.argsort(dist, kind="stable")[:max_n]
        w = 1.0 / (dist[best] + 1e-3)
        return i[best], w / w.sum()

    def mean_orientation(self, answer: tuple[Array, Array]) -> tuple[float, float, float, float] | None:
        """The weighted mean quaternion (x, y, z, w; not normalised) of the points an
        answer of :meth:`query` or :meth:`query_pose` names (indices, weights), each
        taken in the first one's hemisphere; None for no points. Worked out once per
        answer: a reused answer has the same mean."""
        if answer is self._mean_of:
            return self._mean
        i, w = answer
        mean = None
        if len(i):
            q = self.model.quaternions[i]
            q = q * np.where(q @ q[0] < 0.0, -1.0, 1.0)[:, None]  # one hemisphere
            gx, gy, gz, gw = (w @ q).tolist()
            mean = (gx, gy, gz, gw)
        self._mean_of, self._mean = answer, mean
        return mean

    def membership(self, p: Sequence[float], max_n: int, max_d: float) -> Array:
        """P(F | p): neighbours' EM responsibilities, distance-weighted (the prior when
        no demonstration point is near)."""
        key = ("membership", max_n, max_d)
        answer = self._reuse(key, p)
        return answer if answer is not None else self._keep(key, p, None, self._membership(p, max_n, max_d))

    def _membership(self, p: Sequence[float], max_n: int, max_d: float) -> Array:
        i, w = self._query(p, max_n, max_d)
        if len(i) == 0:
            return self.prior
        r = w @ self.model.responsibilities[i]
        s = r.sum()
        return r / s if s > 1e-12 else self.prior
