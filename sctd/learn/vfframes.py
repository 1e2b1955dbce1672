"""Candidate feature frames from vector fields (Ch. 4.2.7): sphere centres and cylinder
axis points, with the centre's mean offset in the ee frame over the points the field
explains (for the pour: the bottle tip); and, for a field the demonstrations turned the
hand about one point of, that point (:func:`turning_point`)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from .. import se3
from ..skill.fields import CylinderField, Field, SphereField

Array = NDArray[np.float64]


def candidate_frames(fields: list[Field], assignment: NDArray[np.int64], points: Array,
                     quaternions: Array, pivot_spread: float,
                     steps: NDArray[np.int64] | None = None) -> tuple[list[dict], list[Field]]:
    """One candidate frame per sphere or cylinder of ``fields``, named by kind and
    number (``sphere0``, ``cylinder0``, ...): its position (and axis), and where the
    points it explains (``assignment``, (n,)) have the ee (``points`` (n, 3),
    ``quaternions`` (n, 4)), its mean offset in the ee frame and that offset's RMS
    spread. Returns the frames and the fields, a field whose offset spreads less than
    ``pivot_spread`` (m) given a point of the hand as its ``pivot`` (the demonstrations
    turned about it: a bottle's opening): with ``steps`` (the indices i of the points
    whose next point i + 1 follows them in the same demonstration), the point of the
    hand that stays put over the field's steps (:func:`turning_point`), else the mean
    offset; a sphere is then centred where that point was (:func:`_about`)."""
    out = []
    fields = list(fields)
    counts = {"sphere": 0, "cylinder": 0}
    for m, f in enumerate(fields):
        if not isinstance(f, SphereField | CylinderField):
            continue
        name = f"{f.type}{counts[f.type]}"
        counts[f.type] += 1
        sel = assignment == m
        if sel.any():
            R = se3.matrix_from_quaternion(quaternions[sel])
            mean, spread = _offset(f, R, points[sel])
            if spread < pivot_spread:  # the demonstrations turned about a point of the hand
                pivot = mean
                if steps is not None:
                    own = steps[sel[steps] & sel[steps + 1]]
                    pivot = turning_point(se3.matrix_from_quaternion(quaternions), points, own, mean)
                f = _about(f, pivot, R, points[sel])
                fields[m] = f
                mean, spread = _offset(f, R, points[sel])
        out.append(_entry(name, f, mean, spread) if sel.any() else _entry(name, f))
    return out, fields


def _position(f: SphereField | CylinderField) -> Array:
    return f.centre if isinstance(f, SphereField) else f.point


def _offset(f: SphereField | CylinderField, R: Array, p: Array) -> tuple[Array, float]:
    """The field's centre (or axis point) in the ee frame of the poses ``R``, ``p``: the
    mean and its RMS spread."""
    off = np.einsum("nji,nj->ni", R, _position(f) - p)
    mean = off.mean(axis=0)
    return mean, float(np.sqrt(np.mean(np.sum((off - mean) ** 2, axis=1))))


def _about(f: SphereField | CylinderField, pivot: Array, R: Array, p: Array
           ) -> SphereField | CylinderField:
    """The field given ``pivot``; a sphere also centred where that point of the hand was
    (its mean over the field's poses ``R``, ``p``), with the hand's mean distance from it
    as its radius. A sphere through the arcs of turns about one axis is not fixed along
    that axis by the arcs (any centre on the axis at the right distance fits): the fit
    may put it centimetres aside, and the hand would then turn about a point that is not
    the one it turned about (a cup's rim would slide along the lips)."""
    if not isinstance(f, SphereField):
        return replace(f, pivot=pivot)
    centre = np.mean(p + np.einsum("nij,j->ni", R, pivot), axis=0)
    radius = float(np.mean(np.linalg.norm(p - centre, axis=1)))
    return replace(f, pivot=pivot, centre=centre, radius=radius)


def _entry(name: str, f: SphereField | CylinderField, mean: Array | None = None,
           spread: float = 0.0) -> dict:
    entry: dict = {"name": name, "position": [round(float(x), 6) for x in _position(f)], "kind": f.type}
    if isinstance(f, CylinderField):
        entry["axis"] = [round(float(x), 6) for x in f.axis]
    if mean is not None:
        entry["ee_offset"] = [round(float(x), 6) for x in mean]
        entry["ee_offset_spread"] = round(spread, 6)
    return entry

FREE = 0.1
"""A direction the steps determine less than this share of the best-determined one
(the singular values' ratio) is left free: along the axis the hand turned about, when
it always turned about one, the point is the one of that axis nearest the hand's
origin."""
ITERATIONS = 20
"""Reweightings of :func:`turning_point`'s robust least squares."""
TUKEY = 4.685
"""Tukey's biweight constant, in robust standard deviations of the residuals."""


def turning_point(R: Array, p: Array, steps: NDArray[np.int64], start: Array) -> Array:
    """The point ``x`` of the hand (ee frame) that moves least over the steps ``i -> i + 1``
    (``i`` in ``steps``) of the ee poses (``R`` (n, 3, 3), ``p`` (n, 3), object frame):
    the robust least-squares solution of ``(R_{i+1} - R_i) x = -(p_{i+1} - p_i)``.

    A step that turns the hand about x satisfies it; one that only translates the hand
    says nothing of x (its matrix is 0) and so does not pull it; one that both turns and
    translates (the hand carried while it wobbles, an arm that overshoots) is
    down-weighted by Tukey's biweight on the residuals (their scale the median absolute
    residual, 1.4826 times), reweighted :data:`ITERATIONS` times. Along directions the
    steps leave (nearly) free (:data:`FREE`) the point is the nearest the hand's origin
    (where the hand always turned about one axis: the point of that axis nearest the
    hand; nothing in the poses tells where along it the turned object's point was).
    Without steps, or with steps that never turn, ``start``. Deterministic, pure numpy.
    """
    if len(steps) == 0:
        return np.asarray(start, dtype=float)
    dR = R[steps + 1] - R[steps]
    dp = p[steps + 1] - p[steps]
    x = np.asarray(start, dtype=float)
    w = np.ones(len(steps))
    for _ in range(ITERATIONS):
        x = _weighted_point(dR, dp, w, start)
        r = np.linalg.norm(np.einsum("nij,j->ni", dR, x) + dp, axis=1)
        scale = 1.4826 * float(np.median(r))
        if not scale > 1e-12:  # (every step agrees: done)
            break
        u = r / (TUKEY * scale)
        w = np.where(u < 1.0, (1.0 - u * u) ** 2, 0.0)
    return x


def _weighted_point(dR: Array, dp: Array, w: Array, start: Array) -> Array:
    """The weighted least-squares ``x`` of ``dR x = -dp`` of least norm along the
    directions the weighted steps leave free; ``start`` when they fix none."""
    sw = np.sqrt(w)
    A = (dR * sw[:, None, None]).reshape(-1, 3)
    b = (-dp * sw[:, None]).reshape(-1)
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    if not s[0] > 0.0:
        return np.asarray(start, dtype=float)
    keep = s >= FREE * s[0]
    return Vt[keep].T @ ((U[:, keep].T @ b) / s[keep])
