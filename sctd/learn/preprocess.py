"""Preprocessing of demonstrations before learning: despike, smooth, subsample.

:class:`Preprocessing` holds its hyperparameters; :func:`preprocess` applies them to
every demonstration and keeps which raw rows survived, so that :func:`raw_labels` can
carry what was learned on the subsampled displacements back to every raw one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .demos import Demo, smooth_poses, spike_mask, subsample_by_distance
from .params import Flag, Interval, hyperparameter

Array = NDArray[np.float64]


@dataclass(frozen=True)
class Preprocessing:
    """How demonstrations are cleaned and subsampled (Ch. 4.1.1).

    Parameters
    ----------
    spacing : float
        tf-norm distance between kept samples for linear IMs (m; the learner's
        ``alpha`` metres per radian).
    vf_spacing : float
        Distance between kept positions for vector fields (m).
    smooth : int
        Moving-average window (samples); 1 disables.
    despike : bool
        Drop isolated gross outliers (a Hampel filter, :func:`spike_mask`).
    """

    spacing: float = hyperparameter(0.02, "tf-norm sample spacing for linear IMs (m)",
                                    valid=Interval(0.001, 0.5))
    vf_spacing: float = hyperparameter(0.015, "sample spacing for vector fields (m)",
                                       valid=Interval(0.001, 0.5))
    smooth: int = hyperparameter(5, "moving-average window (samples)", valid=Interval(1, 101, integer=True))
    despike: bool = hyperparameter(True, "keep isolated outlier samples", flag="--no-despike",
                                   valid=Flag())


@dataclass
class Prepared:
    """One preprocessed demonstration: ``keep`` indexes raw rows, ``poses`` (k, 7)."""

    name: str
    n_raw: int
    keep: NDArray[np.int64]
    poses: Array


def preprocess(demos: list[Demo], options: Preprocessing, spacing: float, alpha: float,
               translation_only: bool) -> list[Prepared]:
    """Despike, smooth and subsample every demonstration by distance.

    Parameters
    ----------
    demos : list of Demo
    options : Preprocessing
        Despiking and smoothing.
    spacing : float
        Distance between kept samples (m, tf-norm with ``alpha`` m/rad unless
        ``translation_only``).
    alpha : float
    translation_only : bool
        Measure the spacing by position alone.
    """
    out = []
    for d in demos:
        idx = np.arange(len(d.t))
        if options.despike:
            idx = np.flatnonzero(spike_mask(d.poses))
        P = smooth_poses(d.poses[idx], options.smooth)
        k = subsample_by_distance(P, spacing, alpha, translation_only=translation_only)
        out.append(Prepared(d.name, len(d.t), idx[k], P[k]))
    return out


def raw_labels(prep: Prepared, labels: NDArray[np.int64]) -> list[int]:
    """Per raw displacement (row i -> i + 1) the label of the subsampled displacement
    that spans it."""
    i = np.arange(prep.n_raw - 1)
    j = np.clip(np.searchsorted(prep.keep, i, side="right") - 1, 0, len(labels) - 1)
    return [int(x) for x in np.asarray(labels)[j]]
