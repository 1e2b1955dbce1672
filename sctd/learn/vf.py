"""Vector fields from demonstrations (Ch. 4.2, Algorithms 4-6, Appendix A.1).

Pipeline (:class:`VectorFieldLearner`):

1. Unit displacement vectors ``v = (p_{t+1} - p_t) / |p_{t+1} - p_t|`` (eq. 4.21) at
   the positions ``p_t`` of the demonstrations.
2. Sequential RANSAC (Algorithm 5): for each field type a minimal-sample estimate --
   translation from 1 (point, vector), cylinder from 2 (the planes through each point
   normal to its vector meet in the axis), sphere from 3 (the planes meet in the
   centre) -- scored by the number of angle inliers (Appendix A.1; thresholds 15 deg
   sphere, 25 deg translation, 20 deg cylinder), iterations from eq. 4.23. The best
   field is kept, its inliers removed, ``n_fields`` times.
3. Stability (the thesis saw centres "jump", Ch. 6.1): every RANSAC winner is refined
   by least squares on its inliers and its inliers recounted (twice). The sphere
   centre minimises ``sum w ((p - c) . v)^2`` -- linear in c; directions the data do
   not constrain (a single rotation axis) keep the minimum-norm solution about the
   inliers' centroid, i.e. the circle's centre.
4. EM (Algorithm 6, eqs. 4.27-4.30): half-normal mixtures over the deviation angles,
   plus a uniform background component for outliers; the spread is the weighted RMS
   angle (eq. 4.30 written as a proper spread); a spatio-temporal coherence filter
   (a point counts for a field only within a run of ``coherence_run`` consecutive
   points of its demonstration and with another such point within
   ``coherence_radius``); weighted least-squares parameter updates; fields with too
   few points or too little weight are pruned.
5. Candidate feature frames (Ch. 4.2.7): sphere centres and cylinder axes, with the
   centre's mean offset in the ee frame (for the pour: the bottle tip).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from .. import se3
from ..skill.fields import CylinderField, Field, SphereField, TranslationField
from .params import hyperparameter

Array = NDArray[np.float64]

FIELD_TYPES = ("translation", "cylinder", "sphere")
SAMPLE_SIZE = {"translation": 1, "cylinder": 2, "sphere": 3}


def unit_vectors(points: ArrayLike, midpoints: bool = True) -> tuple[Array, Array]:
    """Points and unit displacement vectors of one trajectory (eq. 4.21).

    Parameters
    ----------
    points : array-like, shape (n, 3)
    midpoints : bool
        Place each vector at the midpoint of its chord instead of its start (eq. 4.21).
        A chord of a circle is exactly perpendicular to the radius through its
        midpoint, but tilted by half the step angle at its start: at the start, sphere
        and cylinder centres come out biased by ~r tan(step / 2).

    Returns
    -------
    p : ndarray, shape (n - 1, 3)
    v : ndarray, shape (n - 1, 3)
        Unit vectors (zero where two points coincide).
    """
    P = np.asarray(points, dtype=float)
    d = P[1:] - P[:-1]
    n = np.linalg.norm(d, axis=1, keepdims=True)
    p = 0.5 * (P[1:] + P[:-1]) if midpoints else P[:-1]
    return p, np.where(n > 1e-12, d / np.maximum(n, 1e-12), 0.0)


def ransac_iterations(p_success: float, outlier_ratio: float, sample_size: int) -> int:
    """Iterations N = log(1 - p) / log(1 - (1 - e)^S) (eq. 4.23)."""
    good = (1.0 - outlier_ratio) ** sample_size
    if good >= 1.0:
        return 1
    if good <= 0.0:
        raise ValueError("outlier_ratio must be < 1")
    return max(1, math.ceil(math.log(1.0 - p_success) / math.log(1.0 - good)))


# --- estimates ------------------------------------------------------------------------


def _centre_lsq(p: Array, v: Array, w: Array) -> Array:
    """Point c minimising sum w ((p - c) . v)^2, minimum-norm about the weighted
    centroid in the directions the data leave free."""
    w = w / max(float(w.sum()), 1e-12)
    pbar = w @ p
    A = (v * w[:, None]).T @ v
    b = (v * w[:, None]).T @ np.sum(v * (p - pbar), axis=1)
    return pbar + np.linalg.pinv(A, rcond=1e-3) @ b


def translation_field(v: Array, w: Array | None = None) -> Field | None:
    """Translation field along the (weighted) mean unit vector."""
    w = np.ones(len(v)) if w is None else w
    m = w @ v
    n = float(np.linalg.norm(m))
    return None if n < 1e-9 else TranslationField(direction=m / n)


def sphere_field(p: Array, v: Array, w: Array | None = None) -> Field:
    """Sphere field whose centre best makes ``v`` tangent at ``p`` (linear LSQ)."""
    w = np.ones(len(v)) if w is None else w
    c = _centre_lsq(p, v, w)
    r = float(np.average(np.linalg.norm(p - c, axis=1), weights=w + 1e-12))
    return SphereField(centre=c, radius=r)


def cylinder_field(p: Array, v: Array, w: Array | None = None) -> Field | None:
    """Cylinder field: axis the direction most orthogonal to every ``v`` (smallest
    eigenvector of ``sum w v v^T``), point by the sphere LSQ in the plane normal to it,
    sign such that the circulation ``axis x (p - point)`` follows ``v``."""
    w = np.ones(len(v)) if w is None else w
    if len(v) == 2:
        a = np.cross(v[0], v[1])
        if np.linalg.norm(a) < 1e-3:
            return None
        a /= np.linalg.norm(a)
    else:
        A = (v * w[:, None]).T @ v
        a = np.linalg.eigh(A)[1][:, 0]
    c = _centre_lsq(p, v, w)
    c = c - np.dot(c - np.average(p, axis=0, weights=w + 1e-12), a) * a
    circ = np.cross(a, p - c)
    if float(np.sum(w * np.sum(circ * v, axis=1))) < 0:
        a = -a
    return CylinderField(point=c, axis=a)


# The least-squares fit of each field kind (by its registry name) to points and vectors.
ESTIMATORS: dict[str, Callable[[Array, Array, Array | None], Field | None]] = {
    "translation": lambda p, v, w: translation_field(v, w),
    "sphere": sphere_field,
    "cylinder": cylinder_field,
}


def _estimate(kind: str, p: Array, v: Array, w: Array | None = None) -> Field | None:
    return ESTIMATORS[kind](p, v, w)


@dataclass
class VectorFieldLearner:
    """Fit basic vector fields to demonstrations by RANSAC and EM (Algorithm 4).

    Parameters
    ----------
    n_fields : int
        n_R, fields extracted sequentially by RANSAC (thesis 2).
    em_iterations : int
        EM iterations (thesis 5).
    angle_sphere, angle_translation, angle_cylinder : float
        Inlier thresholds in degrees per field type (thesis 15 sphere, 25 translation,
        20 cylinder).
    models : tuple of str
        Field types to try.
    p_success, outlier_ratio : float
        p and e of eq. 4.23.
    min_inliers : int
        Fields with fewer points are pruned.
    min_weight : float
        Fields with a smaller mixing proportion are pruned.
    coherence : bool
        Apply the spatio-temporal coherence filter in EM.
    coherence_run : int
        Minimum run of consecutive points of one demonstration in a field.
    coherence_radius : float
        A field's point needs another of its points within this distance (m).
    min_radius, max_radius : float
        Sphere and cylinder radii (m) allowed for inliers (very large spheres look
        like any motion).
    refine_steps : int
        Least-squares refinements of each RANSAC winner.
    chance_weight : float
        Weight of the chance-inlier correction when comparing field types.
    pivot_spread : float
        A rotational field whose centre (or axis point) stays within this RMS distance
        (m) of one point of the hand over its inliers gets that point as its ``pivot``
        (the demonstrations turned about it: a bottle's opening).
    random_state : int or None
        Seed of RANSAC (flag ``--seed``).

    Attributes
    ----------
    points_, vectors_ : ndarray, (n, 3)
    quaternions_ : ndarray, (n, 4)
    demo_index_ : ndarray, (n,)
    ransac_fields_ : list of Field
    ransac_inliers_ : list of ndarray of bool, (n,)
    fields_ : list of Field
        After EM, with weight (pi), sigma and inliers filled in.
    responsibilities_ : ndarray, (n, K)
        EM membership of each point in each field (rows sum to 1).
    assignment_ : ndarray, (n,)
        Field index of each point, -1 for the background/outliers.
    candidate_frames_ : list of dict
    timings_ : dict
    """

    n_fields: int = hyperparameter(2, "RANSAC fields n_R")
    em_iterations: int = hyperparameter(5, "EM iterations")
    angle_sphere: float = hyperparameter(15.0, "degrees")
    angle_translation: float = hyperparameter(25.0, "degrees")
    angle_cylinder: float = hyperparameter(20.0, "degrees")
    models: tuple[str, ...] = FIELD_TYPES
    p_success: float = 0.99
    outlier_ratio: float = 0.7
    min_inliers: int = 10
    min_weight: float = 0.05
    coherence: bool = True
    coherence_run: int = 3
    coherence_radius: float = 0.05
    min_radius: float = 0.02
    max_radius: float = hyperparameter(0.3, "largest sphere/cylinder radius (m)")
    refine_steps: int = 2
    chance_weight: float = hyperparameter(
        0.5, "weight of the chance-inlier correction when comparing field types")
    pivot_spread: float = 0.02
    random_state: int | None = hyperparameter(
        0, "random seed (default %(default)s)", flag="--seed", metavar="SEED")

    # --- helpers ----------------------------------------------------------------------

    def _threshold(self, kind: str) -> float:
        degrees = {"sphere": self.angle_sphere, "translation": self.angle_translation,
                   "cylinder": self.angle_cylinder}[kind]
        return math.radians(degrees)

    def _angles(self, f: Field, p: Array, v: Array) -> Array:
        """Deviation angles (A.1); pi/2 where a sphere/cylinder radius is out of range."""
        th = f.deviation_angles(p, v)
        if isinstance(f, SphereField):
            r = np.linalg.norm(p - f.centre, axis=1)
        elif isinstance(f, CylinderField):
            r = np.linalg.norm(np.cross(f.axis, p - f.point), axis=1)
        else:
            return th
        bad = (r < self.min_radius) | (r > self.max_radius)
        return np.where(bad, np.pi / 2, th)

    def chance(self, kind: str) -> float:
        """Expected MSAC score of one uniformly random direction for a field type.

        A random direction lies within ``thr`` of a sphere's tangent plane with
        probability sin(thr) (mean inlier score 2/3 for small thr), within ``thr`` of a
        directed field's vector with probability (1 - cos(thr)) / 2 (mean score 1/2).
        """
        thr = self._threshold(kind)
        if kind == "sphere":
            return math.sin(thr) * 2.0 / 3.0
        return 0.5 * (1.0 - math.cos(thr)) * 0.5

    def _inliers(self, f: Field, p: Array, v: Array) -> NDArray[np.bool_]:
        return self._angles(f, p, v) < self._threshold(f.type)

    def _score(self, f: Field, p: Array, v: Array) -> tuple[float, NDArray[np.bool_]]:
        """MSAC score: sum over inliers of ``1 - (angle / threshold)^2``, minus what as
        many uniformly random directions would score (a sphere accepts a whole plane of
        directions, so it would otherwise win on chance inliers alone)."""
        thr = self._threshold(f.type)
        th = self._angles(f, p, v)
        inl = th < thr
        raw = float(np.sum(1.0 - (th[inl] / thr) ** 2))
        return raw - self.chance_weight * self.chance(f.type) * len(p), inl

    def _ransac(self, kind: str, p: Array, v: Array, rng: np.random.Generator):
        S = SAMPLE_SIZE[kind]
        n = len(p)
        if n < max(S, 2):
            return None, np.zeros(n, dtype=bool), -np.inf
        iters = ransac_iterations(self.p_success, self.outlier_ratio, S)
        best, best_in, best_score = None, np.zeros(n, dtype=bool), -np.inf
        for _ in range(iters):
            idx = rng.choice(n, size=S, replace=False)
            f = _estimate(kind, p[idx], v[idx])
            if f is None:
                continue
            score, inl = self._score(f, p, v)
            if score > best_score:
                best, best_in, best_score = f, inl, score
        # Least-squares refinement on the inliers, then rescore (stable parameters).
        for _ in range(self.refine_steps):
            if best is None or best_in.sum() < S + 1:
                break
            f = _estimate(kind, p[best_in], v[best_in])
            if f is None:
                break
            score, inl = self._score(f, p, v)
            if score < best_score:
                break
            best, best_in, best_score = f, inl, score
        return best, best_in, best_score

    # --- fit --------------------------------------------------------------------------

    def fit(self, points: list[ArrayLike], quaternions: list[ArrayLike] | None = None,
            progress: Callable[[str], None] | None = None) -> VectorFieldLearner:
        """Fit on demonstrations.

        Parameters
        ----------
        points : list of array-like, each (n_i, 3)
            Subsampled positions (object frame) of the frame the fields describe.
        quaternions : list of array-like, each (n_i, 4), optional
            Orientations at those samples (kept for the neighbour orientation
            constraint and the candidate frames' ee offsets).
        progress : callable(str), optional
            Called with the stage's name as each stage ends (``ransac``, ``em``).
        """
        rng = np.random.default_rng(self.random_state)
        t0 = time.perf_counter()
        self._set_vectors(points, quaternions)
        self._sequential_ransac(rng)
        if progress is not None:
            progress("ransac")
        t1 = time.perf_counter()
        self._em()
        if progress is not None:
            progress("em")
        self._candidate_frames()
        self.timings_ = {"ransac": t1 - t0, "em": time.perf_counter() - t1}
        return self

    def _set_vectors(self, points: list[ArrayLike], quaternions: list[ArrayLike] | None) -> None:
        """Unit displacement vectors of every demonstration, at chord midpoints, with the
        orientation there, which demonstration and which sample each came from."""
        P, V, Q, demo, order = [], [], [], [], []
        for k, pts in enumerate(points):
            pts = np.asarray(pts, dtype=float)
            if len(pts) < 2:
                continue
            p, v = unit_vectors(pts)
            ok = np.linalg.norm(v, axis=1) > 0.5
            P.append(p[ok])
            V.append(v[ok])
            q = (np.tile([0.0, 0.0, 0.0, 1.0], (len(pts), 1)) if quaternions is None
                 else np.asarray(quaternions[k], dtype=float))
            # Orientation at the chord midpoint: normalised sum of sign-aligned ends.
            q0, q1 = q[:-1], q[1:] * np.where(np.sum(q[:-1] * q[1:], axis=1) < 0, -1.0, 1.0)[:, None]
            qm = q0 + q1
            Q.append((qm / np.linalg.norm(qm, axis=1, keepdims=True))[ok])
            demo.append(np.full(int(ok.sum()), k))
            order.append(np.flatnonzero(ok))
        if not P:
            raise ValueError("no displacement vectors (every demonstration needs 2+ points)")
        self.points_ = np.concatenate(P)
        self.vectors_ = np.concatenate(V)
        self.quaternions_ = np.concatenate(Q)
        self.demo_index_ = np.concatenate(demo)
        self.sample_index_ = np.concatenate(order)

    def _sequential_ransac(self, rng: np.random.Generator) -> None:
        """Algorithm 5: the best field of any type, its inliers removed, n_fields times."""
        p, v = self.points_, self.vectors_
        n = len(p)
        remaining = np.ones(n, dtype=bool)
        self.ransac_fields_, self.ransac_inliers_ = [], []
        for _ in range(self.n_fields):
            idx = np.flatnonzero(remaining)
            best = None
            for kind in self.models:
                f, inl, score = self._ransac(kind, p[idx], v[idx], rng)
                if f is None:
                    continue
                if best is None or score > best[2]:
                    best = (f, inl, score)
            if best is None or best[1].sum() < self.min_inliers:
                break
            mask = np.zeros(n, dtype=bool)
            mask[idx[best[1]]] = True
            self.ransac_fields_.append(best[0])
            self.ransac_inliers_.append(mask)
            remaining &= ~mask

    def _coherent(self, assigned: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """Spatio-temporal coherence: runs of >= coherence_run consecutive samples of
        one demonstration, with another such point within coherence_radius."""
        keep = assigned.copy()
        if self.coherence_run > 1:
            # Run lengths of consecutive assigned points within each demonstration.
            brk = np.ones(len(keep), dtype=bool)
            brk[1:] = (self.demo_index_[1:] != self.demo_index_[:-1]) | \
                      (self.sample_index_[1:] != self.sample_index_[:-1] + 1)
            run_id = np.cumsum(brk | np.r_[True, keep[1:] != keep[:-1]])
            lengths = np.bincount(run_id)
            keep &= lengths[run_id] >= self.coherence_run
        idx = np.flatnonzero(keep)
        if len(idx) > 1:
            d, _ = cKDTree(self.points_[idx]).query(self.points_[idx], k=2)
            keep[idx[d[:, 1] > self.coherence_radius]] = False
        return keep

    def _em(self) -> None:
        p, v = self.points_, self.vectors_
        n = len(p)
        fields = list(self.ransac_fields_)
        if not fields:
            self.fields_, self.responsibilities_ = [], np.zeros((n, 0))
            self.assignment_ = np.full(n, -1)
            return
        inl = np.array(self.ransac_inliers_)
        sig = []
        for f, m in zip(fields, inl, strict=True):
            th = self._angles(f, p[m], v[m])
            sig.append(max(math.radians(1.0), float(np.sqrt(np.mean(th**2)))))
        sigma = np.array(sig)
        pi = inl.sum(axis=1) / n
        pi0 = max(0.05, 1.0 - pi.sum())
        for _ in range(max(1, self.em_iterations)):
            TH, R = self._e_step(fields, sigma, pi, pi0, p, v)
            # M-step (eqs. 4.28-4.30); spread as the weighted RMS angle.
            w = R.sum(axis=0)
            pi = w[:-1] / n
            pi0 = max(1e-3, w[-1] / n)
            sigma = np.maximum(math.radians(1.0),
                               np.sqrt(np.sum(R[:, :-1] * TH**2, axis=0) / np.maximum(w[:-1], 1e-12)))
            hard = np.argmax(R, axis=1)
            new_fields, new_sigma, new_pi = [], [], []
            for m, f in enumerate(fields):
                assigned = hard == m
                if self.coherence:
                    assigned = self._coherent(assigned)
                if assigned.sum() < self.min_inliers or pi[m] < self.min_weight:
                    continue  # prune
                g = _estimate(f.type, p[assigned], v[assigned], R[assigned, m])
                new_fields.append(g if g is not None else f)
                new_sigma.append(sigma[m])
                new_pi.append(pi[m])
            if not new_fields:
                break
            fields, sigma, pi = new_fields, np.array(new_sigma), np.array(new_pi)
        _, R = self._e_step(fields, sigma, pi, pi0, p, v)
        hard = np.argmax(R, axis=1)
        self.assignment_ = np.where(hard == len(fields), -1, hard)
        Rf = R[:, :-1]
        s = Rf.sum(axis=1, keepdims=True)
        prior = pi / pi.sum()
        self.responsibilities_ = np.where(s > 1e-9, Rf / np.maximum(s, 1e-12), prior[None, :])
        weights = pi / pi.sum()
        self.fields_ = [replace(f, weight=float(weights[m]), sigma=float(sigma[m]),
                                inliers=int(np.sum(self.assignment_ == m)))
                        for m, f in enumerate(fields)]

    def _e_step(self, fields, sigma: Array, pi: Array, pi0: float, p: Array,
                v: Array) -> tuple[Array, Array]:
        """Eq. 4.27: the deviation angles (n, k) and the responsibilities (n, k + 1; the
        last column the outliers, whose angles have the uniform density 1 / pi), from a
        half-normal likelihood of each field's deviation angle."""
        TH = np.stack([self._angles(f, p, v) for f in fields], axis=1)
        like = (2.0 / (sigma * math.sqrt(2 * math.pi))) * np.exp(-0.5 * (TH / sigma) ** 2)
        num = np.concatenate([like * pi, np.full((len(p), 1), pi0 / math.pi)], axis=1)
        return TH, num / num.sum(axis=1, keepdims=True)

    def _candidate_frames(self) -> None:
        out = []
        counts = {"sphere": 0, "cylinder": 0}
        for m, f in enumerate(self.fields_):
            if isinstance(f, SphereField):
                pos = f.centre
            elif isinstance(f, CylinderField):
                pos = f.point
            else:
                continue
            name = f"{f.type}{counts[f.type]}"
            counts[f.type] += 1
            sel = self.assignment_ == m
            entry: dict = {"name": name, "position": [round(float(x), 6) for x in pos],
                           "kind": f.type}
            if isinstance(f, CylinderField):
                entry["axis"] = [round(float(x), 6) for x in f.axis]
            if sel.any():
                R = se3.matrix_from_quaternion(self.quaternions_[sel])
                off = np.einsum("nji,nj->ni", R, pos - self.points_[sel])
                mean = off.mean(axis=0)
                spread = float(np.sqrt(np.mean(np.sum((off - mean) ** 2, axis=1))))
                entry["ee_offset"] = [round(float(x), 6) for x in mean]
                entry["ee_offset_spread"] = round(spread, 6)
                if spread < self.pivot_spread:  # the demonstrations turned about a point of the hand
                    self.fields_[m] = replace(f, pivot=mean)
            out.append(entry)
        self.candidate_frames_ = out
