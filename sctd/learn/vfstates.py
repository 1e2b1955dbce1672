"""Vector fields used one after the other become states.

The thesis blends all fields of a skill in one state (eqs. 4.31-4.32). Where the
demonstrations use them in sequence -- reach the handle, then pull -- and switch from one
to the next at one place, a state per field tells the user which motion is on and keeps
the fields from mixing where they meet (the end of a reach is the start of a pull).
:func:`plan_states` decides from the fitted learner whether the fields are such a
sequence; each state's way on is a ``distance`` transition: the hand within reach of
where the demonstrations switched. There is no way back by motion (a pull leads away
from the handle); escape (button 2) returns to the previous state.

A plane between the fields' points, as the linear learner learns (eq. 4.17), does not
do here: the demonstrations only show the side of the plane they came from, and a hand
that starts elsewhere (level with the handle, in front of it) can be on the far side of
it before it has reached anything.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
from numpy.typing import NDArray

from .. import se3
from .vf import VectorFieldLearner

Array = NDArray[np.float64]
AXIS_SNAP = math.radians(30)  # an entry direction this near an object axis is that axis


@dataclass(frozen=True)
class FieldTransition:
    """Fires from field ``source``'s state to ``target``'s when the ee position (object
    frame) is within ``radius`` of ``point``, where the demonstrations switched from
    one to the other (``spread``: the RMS distance of their switch points from it)."""

    source: int
    target: int
    point: Array
    radius: float
    spread: float


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


def _goes_back(labels: NDArray[np.int64], order: tuple[int, ...], min_run: int) -> bool:
    """Whether one demonstration's field labels (in time; -1 outliers) return to a field
    after the next one in ``order``: its runs of at least ``min_run`` points, in time,
    out of order."""
    runs: list[int] = []
    start = 0
    lab = labels[labels >= 0]
    for i in range(1, len(lab) + 1):
        if i == len(lab) or lab[i] != lab[start]:
            if i - start >= min_run and (not runs or runs[-1] != lab[start]):
                runs.append(int(lab[start]))
            start = i
    rank = [order.index(m) for m in runs]
    return any(b < a for a, b in pairwise(rank)) or len(set(runs)) < len(runs)


def _demo_times(demo: NDArray[np.int64], sample: NDArray[np.int64]) -> Array:
    """Each point's time in its demonstration (``demo``, ``sample``: which and which
    sample) normalised to [0, 1], so that demonstrations of different lengths weigh
    alike."""
    t = sample.astype(float)
    for k in np.unique(demo):
        sel = demo == k
        t[sel] = (t[sel] - t[sel].min()) / max(1.0, float(np.ptp(t[sel])))
    return t


def _median_times(learner: VectorFieldLearner, t: Array) -> Array:
    """When each demonstration (rows) uses each field (columns): the median normalised
    time ``t`` of its points of the field, NaN where it has fewer than ``coherence_run``."""
    a, demo = learner.assignment_, learner.demo_index_
    K = len(learner.fields_)
    when = np.full((int(demo.max()) + 1, K), np.nan)
    for k in np.unique(demo):
        for m in range(K):
            sel = (demo == k) & (a == m)
            if sel.sum() >= learner.coherence_run:
                when[k, m] = float(np.median(t[sel]))
    return when


def _switch(learner: VectorFieldLearner, t: Array, when: Array, m0: int, m1: int,
            max_spread: float, min_radius: float) -> FieldTransition | str:
    """The transition from field ``m0`` to ``m1`` where the demonstrations that use both
    switch (the first point of ``m1`` after the median time of ``m0``), or why there is
    none."""
    a, demo = learner.assignment_, learner.demo_index_
    both = np.isfinite(when[:, m0]) & np.isfinite(when[:, m1])
    switches = []
    for k in np.flatnonzero(both):
        # Where the next field starts: its first point after the bulk of the one before.
        i1 = np.flatnonzero((demo == k) & (a == m1))
        first = i1[t[i1] >= when[k, m0]]
        if len(first):
            switches.append(learner.points_[first[0]])
    if not switches:
        return f"no demonstration switches from field {m0} to field {m1}"
    S = np.array(switches)
    centre = np.median(S, axis=0)
    spread = float(np.sqrt(np.mean(np.sum((S - centre) ** 2, axis=1))))
    if spread > max_spread:
        return (f"the demonstrations switch from field {m0} to field {m1} in different places "
                f"({spread * 100:.1f} cm apart, RMS)")
    return FieldTransition(m0, m1, centre, max(min_radius, 2.0 * spread), spread)


def plan_states(learner: VectorFieldLearner, min_order: float = 0.9, max_spread: float = 0.03,
                min_radius: float = 0.01) -> StatePlan:
    """Whether the fitted ``learner``'s fields are a sequence, and its transitions.

    Parameters
    ----------
    learner : VectorFieldLearner
        Fitted.
    min_order : float
        In at least this share of the demonstrations that use both, each field's points
        come (by their median time) before the next one's, and in as many no field is
        used again after the next one (its runs of ``coherence_run`` points).
    max_spread : float
        The demonstrations' switch points from one field to the next (the first point of
        the next) must lie within this RMS distance (m) of their median.
    min_radius : float
        The smallest radius (m) of a switch; otherwise twice the switch points' spread.
    """
    if len(learner.fields_) < 2:
        return StatePlan(reason="one field")
    a, demo = learner.assignment_, learner.demo_index_
    t = _demo_times(demo, learner.sample_index_)
    when = _median_times(learner, t)
    used = np.sum(np.isfinite(when), axis=0)
    if np.any(used < 0.5 * when.shape[0]):
        return StatePlan(reason=f"field {int(np.argmin(used))} is used in {int(used.min())} of "
                                f"{when.shape[0]} demonstrations")
    order = tuple(int(m) for m in np.argsort(np.nanmedian(when, axis=0)))
    back = [k for k in np.unique(demo) if _goes_back(a[demo == k], order, learner.coherence_run)]
    if len(back) > (1.0 - min_order) * when.shape[0]:
        return StatePlan(reason=f"{len(back)} of {when.shape[0]} demonstrations go back to a field "
                                "they left")
    timing = {}
    transitions = []
    for m0, m1 in pairwise(order):
        both = np.isfinite(when[:, m0]) & np.isfinite(when[:, m1])
        share = float(np.mean(when[both, m0] < when[both, m1])) if both.any() else 0.0
        timing[f"{m0}->{m1}"] = round(share, 3)
        if share < min_order:
            return StatePlan(reason=f"field {m0} comes before field {m1} in only {share:.0%} of the "
                                    "demonstrations", timing=timing)
        switch = _switch(learner, t, when, m0, m1, max_spread, min_radius)
        if isinstance(switch, str):
            return StatePlan(reason=switch, timing=timing)
        transitions.append(switch)
    return StatePlan(order=order, transitions=tuple(transitions), timing=timing)


def entry_direction(learner: VectorFieldLearner, order: tuple[int, ...], m: int, axis: Array
                    ) -> Array | None:
    """The mean direction (object frame, unit) of the hand's ``axis`` (unit, in the
    frame the fields were learned on) where the demonstrations entered field ``m``'s
    state of a sequence ``order``: at each demonstration's first point of ``m`` after
    the median time of the field before it (its first point of ``m`` for the first
    state). Within ``AXIS_SNAP`` of one of the object's axes, that axis: the turn then
    takes that stick axis exactly onto the pivot's axis at every tilt, so that pushing it
    only moves the pivot along that axis (across a sphere about the pivot) and the other
    two only turn the hand, where a reference a few degrees off (the demonstrations
    entered the pour 6 degrees tilted) mixes a tenth of each into the other. None where
    no demonstration uses ``m`` or the directions cancel."""
    a, demo = learner.assignment_, learner.demo_index_
    t = _demo_times(demo, learner.sample_index_)
    when = _median_times(learner, t)
    i = order.index(m)
    before = order[i - 1] if i > 0 else None
    total = np.zeros(3)
    for k in np.unique(demo):
        idx = np.flatnonzero((demo == k) & (a == m))
        if before is not None and np.isfinite(when[k, before]):
            idx = idx[t[idx] >= when[k, before]]
        if len(idx):
            first = idx[np.argmin(t[idx])]
            total += se3.matrix_from_quaternion(learner.quaternions_[first]) @ axis
    n = float(np.linalg.norm(total))
    if n < 1e-6:
        return None
    return snapped(total / n)


def snapped(d: Array) -> Array:
    """The unit direction ``d``, or the object's axis (signed) it is within
    ``AXIS_SNAP`` of."""
    k = int(np.argmax(np.abs(d)))
    if abs(d[k]) < math.cos(AXIS_SNAP):
        return d
    out = np.zeros(3)
    out[k] = math.copysign(1.0, float(d[k]))
    return out
