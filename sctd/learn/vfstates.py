"""Vector fields used one after the other become states (issue 14, item 3).

The thesis blends all fields of a skill in one state (eqs. 4.31-4.32). Where the
demonstrations use them in sequence -- reach, then pull -- and in separate places, a
state per field with a transition between them tells the user which motion is on and
keeps the fields from mixing where they meet (the end of a reach is the start of a
pull). :func:`plan_states` decides from the fitted learner whether the fields are such a
sequence and learns the transitions as the linear learner does (a linear SVM between
the points of consecutive fields, eq. 4.17), or says why they stay blended.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from .vf import VectorFieldLearner

Array = NDArray[np.float64]


@dataclass(frozen=True)
class FieldTransition:
    """Fires from field ``source``'s state to ``target``'s when the ee position p (object
    frame) has ``normal . p + offset > margin`` (unit ``normal``); ``accuracy`` the
    SVM's balanced training accuracy."""

    source: int
    target: int
    normal: Array
    offset: float
    margin: float
    accuracy: float


@dataclass(frozen=True)
class StatePlan:
    """Fields in the order the demonstrations use them (``order``, field indices), one
    state each, and the transitions between consecutive ones; ``reason`` says why the
    fields stay blended in one state when ``order`` is empty."""

    order: tuple[int, ...] = ()
    transitions: tuple[FieldTransition, ...] = ()
    reason: str = ""
    timing: dict = field(default_factory=dict)

    @property
    def sequential(self) -> bool:
        return len(self.order) > 1


def plan_states(learner: VectorFieldLearner, min_order: float = 0.9, min_accuracy: float = 0.95,
                C: float = 1000.0, margin: float = 0.005, random_state: int | None = 0) -> StatePlan:
    """Whether the fitted ``learner``'s fields are a sequence, and its transitions.

    Parameters
    ----------
    learner : VectorFieldLearner
        Fitted.
    min_order : float
        In at least this share of the demonstrations that use both, each field's points
        come (by their median time) before the next one's.
    min_accuracy : float
        The SVM between consecutive fields' points must separate them this well
        (balanced training accuracy).
    C, margin : float
        The SVM penalty (eq. 4.17, on metres) and the transitions' hysteresis (m).
    random_state : int or None
    """
    from sklearn.svm import SVC

    K = len(learner.fields_)
    if K < 2:
        return StatePlan(reason="one field")
    a, demo = learner.assignment_, learner.demo_index_
    t = learner.sample_index_.astype(float)
    # Each demonstration's time normalised to [0, 1], so that demonstrations of
    # different lengths weigh alike.
    for k in np.unique(demo):
        sel = demo == k
        t[sel] = (t[sel] - t[sel].min()) / max(1.0, float(np.ptp(t[sel])))
    when = np.full((int(demo.max()) + 1, K), np.nan)
    for k in np.unique(demo):
        for m in range(K):
            sel = (demo == k) & (a == m)
            if sel.sum() >= learner.coherence_run:
                when[k, m] = float(np.median(t[sel]))
    used = np.sum(np.isfinite(when), axis=0)
    if np.any(used < 0.5 * when.shape[0]):
        return StatePlan(reason=f"field {int(np.argmin(used))} is used in {int(used.min())} of "
                                f"{when.shape[0]} demonstrations")
    order = tuple(int(m) for m in np.argsort(np.nanmedian(when, axis=0)))
    timing = {}
    for m0, m1 in pairwise(order):
        both = np.isfinite(when[:, m0]) & np.isfinite(when[:, m1])
        share = float(np.mean(when[both, m0] < when[both, m1])) if both.any() else 0.0
        timing[f"{m0}->{m1}"] = round(share, 3)
        if share < min_order:
            return StatePlan(reason=f"field {m0} comes before field {m1} in only {share:.0%} of the "
                                    "demonstrations", timing=timing)
    transitions = []
    for m0, m1 in pairwise(order):
        A, B = learner.points_[a == m0], learner.points_[a == m1]
        X = np.concatenate([A, B])
        y = np.concatenate([-np.ones(len(A)), np.ones(len(B))])
        svm = SVC(kernel="linear", C=C, class_weight="balanced", max_iter=1_000_000,
                  random_state=random_state).fit(X, y)
        w, b = svm.coef_[0], float(svm.intercept_[0])
        pred = X @ w + b
        acc = 0.5 * (np.mean(pred[y < 0] < 0) + np.mean(pred[y > 0] > 0))
        if acc < min_accuracy:
            return StatePlan(reason=f"fields {m0} and {m1} overlap in space (a plane separates "
                                    f"{acc:.0%} of their points)", timing=timing)
        n = float(np.linalg.norm(w))
        transitions.append(FieldTransition(m0, m1, w / n, b / n, margin, float(acc)))
    return StatePlan(order=order, transitions=tuple(transitions), timing=timing)
