"""EM over vector fields (Algorithm 6, eqs. 4.27-4.30).

Half-normal likelihoods of each field's deviation angle plus a uniform background
component for outliers; the spread is the weighted RMS angle (eq. 4.30 written as a
proper spread); the points a field takes may be filtered for spatio-temporal coherence
(:mod:`.vfcoherence`); weighted least-squares parameter updates (:mod:`.vffields`);
fields with too few points or too little weight are pruned.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..skill.fields import Field
from .vffields import FieldAngles, estimate

Array = NDArray[np.float64]
Mask = NDArray[np.bool_]


@dataclass(frozen=True, eq=False)
class FieldEM:
    """EM of fields over the points of their :class:`~.vffields.FieldAngles`.

    Parameters
    ----------
    iterations : int
        EM iterations (at least one).
    min_inliers : int
        Fields that take fewer points are pruned.
    min_weight : float
        Fields with a smaller mixing proportion are pruned.
    angles : FieldAngles
        The deviation angles (a general field's held out).
    bandwidth : float
        The general field's kernel width (m), for its update.
    coherent : callable, optional
        ``coherent(assigned) -> assigned``: the points a field keeps of those it takes.
    """

    iterations: int
    min_inliers: int
    min_weight: float
    angles: FieldAngles
    bandwidth: float
    coherent: Callable[[Mask], Mask] | None = None

    def fit(self, fields: list[Field], inliers: list[Mask], p: Array, v: Array
            ) -> tuple[list[Field], Array, NDArray[np.int64]]:
        """EM from ``fields`` with their RANSAC ``inliers`` (masks over ``p``) on the
        directions ``v`` at ``p`` (each (n, 3)). Returns the fields (with weight, sigma
        and inliers filled in), the responsibilities (n, K; rows sum to 1) and each
        point's field (n,; -1 the background)."""
        n = len(p)
        if not fields:
            return [], np.zeros((n, 0)), np.full(n, -1)
        inl = np.array(inliers)
        sig = []
        for f, m in zip(fields, inl, strict=True):
            th = self.angles(f, p[m], v[m])
            sig.append(max(math.radians(1.0), float(np.sqrt(np.mean(th**2)))))
        sigma = np.array(sig)
        pi = inl.sum(axis=1) / n
        pi0 = max(0.05, 1.0 - pi.sum())
        for _ in range(max(1, self.iterations)):
            TH, R = self.e_step(fields, sigma, pi, pi0, p, v)
            # M-step (eqs. 4.28-4.30); spread as the weighted RMS angle.
            w = R.sum(axis=0)
            pi = w[:-1] / n
            pi0 = max(1e-3, w[-1] / n)
            sigma = np.maximum(math.radians(1.0),
                               np.sqrt(np.sum(R[:, :-1] * TH**2, axis=0) / np.maximum(w[:-1], 1e-12)))
            kept = self._update(fields, sigma, pi, R, p, v)
            if not kept[0]:
                break
            fields, sigma, pi = kept
        return self._result(fields, sigma, pi, pi0, p, v)

    def _update(self, fields: list[Field], sigma: Array, pi: Array, R: Array, p: Array, v: Array
                ) -> tuple[list[Field], Array, Array]:
        """The M-step's parameter updates: each field refitted by weighted least squares
        to the points it takes (filtered by :attr:`coherent`), or pruned; the fields kept
        with their spreads and shares."""
        hard = np.argmax(R, axis=1)
        new_fields, new_sigma, new_pi = [], [], []
        for m, f in enumerate(fields):
            assigned = hard == m
            if self.coherent is not None:
                assigned = self.coherent(assigned)
            if assigned.sum() < self.min_inliers or pi[m] < self.min_weight:
                continue  # prune
            g = estimate(f.type, p[assigned], v[assigned], R[assigned, m], self.bandwidth)
            new_fields.append(g if g is not None else f)
            new_sigma.append(sigma[m])
            new_pi.append(pi[m])
        return new_fields, np.array(new_sigma), np.array(new_pi)

    def _result(self, fields: list[Field], sigma: Array, pi: Array, pi0: float, p: Array, v: Array
                ) -> tuple[list[Field], Array, NDArray[np.int64]]:
        """The final E-step: each point's field, the responsibilities among the fields
        (the prior where no field explains a point), the fields' weights."""
        _, R = self.e_step(fields, sigma, pi, pi0, p, v)
        hard = np.argmax(R, axis=1)
        assignment = np.where(hard == len(fields), -1, hard)
        Rf = R[:, :-1]
        s = Rf.sum(axis=1, keepdims=True)
        prior = pi / pi.sum()
        responsibilities = np.where(s > 1e-9, Rf / np.maximum(s, 1e-12), prior[None, :])
        weights = pi / pi.sum()
        out = [replace(f, weight=float(weights[m]), sigma=float(sigma[m]),
                       inliers=int(np.sum(assignment == m)))
               for m, f in enumerate(fields)]
        return out, responsibilities, assignment

    def e_step(self, fields: list[Field], sigma: Array, pi: Array, pi0: float, p: Array,
               v: Array) -> tuple[Array, Array]:
        """Eq. 4.27: the deviation angles (n, k) and the responsibilities (n, k + 1; the
        last column the outliers, whose angles have the uniform density 1 / pi), from a
        half-normal likelihood of each field's deviation angle."""
        TH = np.stack([self.angles.held_out(f, p, v) for f in fields], axis=1)
        like = (2.0 / (sigma * math.sqrt(2 * math.pi))) * np.exp(-0.5 * (TH / sigma) ** 2)
        num = np.concatenate([like * pi, np.full((len(p), 1), pi0 / math.pi)], axis=1)
        return TH, num / num.sum(axis=1, keepdims=True)
