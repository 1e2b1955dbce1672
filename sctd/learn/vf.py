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
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from .. import se3
from ..skill.fields import CylinderField, Field, GeneralField, SphereField, TranslationField
from .params import SEED, Flag, Interval, OneOf, hyperparameter

Array = NDArray[np.float64]

FIELD_TYPES = ("translation", "cylinder", "sphere", "general")
SAMPLE_SIZE = {"translation": 1, "cylinder": 2, "sphere": 3}
SELECTIONS = ("likelihood", "inliers")
# Free parameters of each kind's direction model (BIC), besides its spread and share:
# a direction; an axis and a point on it (in the plane normal to it); a centre.
PARAMETERS = {"translation": 2, "cylinder": 4, "sphere": 3}
PLANE_KINDS = ("sphere",)  # kinds that predict a plane of directions, not one direction
LOG_4PI = math.log(4.0 * math.pi)  # -log density of a uniformly random direction


def _log_normaliser(sigma: float, plane: bool) -> float:
    """log Z of a direction density ``exp(-a^2 / (2 sigma^2)) / Z`` on the unit sphere,
    ``a`` the angle to one direction (``plane`` False: a in [0, pi], area 2 pi sin a da)
    or to a plane (True: a in [0, pi/2] either side, area 2 (2 pi cos a) da)."""
    if plane:
        a = np.linspace(0.0, math.pi / 2, 721)
        z = 4.0 * math.pi * np.trapezoid(np.exp(-0.5 * (a / sigma) ** 2) * np.cos(a), a)
    else:
        a = np.linspace(0.0, math.pi, 1441)
        z = 2.0 * math.pi * np.trapezoid(np.exp(-0.5 * (a / sigma) ** 2) * np.sin(a), a)
    return math.log(float(z))


def mixture_fit(angles: ArrayLike, planes: Sequence[bool], iterations: int = 10
                ) -> tuple[float, Array, Array, Array]:
    """How well fields' deviation ``angles`` (n, K) explain the data, against chance.

    The directions are a mixture: a share ``eps_k`` follows field k (a normal spread
    ``sigma_k`` of the angle about its direction, or about its plane when
    ``planes[k]``), the rest is uniform on the sphere; shares and spreads are fitted by
    EM. A plane takes in a band of directions, a direction only a cone: the density of
    a field that predicts less is lower, so it gains less for each direction it
    explains, whatever its inlier count.

    Returns
    -------
    log_lr : float
        Log-likelihood over the uniform-only model (nats; 0 when nothing is explained).
    eps, sigma : ndarray, shape (K,)
    responsibility : ndarray, shape (n, K)
        Each direction's probability of following each field.
    """
    a = np.asarray(angles, dtype=float)
    a = a.reshape(len(a), -1)
    n, K = a.shape
    if n == 0 or K == 0:
        return 0.0, np.zeros(K), np.zeros(K), np.zeros((n, K))
    lo, hi = math.radians(0.5), math.radians(60.0)
    close = a < math.radians(20.0)
    eps = np.clip(close.mean(axis=0) / max(1.0, float(close.mean(axis=0).sum()) / 0.95), 1e-3, 0.95)
    sigma = np.array([min(hi, max(lo, math.sqrt(float(np.mean(a[close[:, k], k] ** 2)))))
                      if close[:, k].any() else 0.3 for k in range(K)])
    dof = np.array([1.0 if pl else 2.0 for pl in planes])  # an angle to a plane has 1 dimension
    log_lr, r = 0.0, np.zeros((n, K))
    for _ in range(iterations):
        logz = np.array([_log_normaliser(float(sg), bool(pl)) for sg, pl in zip(sigma, planes, strict=True)])
        log_in = np.log(eps) - 0.5 * (a / sigma) ** 2 - logz
        log_out = math.log(max(1e-6, 1.0 - float(eps.sum()))) - LOG_4PI
        m = np.maximum(log_in.max(axis=1), log_out)
        log_mix = m + np.log(np.exp(log_in - m[:, None]).sum(axis=1) + np.exp(log_out - m))
        log_lr = float(np.sum(log_mix) + n * LOG_4PI)
        r = np.exp(log_in - log_mix[:, None])
        w = r.sum(axis=0)
        eps = np.maximum(1e-3, w / n)
        if eps.sum() > 0.999:
            eps *= 0.999 / eps.sum()
        sigma = np.clip(np.sqrt((r * a**2).sum(axis=0) / np.maximum(dof * w, 1e-12)), lo, hi)
    return log_lr, eps, sigma, r


