"""How a learned segmentation compares with known phases.

For demonstrations whose true phase of every displacement is known (generated ones,
``sctd_sim.demogen``, or labelled by hand): the share of displacements whose learned
state is the right one, and the kind of field each phase was learned as.

Pure functions on plain data. Labels are mappings from a demonstration's name to one
integer per raw displacement (rows ``i -> i + 1``), as the results give them
(:attr:`LinearResult.labels <sctd.learn.LinearResult>`,
:attr:`VectorFieldResult.field_labels <sctd.learn.VectorFieldResult>`) and as
``demogen``'s truth has them (``truth["labels"]``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

Labels = Mapping[str, Sequence[int] | NDArray[np.integer]]


def _aligned(labels: Labels, true_labels: Labels) -> list[tuple[str, NDArray[np.int64], NDArray[np.int64]]]:
    """(name, learned, true) per demonstration of ``true_labels``; ValueError when one is
    missing from ``labels`` or their lengths differ."""
    if not true_labels:
        raise ValueError("true_labels: no demonstrations")
    out = []
    for name, truth in true_labels.items():
        if name not in labels:
            raise ValueError(f"labels: no demonstration {name!r} (it has {sorted(labels)})")
        got, want = np.asarray(labels[name], dtype=np.int64), np.asarray(truth, dtype=np.int64)
        if got.shape != want.shape or got.ndim != 1:
            raise ValueError(f"labels[{name!r}]: shape {got.shape}, its true labels {want.shape}: "
                             "one label per displacement in both")
        out.append((name, got, want))
    return out


def segmentation_accuracy(labels: Labels, true_labels: Labels) -> tuple[float, dict[str, float]]:
    """The share of displacements whose learned state is their true phase.

    Each learned state stands for the phase most of its displacements have (the
    smallest such phase on a tie), so the state numbering need not be the phases'.

    Parameters
    ----------
    labels : mapping of str to sequence of int
        Demonstration name -> learned state per raw displacement (``result.labels``).
    true_labels : mapping of str to sequence of int
        Demonstration name -> true phase per raw displacement; the demonstrations
        scored are these.

    Returns
    -------
    accuracy : float
        Over every displacement of every demonstration, in [0, 1].
    per_demo : dict of str to float
        The same share within each demonstration.

    Raises
    ------
    ValueError
        No demonstrations, one missing from ``labels``, or lengths that differ.
    """
    demos = _aligned(labels, true_labels)
    got = np.concatenate([g for _, g, _ in demos])
    want = np.concatenate([w for _, _, w in demos])
    if len(got) == 0:
        raise ValueError("true_labels: no displacements")
    phase_of = {int(s): int(np.bincount(want[got == s]).argmax()) for s in np.unique(got)}
    right = np.array([phase_of[int(s)] for s in got]) == want
    per_demo, start = {}, 0
    for name, g, _ in demos:
        per_demo[name] = float(np.mean(right[start:start + len(g)]))
        start += len(g)
    return float(np.mean(right)), per_demo


def field_kinds_by_phase(field_labels: Labels, kinds: Sequence[str], true_labels: Labels,
                         n_phases: int | None = None) -> tuple[str | None, ...]:
    """Per true phase, the kind of field most of its displacements were assigned to.

    Parameters
    ----------
    field_labels : mapping of str to sequence of int
        Demonstration name -> index into ``kinds`` per raw displacement, -1 for an
        outlier (``VectorFieldResult.field_labels``).
    kinds : sequence of str
        The kind of each field (``[f.type for f in result.learner.fields_]``).
    true_labels : mapping of str to sequence of int
        Demonstration name -> true phase per raw displacement.
    n_phases : int, optional
        How many phases there are (default: the largest true label + 1).

    Returns
    -------
    tuple of (str or None)
        One entry per phase: the kind with the most votes (the first one counted on a
        tie, demonstrations in ``true_labels``' order), None when every displacement of
        the phase is an outlier.
    """
    demos = _aligned(field_labels, true_labels)
    if n_phases is None:
        n_phases = 1 + max((int(w.max()) for _, _, w in demos if len(w)), default=-1)
    out: list[str | None] = []
    for phase in range(n_phases):
        votes: dict[str, int] = {}
        for _, fl, want in demos:
            for i in fl[(want == phase) & (fl >= 0)]:
                votes[kinds[i]] = votes.get(kinds[i], 0) + 1
        out.append(max(votes, key=votes.__getitem__) if votes else None)
    return tuple(out)
