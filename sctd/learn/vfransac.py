"""Sequential RANSAC of vector fields (Algorithm 5, Appendix A.1).

For each field shape a minimal-sample estimate -- translation from 1 (point, vector),
cylinder from 2 (the planes through each point normal to its vector meet in the axis),
sphere from 3 (the planes meet in the centre) -- scored by MSAC over the angle inliers
(thresholds: thesis 15 deg sphere, 25 deg translation, 20 deg cylinder), iterations from
eq. 4.23. Every winner is refined by least squares on its inliers and its inliers
recounted (the thesis saw centres "jump", Ch. 6.1). Of the shapes' winners, one is kept
(by the choice given: the score, or the likelihood of :mod:`.vfselect`), its inliers
removed, and the next round runs on the points left.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..skill.fields import Field
from .vffields import estimate

Array = NDArray[np.float64]
Mask = NDArray[np.bool_]
Candidate = tuple[Field, Mask, float]  # a shape's winner: field, inliers, score

SAMPLE_SIZE = {"translation": 1, "cylinder": 2, "sphere": 3, "point": 2}


def ransac_iterations(p_success: float, outlier_ratio: float, sample_size: int) -> int:
    """Iterations N = log(1 - p) / log(1 - (1 - e)^S) (eq. 4.23)."""
    good = (1.0 - outlier_ratio) ** sample_size
    if good >= 1.0:
        return 1
    if good <= 0.0:
        raise ValueError("outlier_ratio must be < 1")
    return max(1, math.ceil(math.log(1.0 - p_success) / math.log(1.0 - good)))


def chance(kind: str, threshold: float) -> float:
    """Expected MSAC score of one uniformly random direction for a field type with
    inlier ``threshold`` (rad).

    A random direction lies within ``thr`` of a sphere's tangent plane with probability
    sin(thr) (mean inlier score 2/3 for small thr), within ``thr`` of a directed field's
    vector with probability (1 - cos(thr)) / 2 (mean score 1/2).
    """
    if kind == "sphere":
        return math.sin(threshold) * 2.0 / 3.0
    return 0.5 * (1.0 - math.cos(threshold)) * 0.5


@dataclass(frozen=True, eq=False)
class Ransac:
    """RANSAC of one field shape at a time, with the MSAC score.

    Parameters
    ----------
    thresholds : dict of str to float
        Inlier threshold (rad) per field shape.
    p_success, outlier_ratio : float
        p and e of eq. 4.23.
    refine_steps : int
        Least-squares refinements of the winner.
    chance_weight : float
        Weight of the chance-inlier correction of the score.
    angles : callable
        ``angles(field, p, v)``: the deviation angles (n,) of directions ``v`` at ``p``.
    """

    thresholds: dict[str, float]
    p_success: float
    outlier_ratio: float
    refine_steps: int
    chance_weight: float
    angles: Callable[[Field, Array, Array], Array]

    def score(self, f: Field, p: Array, v: Array) -> tuple[float, Mask]:
        """MSAC score: sum over inliers of ``1 - (angle / threshold)^2``, minus what as
        many uniformly random directions would score (a sphere accepts a whole plane of
        directions, so it would otherwise win on chance inliers alone); and the inliers."""
        thr = self.thresholds[f.type]
        th = self.angles(f, p, v)
        inl = th < thr
        raw = float(np.sum(1.0 - (th[inl] / thr) ** 2))
        return raw - self.chance_weight * chance(f.type, thr) * len(p), inl

    def fit(self, kind: str, p: Array, v: Array, rng: np.random.Generator
            ) -> tuple[Field | None, Mask, float]:
        """The best field of shape ``kind`` through directions ``v`` at ``p`` (each (n, 3)):
        the field (None: no sample gave one), its inliers (n,) and its score."""
        S = SAMPLE_SIZE[kind]
        n = len(p)
        if n < max(S, 2):
            return None, np.zeros(n, dtype=bool), -np.inf
        iters = ransac_iterations(self.p_success, self.outlier_ratio, S)
        best, best_in, best_score = None, np.zeros(n, dtype=bool), -np.inf
        for _ in range(iters):
            idx = rng.choice(n, size=S, replace=False)
            f = estimate(kind, p[idx], v[idx])
            if f is None:
                continue
            score, inl = self.score(f, p, v)
            if score > best_score:
                best, best_in, best_score = f, inl, score
        # Least-squares refinement on the inliers, then rescore (stable parameters).
        for _ in range(self.refine_steps):
            if best is None or best_in.sum() < S + 1:
                break
            f = estimate(kind, p[best_in], v[best_in])
            if f is None:
                break
            score, inl = self.score(f, p, v)
            if score < best_score:
                break
            best, best_in, best_score = f, inl, score
        return best, best_in, best_score


def best_score(candidates: list[Candidate], idx: NDArray[np.int64]) -> int:
    """The thesis' choice among a round's candidates: the largest MSAC score."""
    return max(range(len(candidates)), key=lambda i: candidates[i][2])


def sequential_ransac(p: Array, v: Array, rng: np.random.Generator, ransac: Ransac,
                      kinds: Iterable[str], n_fields: int, min_inliers: int,
                      choose: Callable[[list[Candidate], NDArray[np.int64]], int] = best_score
                      ) -> tuple[list[Field], list[Mask]]:
    """Algorithm 5: ``n_fields`` rounds of the best field of any of the shapes ``kinds``
    (the general field is not one) on the points left, its inliers removed; it stops
    early when no shape fits or the chosen one has fewer than ``min_inliers``.

    ``choose(candidates, idx)`` picks a round's field: ``candidates`` (field, inliers
    among the points left, score) one per shape, ``idx`` the points left (indices into
    ``p``). Returns the fields and their inliers (masks over all of ``p``).
    """
    n = len(p)
    remaining = np.ones(n, dtype=bool)
    fields: list[Field] = []
    masks: list[Mask] = []
    for _ in range(n_fields):
        idx = np.flatnonzero(remaining)
        scored: list[Candidate] = []
        for kind in kinds:
            if kind == "general":
                continue
            f, inl, score = ransac.fit(kind, p[idx], v[idx], rng)
            if f is not None:
                scored.append((f, inl, score))
        if not scored:
            break
        best = scored[choose(scored, idx)]
        if best[1].sum() < min_inliers:
            break
        mask = np.zeros(n, dtype=bool)
        mask[idx[best[1]]] = True
        fields.append(best[0])
        masks.append(mask)
        remaining &= ~mask
    return fields, masks