def point_log_ratios(angles: ArrayLike, plane: bool, eps: float, sigma: float) -> Array:
    """Each direction's log-likelihood ratio (n,) under one field's mixture (share
    ``eps``, spread ``sigma``) over uniform directions."""
    a = np.asarray(angles, dtype=float)
    log_in = math.log(eps) - 0.5 * (a / sigma) ** 2 - _log_normaliser(sigma, plane)
    log_out = math.log(max(1e-6, 1.0 - eps)) - LOG_4PI
    return np.logaddexp(log_in, log_out) + LOG_4PI


def mixture_log_likelihood(angles: ArrayLike, plane: bool) -> tuple[float, float, float, Array]:
    """:func:`mixture_fit` of one field: ``(log_lr, eps, sigma, responsibility (n,))``."""
    log_lr, eps, sigma, r = mixture_fit(np.asarray(angles, dtype=float)[:, None], [plane])
    return log_lr, float(eps[0]), float(sigma[0]), r[:, 0]


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


def general_field(p: Array, v: Array, w: Array | None = None, bandwidth: float = 0.02) -> Field | None:
    """A general (non-parametric) field through the directions ``v`` at points ``p``:
    one kernel centre per occupied cell of a grid of ``bandwidth / 2``, at the cell's
    (weighted) mean point with its mean direction (cells whose directions cancel are
    left out), so its size is bounded by the space the demonstrations cover, not by
    how many points they have."""
    w = np.ones(len(v)) if w is None else w
    if len(p) == 0:
        return None
    cell = np.floor(p / (0.5 * bandwidth)).astype(np.int64)
    _, inv = np.unique(cell, axis=0, return_inverse=True)
    inv = inv.reshape(-1)
    k = int(inv.max()) + 1
    sw = np.bincount(inv, weights=w, minlength=k)
    centres = np.stack([np.bincount(inv, weights=w * p[:, j], minlength=k) for j in range(3)], axis=1)
    dirs = np.stack([np.bincount(inv, weights=w * v[:, j], minlength=k) for j in range(3)], axis=1)
    ok = (sw > 1e-12) & (np.linalg.norm(dirs, axis=1) > 0.5 * sw)
    if not ok.any():
        return None
    centres = centres[ok] / sw[ok, None]
    dirs = dirs[ok] / np.linalg.norm(dirs[ok], axis=1, keepdims=True)
    return GeneralField(centres=centres, directions=dirs, bandwidth=bandwidth)


