"""The vector fields' geometry (Ch. 4.2, Appendix A.1): unit displacement vectors of
demonstrations, the least-squares fit of each field kind to points and vectors, and the
deviation angles by which fields are scored.

Sphere centre: it minimises ``sum w ((p - c) . v)^2``, linear in c; directions the data
do not constrain (a single rotation axis) keep the minimum-norm solution about the
points' centroid, i.e. the circle's centre. Cylinder: the axis is the direction most
orthogonal to every ``v``, its point the sphere's solution in the plane normal to it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from ..skill.fields import CylinderField, Field, GeneralField, PointField, SphereField, TranslationField

Array = NDArray[np.float64]


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


class Displacements(NamedTuple):
    """The unit displacement vectors of every demonstration, at chord midpoints, with
    the orientation there and which demonstration and which sample each came from."""

    points: Array  # (n, 3)
    vectors: Array  # (n, 3)
    quaternions: Array  # (n, 4)
    demo: NDArray[np.int64]  # (n,)
    sample: NDArray[np.int64]  # (n,)


def displacements(points: list[ArrayLike], quaternions: list[ArrayLike] | None) -> Displacements:
    """The :class:`Displacements` of demonstrations ``points`` (each (n_i, 3)) with their
    orientations ``quaternions`` (each (n_i, 4); none: the identity). A demonstration of
    fewer than 2 points has none, and neither has a step of zero length.

    Raises
    ------
    ValueError
        No demonstration has a displacement vector.
    """
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
    return Displacements(np.concatenate(P), np.concatenate(V), np.concatenate(Q),
                         np.concatenate(demo), np.concatenate(order))


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


def point_field(p: Array, v: Array, w: Array | None = None, iterations: int = 5) -> Field | None:
    """Point field whose point best lies ahead of every point ``p`` along its ``v``.

    It minimises ``sum w sin^2(angle)``, the angle between ``v`` and the way to the
    point, by reweighted least squares: each step solves the linear problem ``sum w'
    |(I - v v^T)(c - p)|^2`` (the squared distance of c from the line through p along
    v) with ``w' = w / |c - p|^2`` from the last step, so that a far point's line
    counts by its angle, not by how far it passes; lines the point lies behind (the
    motion has gone past it) count for nothing. None when the lines are (nearly)
    parallel (a translation field describes them) or the point lies behind them all."""
    w = np.ones(len(v)) if w is None else np.asarray(w, dtype=float)
    proj = np.eye(3)[None, :, :] - v[:, :, None] * v[:, None, :]  # (n, 3, 3)
    wk = w
    c = None
    for _ in range(iterations + 1):
        wk = wk / max(float(wk.sum()), 1e-12)
        A = np.einsum("n,nij->ij", wk, proj)
        if np.linalg.eigvalsh(A)[0] < 1e-4:  # lines all (nearly) parallel: no point
            return None if c is None else PointField(point=c)
        c = np.linalg.solve(A, np.einsum("n,nij,nj->i", wk, proj, p))
        ahead = np.sum(v * (c - p), axis=1)
        if not np.any(ahead > 0.0):
            return None
        d2 = np.sum((c - p) ** 2, axis=1)
        wk = np.where(ahead > 0.0, w / np.maximum(d2, 1e-6), 0.0)
    assert c is not None
    return PointField(point=c)


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
    "point": point_field,
}

def estimate(kind: str, p: Array, v: Array, w: Array | None = None, bandwidth: float = 0.02
             ) -> Field | None:
    """The least-squares field of ``kind`` through directions ``v`` (n, 3) at points ``p``
    (n, 3), weighted by ``w`` (n,; default ones); ``bandwidth``: a general field's."""
    if kind == "general":
        return general_field(p, v, w, bandwidth)
    return ESTIMATORS[kind](p, v, w)


# --- deviation angles ---------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class FieldAngles:
    """Deviation angles (Appendix A.1) of fields from the directions of the points of
    :class:`Displacements` ``data``, spheres and cylinders counting only points at a
    radius within [``min_radius``, ``max_radius``] (m)."""

    data: Displacements
    min_radius: float
    max_radius: float
    max_cylinder_radius: float | None = None

    def __call__(self, f: Field, p: Array, v: Array) -> Array:
        """Deviation angles (n,) of directions ``v`` at ``p``; pi/2 where a sphere's or a
        cylinder's radius is out of range."""
        th = f.deviation_angles(p, v)
        top = self.max_radius
        if isinstance(f, SphereField):
            r = np.linalg.norm(p - f.centre, axis=1)
        elif isinstance(f, CylinderField):
            r = np.linalg.norm(np.cross(f.axis, p - f.point), axis=1)
            top = self.max_cylinder_radius if self.max_cylinder_radius is not None else top
        else:
            return th
        bad = (r < self.min_radius) | (r > top)
        return np.where(bad, np.pi / 2, th)

    def held_out(self, f: Field, p: Array, v: Array) -> Array:
        """:meth:`__call__`, but a general field's held out: predicted at each of the
        points ``p`` (of ``data``, in its order) from the other demonstrations' points
        near it (a general field fits its own points by construction)."""
        if isinstance(f, GeneralField):
            return held_out_angles(p, v, self.data.demo, f.bandwidth, support=self.general_support(f))
        return self(f, p, v)

    def general_support(self, f: GeneralField) -> tuple[Array, Array, NDArray[np.int64], Array]:
        """The points a general field stands for (those within a cell of one of its
        centres), as a support for :func:`held_out_angles`."""
        data = self.data
        d, _ = cKDTree(f.centres).query(data.points, k=1)
        near = d <= f.bandwidth
        return data.points[near], data.vectors[near], data.demo[near], np.ones(int(near.sum()))
