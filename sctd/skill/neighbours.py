"""Nearest demonstration points of a vector-field model, for the tick (Ch. 4.2.5)."""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .modelfile import VectorFieldModel

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

Array = NDArray[np.float64]
Index = NDArray[np.intp]
Answer = tuple[list[int], list[float]]  # a query's answer: point indices, their weights

POSE_CANDIDATES = 8  # points within max_d a pose query ranks, per neighbour it keeps

# A neighbour query is reused while the frame stays this close to where it was made: well
# below the spacing of the demonstrations' points (sampled at 50 Hz, 1-2 mm apart at the
# demonstrated speeds), so the field does not change for it, and at the speed limits a
# query is then answered every few ticks rather than every tick.
REFRESH_LEAD = 0.5  # refresh: an answer is worked out ahead once a query is this share of the
# reuse distance (or angle) from where it was made: at the speed limits (0.1 mm, 0.5 mrad per
# 1 ms tick) the next question is then well within reuse of the new answer
REUSE_DISTANCE = 5e-4  # m
REUSE_ANGLE = 5e-3  # rad (pose queries)

# The points a KD-tree query fetches around the frame (at least; 4 per neighbour asked
# for). A query is answered exactly from the fetched points while they provably hold its
# answer, which at this many lasts millimetres to centimetres of motion: in the tick
# benchmark's 4,000 ticks the tree (whose single-point query costs tens of microseconds
# in Python) is asked 2 times with 1,000 points, 4 with 5,000 and about 30 with 20,000,
# and answering from the fetched points costs the same whatever the model's size.
FETCH_POINTS = 128
FETCHED_SETS = 4  # fetched sets kept (one per place the skill's frames query)
MEANS_KEPT = 4  # answers whose mean orientation is kept (mean_orientation)


class _Fetched:
    """The ``size`` points of the model nearest to ``centre`` (their rows of the model,
    in index order), and ``reach``: no other point is nearer to the centre than it
    (infinite when these are all the model's points). What a query reads of them is
    kept as Python lists: it reads a handful of them, where numpy's per-call cost would
    dominate."""

    __slots__ = ("centre", "index", "quaternions", "reach", "responsibilities", "rows")

    def __init__(self, model: VectorFieldModel, tree: cKDTree, centre: Sequence[float], size: int):
        n = len(model.points)
        self.centre = (float(centre[0]), float(centre[1]), float(centre[2]))
        if size >= n:
            index: Index = np.arange(n)
            self.reach = math.inf
        else:  # the size + 1 nearest: the last one's distance bounds every point left out
            d, i = tree.query(self.centre, k=size + 1)
            index = np.sort(i[:size])
            self.reach = float(d[size])
        self.index: list[int] = index.tolist()
        # |x - p|^2 - |p - c|^2 = |x - c|^2 - 2 (x - c).(p - c): one product per query
        # of the rows [x - c, |x - c|^2] (offsets from the centre, centimetres: no
        # cancellation to speak of) with (-2 (p - c), 1)
        offsets = model.points[index] - self.centre
        self.rows = np.column_stack([offsets, np.einsum("ij,ij->i", offsets, offsets)])
        self.quaternions: list[list[float]] = model.quaternions[index].tolist()
        self.responsibilities: list[list[float]] = model.responsibilities[index].tolist()

    def nearest(self, p: Sequence[float], k: int, max_d: float) -> tuple[list[int], list[float]] | None:
        """Rows (into this set, nearest first, ties in index order) and squared distances
        of the up to ``k`` model points within ``max_d`` (strictly) of ``p``; None when
        this set cannot prove them to be the model's.

        Every point left out is at least ``reach`` from the centre, so at least ``reach -
        |p - centre|`` from ``p`` (triangle inequality): the answer is the model's when
        its farthest distance, or ``max_d`` when it has fewer than ``k``, is smaller."""
        c = self.centre
        vx, vy, vz = p[0] - c[0], p[1] - c[1], p[2] - c[2]
        vv = vx * vx + vy * vy + vz * vz
        left_out = self.reach - math.sqrt(vv)  # no point outside this set is nearer to p
        if left_out <= 0.0:
            return None
        ranking = self.rows @ np.array((-2.0 * vx, -2.0 * vy, -2.0 * vz, 1.0))
        order = np.argsort(ranking, kind="stable")[:k]  # nearest first, ties in index order
        d2: list[float] = (ranking[order] + vv).tolist()
        n = bisect.bisect_left(d2, max_d * max_d)  # those within max_d (sorted)
        rows: list[int] = order[:n].tolist()
        del d2[n:]
        bound = math.sqrt(max(d2[-1], 0.0)) if n == k else max_d
        return (rows, d2) if bound < left_out else None