def held_out_angles(p: Array, v: Array, demo: NDArray[np.int64], bandwidth: float,
                    support: tuple[Array, Array, NDArray[np.int64], Array] | None = None,
                    k: int = 32) -> Array:
    """Deviation angle of each direction ``v`` (n, 3) at ``p`` (n, 3) of demonstration
    ``demo`` (n,) from what a general field of ``bandwidth`` predicts there when learned
    on the *other* demonstrations' points of ``support`` (points, directions,
    demonstrations and weights; default ``p``, ``v``, ``demo``, ones): the kernel mean
    over its ``k`` nearest support points of other demonstrations. The general field's
    likelihood is a cross-validated one, so it cannot explain a direction by itself.
    pi/2 where no other demonstration is among the ``k`` nearest."""
    sp, sv, sd, sw = (p, v, demo, np.ones(len(p))) if support is None else support
    n = len(p)
    if n == 0 or len(sp) < 2:
        return np.full(n, np.pi / 2)
    d, i = cKDTree(sp).query(p, k=min(k, len(sp)))
    d, i = d.reshape(n, -1), i.reshape(n, -1)
    other = sd[i] != demo[:, None]
    dd = np.where(other, d, np.inf)
    h = np.maximum(bandwidth, dd.min(axis=1, keepdims=True))
    h = np.where(np.isfinite(h), h, 1.0)
    wk = np.where(other, sw[i] * np.exp(-0.5 * (np.where(other, d, 0.0) / h) ** 2), 0.0)
    g = np.einsum("nk,nkj->nj", wk, sv[i])
    norm = np.linalg.norm(g, axis=1)
    c = np.clip(np.sum(g * v, axis=1) / np.maximum(norm, 1e-12), -1.0, 1.0)
    return np.where(norm > 1e-9, np.arccos(c), np.pi / 2)


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
        Weight of the chance-inlier correction when comparing field types by inliers.
    selection : {"likelihood", "inliers"}
        How field types compete in each round of sequential RANSAC. ``likelihood``: by
        the BIC of a mixture of the field's direction density and uniform directions
        (:func:`mixture_log_likelihood`): a field that predicts a direction gains more
        per point it explains than one that only predicts a plane, so a cylinder beats
        the sphere that fits wherever it does, and the general field's
        cross-validated likelihood competes with the shapes'. ``inliers``: the
        thesis' MSAC inlier score with the chance correction (no general field).
    demo_tolerance : float
        A cylinder beats a sphere only where it explains their points better in all but
        this share of the demonstrations (:meth:`_nested_winner`).
    general_bandwidth : float
        Kernel width (m) of the general field.
    general_parameters : float
        Free parameters per kernel centre of the general field in the BIC (the shapes
        have 2-4 in all): the general field pays for the space it covers (one centre
        per cell of half its bandwidth), so it is chosen only where the shapes cannot
        explain the motion.
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

    n_fields: int = hyperparameter(2, "RANSAC fields n_R", valid=Interval(1, 10, integer=True))
    em_iterations: int = hyperparameter(5, "EM iterations", valid=Interval(1, 100, integer=True))
    angle_sphere: float = hyperparameter(15.0, "degrees", valid=Interval(0, 90, open="low"))
    angle_translation: float = hyperparameter(25.0, "degrees", valid=Interval(0, 90, open="low"))
    angle_cylinder: float = hyperparameter(20.0, "degrees", valid=Interval(0, 90, open="low"))
    models: tuple[str, ...] = hyperparameter(FIELD_TYPES, valid=OneOf(FIELD_TYPES, subset=True))
    p_success: float = hyperparameter(0.99, valid=Interval(0.5, 1, open="high"))
    outlier_ratio: float = hyperparameter(0.7, valid=Interval(0, 0.99))
    min_inliers: int = hyperparameter(10, valid=Interval(3, 100_000, integer=True))
    min_weight: float = hyperparameter(0.05, valid=Interval(0, 1))
    coherence: bool = hyperparameter(True, valid=Flag())
    coherence_run: int = hyperparameter(3, valid=Interval(1, 1000, integer=True))
    coherence_radius: float = hyperparameter(0.05, valid=Interval(0, 1))
    min_radius: float = hyperparameter(0.02, valid=Interval(0, 1))
    max_radius: float = hyperparameter(0.3, "largest sphere/cylinder radius (m)",
                                       valid=Interval(0, 5, open="low"))
    refine_steps: int = hyperparameter(2, valid=Interval(0, 20, integer=True))
    chance_weight: float = hyperparameter(
        0.5, "weight of the chance-inlier correction when comparing field types", valid=Interval(0, 10))
    selection: str = hyperparameter(
        "likelihood", "how field types compete: likelihood (BIC of each field's direction "
        "density, with a general non-parametric field) or inliers (the thesis' MSAC score) "
        "(default %(default)s)", choices=SELECTIONS, valid=OneOf(SELECTIONS))
    demo_tolerance: float = hyperparameter(
        0.1, "share of demonstrations a cylinder may explain worse than a sphere and still "
        "be chosen over it (default %(default)s)", valid=Interval(0, 1))
    general_bandwidth: float = hyperparameter(0.02, "general field kernel width (m)",
                                              valid=Interval(0.001, 1))
    general_parameters: float = hyperparameter(
        1.0, "free parameters per kernel centre of the general field in the BIC "
        "(default %(default)s)", valid=Interval(0, 100))
    pivot_spread: float = hyperparameter(0.02, valid=Interval(0, 1))
    random_state: int | None = hyperparameter(
        0, "random seed (default %(default)s)", flag="--seed", metavar="SEED", valid=SEED)

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

    def _estimate(self, kind: str, p: Array, v: Array, w: Array | None = None) -> Field | None:
        if kind == "general":
            return general_field(p, v, w, self.general_bandwidth)
        return _estimate(kind, p, v, w)

    def _field_angles(self, f: Field, p: Array, v: Array) -> Array:
        """:meth:`_angles` over all the learner's points ``p``, ``v``; a general field's
        held out: predicted from the other demonstrations' points near each one (a
        general field fits its own points by construction)."""
        if isinstance(f, GeneralField):
            return held_out_angles(p, v, self.demo_index_, f.bandwidth,
                                   support=self._general_support(f))
        return self._angles(f, p, v)

    def _general_support(self, f: GeneralField) -> tuple[Array, Array, NDArray[np.int64], Array]:
        """The learner's points a general field stands for (those within a cell of one
        of its centres), as a support for :func:`held_out_angles`."""
        d, _ = cKDTree(f.centres).query(self.points_, k=1)
        near = d <= f.bandwidth
        return (self.points_[near], self.vectors_[near], self.demo_index_[near],
                np.ones(int(near.sum())))

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
        """Algorithm 5: the best field of any shape, its inliers removed, n_fields times;
        then, by :attr:`selection` ``likelihood``, the general field may take the place
        of the last fields (:meth:`_with_general`)."""
        p, v = self.points_, self.vectors_
        n = len(p)
        remaining = np.ones(n, dtype=bool)
        self.ransac_fields_, self.ransac_inliers_ = [], []
        self.selection_: list[dict[str, float]] = []  # each round's shapes and their evidence
        for _ in range(self.n_fields):
            idx = np.flatnonzero(remaining)
            scored: list[tuple[Field, NDArray[np.bool_], float]] = []
            for kind in self.models:
                if kind == "general":
                    continue
                f, inl, score = self._ransac(kind, p[idx], v[idx], rng)
                if f is not None:
                    scored.append((f, inl, score))
            if not scored:
                break
            if self.selection == "likelihood":
                best = scored[self._tournament([f for f, _, _ in scored], [m for _, m, _ in scored],
                                               p[idx], v[idx], self.demo_index_[idx])]
            else:
                best = max(scored, key=lambda c: c[2])
            if best[1].sum() < self.min_inliers:
                break
            mask = np.zeros(n, dtype=bool)
            mask[idx[best[1]]] = True
            self.ransac_fields_.append(best[0])
            self.ransac_inliers_.append(mask)
            remaining &= ~mask
        if self.selection == "likelihood" and "general" in self.models:
            self._with_general()

    def _evidence(self, f: Field, p: Array, v: Array) -> float:
        """BIC score (higher is better, nats) of field ``f`` on points ``p`` with
        directions ``v``: its mixture log-likelihood ratio over uniform directions
        (:func:`mixture_fit`), less half its free parameters (direction model, spread,
        share) times log n."""
        log_lr = mixture_log_likelihood(self._angles(f, p, v), f.type in PLANE_KINDS)[0]
        return log_lr - 0.5 * (PARAMETERS[f.type] + 2) * math.log(max(2, len(p)))

    def _tournament(self, fields: list[Field], inliers: list[NDArray[np.bool_]], p: Array,
                    v: Array, demo: NDArray[np.int64]) -> int:
        """Which of a round's candidate fields (one per shape) is chosen: the larger
        :meth:`_evidence` on the points left (in ``self.selection_``), once the cylinder
        and the sphere have been compared on the points either of them explains (the
        union of their inliers, :meth:`_nested_winner`) and the loser dropped.

        Comparing on the points in question is what makes a cylinder win where it fits:
        a sphere centred on its axis fits there as well, but the cylinder predicts a
        direction, not a plane, and explains them more sharply."""
        whole = [self._evidence(f, p, v) for f in fields]
        self.selection_.append({f.type: round(w, 3) for f, w in zip(fields, whole, strict=True)})
        kinds = [f.type for f in fields]
        alive = list(range(len(fields)))
        if "cylinder" in kinds and "sphere" in kinds:
            c, s = kinds.index("cylinder"), kinds.index("sphere")
            u = inliers[c] | inliers[s]
            if u.any():
                alive.remove(s if self._nested_winner(fields[c], fields[s], p[u], v[u], demo[u]) else c)
        return max(alive, key=lambda i: whole[i])

    def _nested_winner(self, cylinder: Field, sphere: Field, p: Array, v: Array,
                       demo: NDArray[np.int64]) -> bool:
        """Whether the cylinder rather than the sphere explains the points ``p``, ``v``
        (of demonstrations ``demo``): a larger :meth:`_evidence` there and, since a
        cylinder is a sphere whose rotation axis is fixed, a larger likelihood in all but
        ``demo_tolerance`` of the demonstrations that have them (where the
        demonstrations turned about different axes, a fixed axis would make some of
        them impossible)."""
        if self._evidence(cylinder, p, v) < self._evidence(sphere, p, v):
            return False
        per = []
        for f in (cylinder, sphere):
            th = self._angles(f, p, v)
            plane = f.type in PLANE_KINDS
            _, eps, sigma, _ = mixture_log_likelihood(th, plane)
            per.append(point_log_ratios(th, plane, eps, sigma))
        demos = [d for d in np.unique(demo) if np.sum(demo == d) >= self.coherence_run]
        lost = sum(1 for d in demos if per[0][demo == d].sum() < per[1][demo == d].sum())
        return lost <= self.demo_tolerance * len(demos)

    def _with_general(self) -> None:
        """Whole-model selection: the shapes found, against the first j of them plus a
        general field on the points they leave (j = 0 .. found - 1), by the BIC of
        the whole mixture; the general field's angles are held out (predicted from the
        other demonstrations). Keeps the best, and the scores in ``model_scores_``."""
        p, v, demo = self.points_, self.vectors_, self.demo_index_
        fields, masks = list(self.ransac_fields_), list(self.ransac_inliers_)
        angles = [self._angles(f, p, v) for f in fields]

        def bic(cols: list[Array], kinds: list[str], general: tuple[GeneralField, ...] = ()
                ) -> tuple[float, Array]:
            log_lr, _, _, r = mixture_fit(np.stack(cols, axis=1), [k in PLANE_KINDS for k in kinds])
            k = float(sum(PARAMETERS[t] for t in kinds if t != "general"))
            k += sum(self.general_parameters * len(g.centres) for g in general)
            return log_lr - 0.5 * (k + 2 * len(kinds)) * math.log(max(2, len(p))), r

        best_score, _ = bic(angles, [f.type for f in fields]) if fields else (0.0, None)
        scores = {"+".join(f.type for f in fields) or "none": round(best_score, 3)}
        best = None
        for j in range(len(fields) - 1, -1, -1):
            rest = ~np.any(masks[:j], axis=0) if j else np.ones(len(p), dtype=bool)
            if rest.sum() < self.min_inliers:
                continue
            g = general_field(p[rest], v[rest], bandwidth=self.general_bandwidth)
            if not isinstance(g, GeneralField):
                continue
            support = (p[rest], v[rest], demo[rest], np.ones(int(rest.sum())))
            th = held_out_angles(p, v, demo, self.general_bandwidth, support=support)
            kinds = [f.type for f in fields[:j]] + ["general"]
            score, r = bic([*angles[:j], th], kinds, (g,))
            scores["+".join(kinds)] = round(score, 3)
            if score > best_score:
                best_score, best = score, (j, g, (r[:, -1] > 0.5) & rest)
        self.model_scores_ = scores
        if best is not None:
            j, g, inl = best
            self.ransac_fields_ = [*fields[:j], g]
            self.ransac_inliers_ = [*masks[:j], inl]

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
                g = self._estimate(f.type, p[assigned], v[assigned], R[assigned, m])
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
        TH = np.stack([self._field_angles(f, p, v) for f in fields], axis=1)
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
