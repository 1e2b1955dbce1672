"""Which vector fields: the shapes compared by likelihood, and the general field against
them (``docs/learning.md``, "Which field: a likelihood, not inlier counts").

Each round of sequential RANSAC (:mod:`.vfransac`) offers the best field of each shape;
:meth:`ModelSelection.tournament` keeps the one with the larger BIC of its direction
mixture (:mod:`.vfmixture`), once the cylinder and the sphere have been compared on the
points either explains. At the end, :meth:`ModelSelection.with_general` weighs the shapes
found against the first j of them plus a general field on the points they leave.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..skill.fields import Field, GeneralField
from .vffields import general_field, held_out_angles
from .vfmixture import PARAMETERS, PLANE_KINDS, mixture_fit, mixture_log_likelihood, point_log_ratios

Array = NDArray[np.float64]
Mask = NDArray[np.bool_]


@dataclass(eq=False)
class ModelSelection:
    """Field shapes compared by the BIC of their direction mixtures.

    Parameters
    ----------
    angles : callable
        ``angles(field, p, v)``: the deviation angles (n,) of directions ``v`` at ``p``.
    coherence_run : int
        A demonstration counts in the cylinder-sphere comparison with at least this many
        of the points in question.
    demo_tolerance : float
        Share of those demonstrations a cylinder may explain worse than a sphere and
        still be chosen over it.
    general_bandwidth : float
        Kernel width (m) of the general field.
    general_parameters : float
        Free parameters per kernel centre of the general field in the BIC.
    min_inliers : int
        The fewest points a general field may stand for.

    Attributes
    ----------
    rounds : list of dict
        Each :meth:`tournament`'s shapes and their evidence (nats).
    """

    angles: Callable[[Field, Array, Array], Array]
    coherence_run: int
    demo_tolerance: float
    general_bandwidth: float
    general_parameters: float
    min_inliers: int
    rounds: list[dict[str, float]] = field(default_factory=list)

    def evidence(self, f: Field, p: Array, v: Array) -> float:
        """BIC score (higher is better, nats) of field ``f`` on points ``p`` with
        directions ``v``: its mixture log-likelihood ratio over uniform directions
        (:func:`~.vfmixture.mixture_fit`), less half its free parameters (direction
        model, spread, share) times log n."""
        log_lr = mixture_log_likelihood(self.angles(f, p, v), f.type in PLANE_KINDS)[0]
        return log_lr - 0.5 * (PARAMETERS[f.type] + 2) * math.log(max(2, len(p)))

    def tournament(self, fields: list[Field], inliers: list[Mask], p: Array, v: Array,
                   demo: NDArray[np.int64]) -> int:
        """Which of a round's candidate fields (one per shape) is chosen: the larger
        :meth:`evidence` on the points left (kept in :attr:`rounds`), once the cylinder
        and the sphere have been compared on the points either of them explains (the
        union of their inliers, :meth:`nested_winner`) and the loser dropped.

        Comparing on the points in question is what makes a cylinder win where it fits:
        a sphere centred on its axis fits there as well, but the cylinder predicts a
        direction, not a plane, and explains them more sharply."""
        whole = [self.evidence(f, p, v) for f in fields]
        self.rounds.append({f.type: round(w, 3) for f, w in zip(fields, whole, strict=True)})
        kinds = [f.type for f in fields]
        alive = list(range(len(fields)))
        if "cylinder" in kinds and "sphere" in kinds:
            c, s = kinds.index("cylinder"), kinds.index("sphere")
            u = inliers[c] | inliers[s]
            if u.any():
                alive.remove(s if self.nested_winner(fields[c], fields[s], p[u], v[u], demo[u]) else c)
        return max(alive, key=lambda i: whole[i])

    def nested_winner(self, cylinder: Field, sphere: Field, p: Array, v: Array,
                      demo: NDArray[np.int64]) -> bool:
        """Whether the cylinder rather than the sphere explains the points ``p``, ``v``
        (of demonstrations ``demo``): a larger :meth:`evidence` there and, since a
        cylinder is a sphere whose rotation axis is fixed, a larger likelihood in all but
        ``demo_tolerance`` of the demonstrations that have them (where the
        demonstrations turned about different axes, a fixed axis would make some of
        them impossible)."""
        if self.evidence(cylinder, p, v) < self.evidence(sphere, p, v):
            return False
        per = []
        for f in (cylinder, sphere):
            th = self.angles(f, p, v)
            plane = f.type in PLANE_KINDS
            _, eps, sigma, _ = mixture_log_likelihood(th, plane)
            per.append(point_log_ratios(th, plane, eps, sigma))
        demos = [d for d in np.unique(demo) if np.sum(demo == d) >= self.coherence_run]
        lost = sum(1 for d in demos if per[0][demo == d].sum() < per[1][demo == d].sum())
        return lost <= self.demo_tolerance * len(demos)

    def _bic(self, cols: list[Array], kinds: list[str], n: int,
             general: tuple[GeneralField, ...] = ()) -> tuple[float, Array]:
        """The BIC of a whole mixture of fields of ``kinds`` with deviation angles
        ``cols`` (each (n,)) over ``n`` points, and its responsibilities (n, K)."""
        log_lr, _, _, r = mixture_fit(np.stack(cols, axis=1), [k in PLANE_KINDS for k in kinds])
        k = float(sum(PARAMETERS[t] for t in kinds if t != "general"))
        k += sum(self.general_parameters * len(g.centres) for g in general)
        return log_lr - 0.5 * (k + 2 * len(kinds)) * math.log(max(2, n)), r

    def with_general(self, p: Array, v: Array, demo: NDArray[np.int64], fields: list[Field],
                     masks: list[Mask]) -> tuple[list[Field], list[Mask], dict[str, float]]:
        """Whole-model selection: the shapes found (``fields`` with their inlier
        ``masks`` over ``p``), against the first j of them plus a general field on the
        points they leave (j = 0 .. found - 1), by the BIC of the whole mixture; the
        general field's angles are held out (predicted from the other demonstrations).
        Returns the best fields and inliers, and every model's score."""
        angles = [self.angles(f, p, v) for f in fields]
        best_score, _ = self._bic(angles, [f.type for f in fields], len(p)) if fields else (0.0, None)
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
            score, r = self._bic([*angles[:j], th], kinds, len(p), (g,))
            scores["+".join(kinds)] = round(score, 3)
            if score > best_score:
                best_score, best = score, (j, g, (r[:, -1] > 0.5) & rest)
        if best is None:
            return list(fields), list(masks), scores
        j, g, inl = best
        return [*fields[:j], g], [*masks[:j], inl], scores