class Neighbours:
    """KD-tree over a vector-field model's demonstration points (Ch. 4.2.5), with the
    last answer to each kind of query kept for reuse (see ``REUSE_DISTANCE``) and the
    points around the frame fetched from the tree for answering (see
    ``FETCH_POINTS``).

    Per-engine data: one per model file of a skill, shared by the elements that read it.

    Parameters
    ----------
    model : VectorFieldModel

    Attributes
    ----------
    queries : int
        Queries answered (the rest were reused).
    fetches : int
        KD-tree queries made (points fetched around the frame).
    """

    def __init__(self, model: VectorFieldModel):
        from scipy.spatial import cKDTree  # here: 0.6 s to import, and only vector fields need it

        self.model = model
        self.tree = cKDTree(model.points)
        w = np.array([f.weight for f in model.fields], dtype=float)
        self.prior = w / w.sum() if w.sum() > 0 else np.full(len(w), 1.0 / len(w))
        self._last: dict[tuple, tuple] = {}
        self._asked: dict[tuple, tuple] = {}  # per kind of query: where it was last asked
        self._fetched: list[_Fetched] = []  # the most recently used first
        self.refreshes = 0  # answers worked out ahead by refresh
        self.queries = 0
        self.fetches = 0
        # (answer, its mean orientation), the newest first: one per kind of query that
        # asks for a mean (a mapping's and a constraint's alternate every tick)
        self._means: list[tuple[Answer, tuple[float, float, float, float] | None]] = []

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

    def refresh(self, lead: float = REFRESH_LEAD) -> int:
        """Work out ahead, between ticks, the answers the next tick would otherwise work
        out itself: every kind of query whose last question has moved more than
        ``lead`` of the reuse distance (or angle) from where its kept answer was made is
        answered anew where it was last asked. The next question (a tick's motion
        away) then falls within the reuse distance of it. What a query returns is as
        documented (an answer made within the reuse distance and angle of it); only
        when the work is done changes. Returns how many answers were worked out."""
        done = 0
        for key, (p, q) in self._asked.items():
            last = self._last.get(key)
            if last is not None:
                (x, y, z), q_last, _ = last
                near = (p[0] - x) ** 2 + (p[1] - y) ** 2 + (p[2] - z) ** 2 <= (lead * REUSE_DISTANCE) ** 2
                if near and q is not None:
                    c = abs(q[0] * q_last[0] + q[1] * q_last[1] + q[2] * q_last[2] + q[3] * q_last[3])
                    near = 2.0 * math.acos(min(1.0, c)) <= lead * REUSE_ANGLE
                if near:
                    continue
            kind, *args = key
            if kind == "query":
                answer: Any = self._query(p, *args)
            elif kind == "pose":
                answer = self._query_pose(p, q, *args)
            else:
                answer = self._membership(p, *args)
            self._last[key] = (tuple(p), None if q is None else tuple(q), answer)
            done += 1
        self.refreshes += done
        return done

    def _nearest(self, p: Sequence[float], k: int, max_d: float) -> tuple[_Fetched, list[int], list[float]]:
        """The fetched set that answers a query, and its answer (see
        :meth:`_Fetched.nearest`): the nearest kept set when it can, else one fetched
        around ``p`` (which always can: ``p`` is its centre)."""
        sets = self._fetched
        if sets:
            best = min(sets, key=lambda s: (p[0] - s.centre[0]) ** 2 + (p[1] - s.centre[1]) ** 2
                       + (p[2] - s.centre[2]) ** 2)
            answer = best.nearest(p, k, max_d)
            if answer is not None:
                if sets[0] is not best:
                    sets.remove(best)
                    sets.insert(0, best)
                return best, *answer
            sets.remove(best)  # outgrown: replaced by the one fetched here
        s = _Fetched(self.model, self.tree, p, max(FETCH_POINTS, 4 * k))
        self.fetches += 1
        sets.insert(0, s)
        del sets[FETCHED_SETS:]
        answer = s.nearest(p, k, max_d)
        if answer is None:  # only for points tied with the reach: fetch them all
            s = _Fetched(self.model, self.tree, p, len(self.model.points))
            self.fetches += 1
            sets[0] = s
            answer = s.nearest(p, k, max_d)
            assert answer is not None
        return s, *answer

    def query(self, p: Sequence[float], max_n: int, max_d: float) -> Answer:
        """Indices and distance weights of up to ``max_n`` points within ``max_d`` of the
        position ``p`` (3 floats, or shape (3,)), nearest first."""
        key = ("query", max_n, max_d)
        self._asked[key] = (tuple(p), None)
        answer = self._reuse(key, p)
        return answer if answer is not None else self._keep(key, p, None, self._query(p, max_n, max_d))

    def _query(self, p: Sequence[float], max_n: int, max_d: float) -> Answer:
        s, rows, d2 = self._nearest(p, max_n, max_d)
        return [s.index[j] for j in rows], _weights(d2)

    def query_pose(self, p: Sequence[float], q: Sequence[float], max_n: int, max_d: float,
                   rotation_weight: float) -> Answer:
        """Like :meth:`query`, but the ``max_n`` nearest in pose: of the points within
        ``max_d`` (at most ``POSE_CANDIDATES * max_n`` of them, the nearest), those with
        the smallest ``sqrt(|dp|^2 + (rotation_weight * angle)^2)`` to position ``p``
        and unit quaternion ``q`` [x, y, z, w]."""
        key = ("pose", max_n, max_d, rotation_weight)
        self._asked[key] = (tuple(p), tuple(q))
        answer = self._reuse(key, p, q)
        if answer is None:
            answer = self._keep(key, p, tuple(q), self._query_pose(p, q, max_n, max_d, rotation_weight))
        return answer

    def _query_pose(self, p: Sequence[float], q: Sequence[float], max_n: int, max_d: float,
                    rotation_weight: float) -> Answer:
        s, rows, d2 = self._nearest(p, POSE_CANDIDATES * max_n, max_d)
        qx, qy, qz, qw = q
        w2 = (2.0 * rotation_weight) ** 2
        best: list[tuple[float, int, int]] = []  # (distance in pose squared, position, row)
        for pos, (j, r) in enumerate(zip(rows, d2, strict=True)):
            if len(best) == max_n and r >= best[-1][0]:
                break  # no farther point is nearer in pose (that distance is at least r)
            x, y, z, w = s.quaternions[j]
            half = math.acos(min(abs(x * qx + y * qy + z * qz + w * qw), 1.0))  # half the angle
            bisect.insort(best, (r + w2 * (half * half), pos, j))
            del best[max_n:]
        return [s.index[j] for _, _, j in best], _weights([r for r, _, _ in best])

    def mean_orientation(self, answer: Answer) -> tuple[float, float, float, float] | None:
        """The weighted mean quaternion (x, y, z, w; not normalised) of the points an
        answer of :meth:`query` or :meth:`query_pose` names (indices, weights), each
        taken in the first one's hemisphere; None for no points. Worked out once per
        answer (the last :data:`MEANS_KEPT` answers asked about): a reused answer has the
        same mean."""
        for kept, mean in self._means:
            if kept is answer:
                return mean
        i, w = answer
        mean = None
        if i:
            # the answer's few rows only: the whole model as a list would be built with
            # the GIL held (100 ms for 100k points, in the daemon while it swaps)
            rows: list[list[float]] = self.model.quaternions[i].tolist()
            x0, y0, z0, w0 = rows[0]
            gx = gy = gz = gw = 0.0
            for wk, (x, y, z, qw) in zip(w, rows, strict=True):
                if x * x0 + y * y0 + z * z0 + qw * w0 < 0.0:  # into the first one's hemisphere
                    wk = -wk
                gx, gy, gz, gw = gx + wk * x, gy + wk * y, gz + wk * z, gw + wk * qw
            mean = (gx, gy, gz, gw)
        self._means.insert(0, (answer, mean))
        del self._means[MEANS_KEPT:]
        return mean

    def membership(self, p: Sequence[float], max_n: int, max_d: float) -> Array:
        """P(F | p): neighbours' EM responsibilities, distance-weighted (the prior when
        no demonstration point is near)."""
        key = ("membership", max_n, max_d)
        self._asked[key] = (tuple(p), None)
        answer = self._reuse(key, p)
        return answer if answer is not None else self._keep(key, p, None, self._membership(p, max_n, max_d))

    def _membership(self, p: Sequence[float], max_n: int, max_d: float) -> Array:
        s, rows, d2 = self._nearest(p, max_n, max_d)
        if not rows:
            return self.prior
        K = len(self.prior)
        r = [0.0] * K
        for wk, j in zip(_weights(d2), rows, strict=True):
            resp = s.responsibilities[j]
            for f in range(K):
                r[f] += wk * resp[f]
        total = math.fsum(r)
        return np.array([x / total for x in r]) if total > 1e-12 else self.prior


def _weights(d2: list[float]) -> list[float]:
    """The normalised distance weights ``1 / (d + 1 mm)`` of squared distances ``d2``."""
    w = [1.0 / (math.sqrt(max(x, 0.0)) + 1e-3) for x in d2]
    total = sum(w)
    return [x / total for x in w]
