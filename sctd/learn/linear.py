"""Linear input mappings from demonstrations (Ch. 4.1, Algorithm 1).

Pipeline (:class:`LinearIMLearner`):

1. Displacements of every candidate feature frame between consecutive (subsampled)
   samples, with the displacement convention of :mod:`sctd.se3`
   (``T_next = Trans(d) T Rot(exp(r))``: ``d`` in the object's axes, ``r`` about the
   frame's own axes) -- exactly what the runtime's linear mapping applies.
2. The label set: the 41 axis-selection matrices (6 one-DoF, 15 two-DoF, 20 three-DoF)
   seen from every frame. A translation-only selection moves every ee-attached frame
   identically, so it is kept once (for ``ee``): ties between frames would otherwise
   make the labelling arbitrary.
3. Cost of each label per displacement (eqs. 4.5-4.14): the least-squares command
   ``u = M^+ d6`` (eq. 4.6), residual ``M u - d6`` (eq. 4.8) measured by the tf-norm
   (eq. 4.9) plus ``beta * DoF``.
4. Segmentation minimising E(f) (eqs. 4.13-4.16) by alpha-beta swap (or expansion) on
   a neighbourhood of temporal successors and spatial neighbours.
5. States (improving on Ch. 6): runs shorter than ``min_segment`` are absorbed, the
   per-demonstration run sequences are merged into one temporal sequence of states
   (the most common number of runs), each state's IM is the majority frame with the
   union of the axes the demonstrations used there, and every demonstration is then
   assigned to those states monotonically by dynamic programming -- so the FSM is one
   chain every demonstration follows.
6. Transitions (Ch. 4.1.5): a linear SVM on positions in the object frame separates
   each pair of consecutive states; the frame whose positions separate best *and*
   which the source state's IM can move across the plane is chosen. Reverse
   transitions share the plane with opposite sign; the margin is the hysteresis.

scikit-learn is imported by the first fit, not with this module: ``sctd`` commands
that never learn do not pay its start-up time.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import cKDTree

from .. import se3
from .demos import dtw
from .graphcut import alpha_beta_swap, alpha_expansion, energy
from .params import SEED, Flag, Interval, OneOf, hyperparameter

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

AXIS_NAMES = ("tx", "ty", "tz", "rx", "ry", "rz")
CUTS = ("swap", "expansion")

Progress = Callable[[str], None]
"""A progress callback: called with the name of each stage as it ends."""

SELECTIONS: tuple[tuple[int, ...], ...] = tuple(
    c for k in (1, 2, 3) for c in itertools.combinations(range(6), k)
)
"""The 41 axis selections (6 + 15 + 20), as tuples of motion-axis indices."""


def selection_matrix(axes: tuple[int, ...]) -> Array:
    """The 6 x k selection matrix M (eq. 4.1) whose column j drives motion axis axes[j]."""
    M = np.zeros((6, len(axes)))
    M[list(axes), np.arange(len(axes))] = 1.0
    return M


def selection_matrices() -> list[Array]:
    """All 41 selection matrices, 1-DoF first (Ch. 4.1)."""
    return [selection_matrix(a) for a in SELECTIONS]


@dataclass(frozen=True)
class IMLabel:
    """One label: a selection of motion axes seen from one feature frame."""

    frame: str
    axes: tuple[int, ...]

    @property
    def dof(self) -> int:
        return len(self.axes)

    @property
    def matrix(self) -> Array:
        return selection_matrix(self.axes)

    @property
    def rotates(self) -> bool:
        return any(a >= 3 for a in self.axes)

    @property
    def name(self) -> str:
        return f"{self.frame}:" + "".join(AXIS_NAMES[a] for a in self.axes)


def label_set(frame_names: list[str]) -> list[IMLabel]:
    """Labels for frames ``frame_names`` (the first is ``ee``): 41 + 34 per extra frame."""
    labels = [IMLabel(frame_names[0], a) for a in SELECTIONS]
    for name in frame_names[1:]:
        labels.extend(IMLabel(name, a) for a in SELECTIONS if any(x >= 3 for x in a))
    return labels


def frame_displacements(T_obj_ee: ArrayLike, T_ee_frame: ArrayLike) -> Array:
    """Displacements [d, r] (n - 1, 6) of a feature frame between consecutive poses.

    Parameters
    ----------
    T_obj_ee : array-like, shape (n, 4, 4)
        End-effector poses in the object frame.
    T_ee_frame : array-like, shape (4, 4)
        The feature frame's fixed offset from the end-effector.
    """
    T = np.asarray(T_obj_ee, dtype=float) @ np.asarray(T_ee_frame, dtype=float)
    return se3.displacement_from_transforms(T[:-1], T[1:])


def least_squares_command(M: ArrayLike, d6: ArrayLike) -> tuple[Array, Array]:
    """Command ``u = M^+ d6`` (eqs. 4.6-4.7) and residual ``M u - d6`` (eq. 4.8).

    Parameters
    ----------
    M : array-like, shape (6, k)
    d6 : array-like, shape (..., 6)

    Returns
    -------
    u : ndarray, shape (..., k)
    residual : ndarray, shape (..., 6)
    """
    M = np.asarray(M, dtype=float)
    d6 = np.asarray(d6, dtype=float)
    u = d6 @ np.linalg.pinv(M).T
    return u, u @ M.T - d6


def im_costs(d6_by_frame: ArrayLike, labels: list[IMLabel], frame_names: list[str],
             alpha: float = 0.4, beta: float = 0.01) -> Array:
    """Cost of every label for every displacement (eq. 4.14), vectorised.

    For a selection matrix the least-squares residual is the unselected part of the
    displacement, so the cost is ``tf_norm(d6 * (1 - mask)) + beta * DoF``.

    Parameters
    ----------
    d6_by_frame : array-like, shape (F, m, 6)
        Displacements of each frame (order of ``frame_names``).
    labels : list of IMLabel, length L
    frame_names : list of str, length F

    Returns
    -------
    ndarray, shape (m, L)
    """
    D = np.asarray(d6_by_frame, dtype=float)
    fidx = np.array([frame_names.index(lab.frame) for lab in labels])
    keep = np.ones((len(labels), 6))
    for j, lab in enumerate(labels):
        keep[j, list(lab.axes)] = 0.0
    res = D[fidx].transpose(1, 0, 2) * keep[None]  # (m, L, 6)
    dof = np.array([lab.dof for lab in labels], dtype=float)
    return se3.tf_norm_of_displacement(res, alpha) + beta * dof[None, :]


def neighbour_graph(poses: ArrayLike, demo_index: ArrayLike, radius: float = 0.04,
                    max_n: int = 10, alpha: float = 0.4) -> tuple[IntArray, Array]:
    """Neighbourhood of displacements (eq. 4.16): temporal successors plus up to
    ``max_n`` spatial neighbours within ``radius`` (m), weights ``exp(-tf-norm)``.

    Parameters
    ----------
    poses : array-like, shape (m, 7)
        Pose (ee, object frame) at the start of each displacement.
    demo_index : array-like, shape (m,)
        Which demonstration each displacement belongs to (consecutive within a demo).

    Returns
    -------
    edges : ndarray, shape (e, 2) of int, each pair once (i < j)
    weights : ndarray, shape (e,)
    """
    P = np.asarray(poses, dtype=float)
    demo = np.asarray(demo_index)
    m = len(P)
    same = demo[1:] == demo[:-1]
    i0 = np.flatnonzero(same)
    pairs = [np.stack([i0, i0 + 1], axis=1)]
    if m > 1 and max_n > 0:
        k = min(max_n + 1, m)
        _dist, idx = cKDTree(P[:, :3]).query(P[:, :3], k=k, distance_upper_bound=radius)
        rows = np.repeat(np.arange(m), k)
        cols = idx.reshape(-1)
        ok = (cols < m) & (cols != rows)
        a, b = rows[ok], cols[ok]
        pairs.append(np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1))
    E = np.unique(np.concatenate(pairs).astype(np.int64), axis=0) if m > 1 else np.zeros((0, 2), int)
    w = np.exp(-_tf_dist(P[E[:, 0]], P[E[:, 1]], alpha)) if len(E) else np.zeros(0)
    return E, w


def dtw_edges(poses_by_demo: list[Array], alpha: float = 0.4) -> tuple[IntArray, Array]:
    """Cross-demonstration neighbours from DTW alignment (Ch. 3.3.1's preprocessing).

    Every demonstration is aligned by DTW (tf-norm local cost) to a reference, the one
    of median length; each matched pair of displacements becomes an edge of the
    smoothness term, so the graph cut prefers to label what the demonstrators did at
    the same stage of the task alike, even where the demonstrations are far apart in
    space (beyond the spatial neighbour radius).

    Parameters
    ----------
    poses_by_demo : list of ndarray, each (m_k, 7)
        Start pose of each displacement, per demonstration, in global order.

    Returns
    -------
    edges : ndarray, shape (e, 2) of int (global displacement indices, i < j)
    weights : ndarray, shape (e,), ``exp(-tf-norm)`` of the matched poses
    """
    if len(poses_by_demo) < 2:
        return np.zeros((0, 2), np.int64), np.zeros(0)
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in poses_by_demo])])
    ref = int(np.argsort([len(p) for p in poses_by_demo])[len(poses_by_demo) // 2])
    pairs = []
    for k, P in enumerate(poses_by_demo):
        if k == ref:
            continue
        _cost, path = dtw(P, poses_by_demo[ref], alpha)
        a, b = path[:, 0] + offsets[k], path[:, 1] + offsets[ref]
        pairs.append(np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1))
    E = np.unique(np.concatenate(pairs).astype(np.int64), axis=0)
    allP = np.concatenate(poses_by_demo)
    return E, np.exp(-_tf_dist(allP[E[:, 0]], allP[E[:, 1]], alpha))


def _tf_dist(a: Array, b: Array, alpha: float) -> Array:
    return (np.linalg.norm(a[:, :3] - b[:, :3], axis=1)
            + alpha * se3.quaternion_angle(a[:, 3:], b[:, 3:]))


@dataclass
class Hyperplane:
    """A learned transition ``source -> target``: fires when
    ``(normal . p + offset) / |normal| > margin`` for the position p of ``frame``."""

    source: int
    target: int
    frame: str
    normal: Array
    offset: float
    margin: float
    accuracy: float
    reachable: bool
    candidates: dict = field(default_factory=dict)


@dataclass
class StateIM:
    """One FSM state: its input mapping (a selection seen from a frame)."""

    label: IMLabel
    support: dict = field(default_factory=dict)  # axis name -> fraction of displacements


class _Laps:
    """Stage timings of a fit, reporting each finished stage to a progress callback."""

    def __init__(self, progress: Progress | None):
        self.progress = progress
        self.timings: dict[str, float] = {}
        self._tick = time.perf_counter()

    def __call__(self, name: str) -> None:
        now = time.perf_counter()
        self.timings[name] = now - self._tick
        self._tick = now
        if self.progress is not None:
            self.progress(name)


def _runs(labels: IntArray) -> list[list[int]]:
    """[start, end (exclusive), label] of each run of equal labels."""
    out: list[list[int]] = []
    for i, lab in enumerate(labels):
        if out and out[-1][2] == lab:
            out[-1][1] = i + 1
        else:
            out.append([i, i + 1, int(lab)])
    return out


def _absorb_short_runs(labels: IntArray, cost: Array, min_len: int) -> IntArray:
    f = labels.copy()
    while True:
        runs = _runs(f)
        if len(runs) <= 1:
            return f
        lengths = [r[1] - r[0] for r in runs]
        k = int(np.argmin(lengths))
        if lengths[k] >= min_len:
            return f
        s, e, _ = runs[k]
        options = [runs[j][2] for j in (k - 1, k + 1) if 0 <= j < len(runs)]
        best = min(options, key=lambda lab: cost[s:e, lab].sum())
        f[s:e] = best


def _monotone_assignment(cost: Array, switch_penalty: float) -> IntArray:
    """Non-decreasing state sequence minimising sum cost[i, s_i] + penalty per switch.

    Parameters
    ----------
    cost : ndarray, shape (m, K)
    """
    m, K = cost.shape
    acc = cost[0].copy()
    back = np.zeros((m, K), dtype=np.int64)
    for i in range(1, m):
        # Best predecessor state j <= k: stay (j == k) or switch (j < k, + penalty).
        cm = np.minimum.accumulate(acc)
        arg = np.array([int(np.argmin(acc[: k + 1])) for k in range(K)])
        switch = cm + switch_penalty
        stay = acc
        use_stay = stay <= switch
        back[i] = np.where(use_stay, np.arange(K), arg)
        acc = np.where(use_stay, stay, switch) + cost[i]
    s = np.empty(m, dtype=np.int64)
    s[-1] = int(np.argmin(acc))
    for i in range(m - 1, 0, -1):
        s[i - 1] = back[i, s[i]]
    return s


def _merge_repeats(states: list[StateIM]) -> list[StateIM]:
    """Consecutive states with the same IM are one state (the first of them)."""
    merged = [states[0]]
    for st in states[1:]:
        if st.label != merged[-1].label:
            merged.append(st)
    return merged


@dataclass
class LinearIMLearner:
    """Learn an FSM of linear input mappings from demonstrations (Algorithm 1).

    Parameters
    ----------
    alpha : float
        Metres per radian in the tf-norm (eq. 4.9); thesis 0.3-0.5.
    beta : float
        Cost per controlled DoF (eq. 4.14); thesis ~0.01.
    smoothness : float
        lambda of eq. 4.16; thesis 0-0.007 (flag ``--lambda``).
    radius : float
        Spatial neighbour radius (m); thesis ~0.04.
    max_n : int
        Spatial neighbours per displacement; thesis 10.
    C : float
        SVM penalty (eq. 4.17); thesis 1000.
    cut : {"swap", "expansion"}
        Graph-cut move (Appendix A.3).
    min_segment : int
        Runs shorter than this many displacements are absorbed by a neighbour run.
    axis_support : float
        Fraction of a state's displacements whose label must use an axis for the
        state's IM to include it.
    margin : float
        Hysteresis margin of the hyperplane transitions (m).
    dtw_align : bool
        Also make DTW-aligned displacements of different demonstrations neighbours in
        the smoothness term (:func:`dtw_edges`).
    auto_frames : bool
        Read by :func:`~sctd.learn.learn_linear`: without given frames, use the ones
        found in the demonstrations (:func:`~sctd.learn.frames.automatic_frames`).
    random_state : int or None
        Seed for the SVM solver (flag ``--seed``).

    Attributes
    ----------
    frame_names_ : list of str
    labels_ : list of IMLabel
    costs_ : list of ndarray, (m_i, L) per demonstration
    graph_labels_ : list of ndarray, (m_i,) graph-cut label per displacement
    energy_ : float
        E(f) of the graph-cut labelling.
    states_ : list of StateIM
    state_labels_ : list of ndarray, (m_i,) state index per displacement
    transitions_ : list of Hyperplane (forward transitions k -> k + 1)
    timings_ : dict
    """

    alpha: float = hyperparameter(0.4, "tf-norm m/rad (eq. 4.9)", valid=Interval(0, 10, open="low"))
    beta: float = hyperparameter(0.01, "cost per DoF (eq. 4.14)", valid=Interval(0, 10))
    smoothness: float = hyperparameter(0.005, "smoothness (eq. 4.16)", flag="--lambda",
                                       valid=Interval(0, 10))
    radius: float = hyperparameter(0.04, "neighbour radius (m)", valid=Interval(0.001, 1))
    max_n: int = hyperparameter(10, "spatial neighbours", valid=Interval(1, 100, integer=True))
    C: float = hyperparameter(1000.0, "SVM penalty (eq. 4.17)", valid=Interval(0, 1e6, open="low"))
    cut: str = hyperparameter("swap", "graph-cut move (alpha-beta swap or alpha-expansion)",
                              choices=CUTS, valid=OneOf(CUTS))
    min_segment: int = hyperparameter(3, "shortest run kept (displacements)",
                                      valid=Interval(1, 1000, integer=True))
    axis_support: float = hyperparameter(
        0.08, "share of a state's net motion an axis needs to be in its IM", valid=Interval(0, 1))
    margin: float = hyperparameter(0.005, "transition hysteresis (m)", valid=Interval(0, 0.1))
    dtw_align: bool = hyperparameter(
        False, "add DTW-aligned displacements of different demos as graph-cut neighbours",
        valid=Flag())
    auto_frames: bool = hyperparameter(
        True, "without --frame, do not look for feature frames in the demonstrations (sphere "
        "centres and cylinder axes fixed in the hand)", flag="--no-auto-frames", valid=Flag())
    random_state: int | None = hyperparameter(
        0, "random seed (default %(default)s)", flag="--seed", metavar="SEED", valid=SEED)

    def fit(self, T_obj_ee: list[ArrayLike], frames: dict[str, ArrayLike] | None = None,
            progress: Progress | None = None) -> LinearIMLearner:
        """Fit on demonstrations.

        Parameters
        ----------
        T_obj_ee : list of array-like, each (n_i, 4, 4)
            Subsampled end-effector poses in the object frame, one array per demo.
        frames : dict of str -> (4, 4), optional
            Candidate feature frames as offsets ``T_ee_frame`` (``ee`` is always a
            candidate and must not be given).
        progress : callable(str), optional
            Called with the stage's name as each stage ends (``costs``,
            ``segmentation``, ``states``, ``transitions``).
        """
        demos = self._check_fit(T_obj_ee, frames)
        lap = _Laps(progress)
        self._fit_costs(demos)
        lap("costs")
        self._fit_segmentation(demos)
        lap("segmentation")
        self._build_states()
        lap("states")
        self._fit_transitions(demos)
        lap("transitions")
        self.timings_ = lap.timings
        return self

    def _check_fit(self, T_obj_ee: list[ArrayLike], frames: dict[str, ArrayLike] | None) -> list[Array]:
        """Validate the inputs; set the frames and the label set."""
        if self.cut not in CUTS:
            raise ValueError(f"cut must be 'swap' or 'expansion', got {self.cut!r}")
        demos = [np.asarray(T, dtype=float) for T in T_obj_ee]
        if not demos or any(len(T) < 2 for T in demos):
            raise ValueError("every demonstration needs at least 2 poses")
        frames = dict(frames or {})
        if "ee" in frames:
            raise ValueError("'ee' is always a candidate frame; do not pass it")
        self.frame_names_ = ["ee", *frames]
        offsets = [np.eye(4)] + [np.asarray(frames[n], dtype=float) for n in frames]
        self.frame_offsets_ = dict(zip(self.frame_names_, offsets, strict=True))
        self.labels_ = label_set(self.frame_names_)
        return demos

    def _fit_costs(self, demos: list[Array]) -> None:
        """Steps 1-3: displacements of every frame and the cost of every label."""
        self.d6_ = [self.displacements(T) for T in demos]
        self.costs_ = [im_costs(D, self.labels_, self.frame_names_, self.alpha, self.beta)
                       for D in self.d6_]

    def _fit_segmentation(self, demos: list[Array]) -> None:
        """Step 4: graph-cut segmentation of all demonstrations jointly."""
        unary = np.concatenate(self.costs_)
        demo_index = np.concatenate([np.full(len(c), k) for k, c in enumerate(self.costs_)])
        start_poses = np.concatenate([se3.pose_from_transform(T[:-1]) for T in demos])
        edges, weights = neighbour_graph(start_poses, demo_index, self.radius, self.max_n,
                                         self.alpha)
        if self.dtw_align:
            per_demo = [se3.pose_from_transform(T[:-1]) for T in demos]
            e2, w2 = dtw_edges(per_demo, self.alpha)
            both = np.concatenate([edges, e2])
            edges, first = np.unique(both, axis=0, return_index=True)
            weights = np.concatenate([weights, w2])[first]
        solve = alpha_beta_swap if self.cut == "swap" else alpha_expansion
        f = solve(unary, edges, weights, self.smoothness)
        self.edges_, self.weights_ = edges, weights
        self.energy_ = energy(unary, edges, weights, self.smoothness, f)
        self.energy_initial_ = energy(unary, edges, weights, self.smoothness,
                                      np.argmin(unary, axis=1))
        splits = np.cumsum([len(c) for c in self.costs_])[:-1]
        self.graph_labels_ = np.split(f, splits)

    # --- states -----------------------------------------------------------------------

    def _build_states(self) -> None:
        """Step 5: the chain of states from the graph-cut runs, then one refinement."""
        cleaned = [_absorb_short_runs(f, c, self.min_segment)
                   for f, c in zip(self.graph_labels_, self.costs_, strict=True)]
        runs = [_runs(f) for f in cleaned]
        counts = np.array([len(r) for r in runs])
        values, freq = np.unique(counts, return_counts=True)
        K = int(values[np.flatnonzero(freq == freq.max())].min())
        ref = [k for k, r in enumerate(runs) if len(r) == K]
        states = [self._state_from_segments([(cleaned[k][runs[k][s][0]:runs[k][s][1]],
                                              self.d6_[k][:, runs[k][s][0]:runs[k][s][1]])
                                             for k in ref])
                  for s in range(K)]
        merged = _merge_repeats(states)
        # Monotone assignment by how well each state's IM explains each displacement:
        # the residual alone (beta * DoF is a constant per state here and, at small
        # sample spacings, as large as the displacement itself).
        assigned = self._assign(merged)
        # One refinement: the assignment's boundaries are sharper than the graph cut's
        # (spatial neighbours pull a few displacements across a phase change), so the
        # states' axes are re-derived from the motion within the assigned runs (each a
        # contiguous run: the assignment is monotone).
        refined = []
        for k, state in enumerate(merged):
            segments = [(gl[sl == k], D[:, sl == k])
                        for gl, sl, D in zip(self.graph_labels_, assigned, self.d6_, strict=True)
                        if np.any(sl == k)]
            refined.append(self._state_from_segments(segments) if segments else state)
        if [st.label for st in refined] != [st.label for st in merged]:
            self.states_ = _merge_repeats(refined)
            self.state_labels_ = self._assign(self.states_)
        else:
            self.states_, self.state_labels_ = refined, assigned

    def _state_from_segments(self, segments: list[tuple[IntArray, Array]]) -> StateIM:
        """A state from the runs the demonstrations spent in it: per run the graph-cut
        labels (r,) and every frame's displacements (F, r, 6)."""
        used: dict[int, int] = {}
        motion: list[list[Array]] = [[] for _ in self.frame_names_]
        for labels, D in segments:
            for lab in labels:
                used[int(lab)] = used.get(int(lab), 0) + 1
            # The run's interior: smoothing blurs the corners between phases.
            trim = min(2, len(labels) // 4)
            for fi in range(len(self.frame_names_)):
                motion[fi].append(D[fi, trim:len(labels) - trim].sum(axis=0))
        return self._state_from_labels(used, motion)

    def _assign(self, states: list[StateIM]) -> list[IntArray]:
        out = []
        for D in self.d6_:
            sc = np.stack([self._residual_of(st.label, D) for st in states], axis=1)
            out.append(_monotone_assignment(sc, self.smoothness))
        return out

    def _residual_of(self, label: IMLabel, D: Array) -> Array:
        return im_costs(D, [label], self.frame_names_, self.alpha, 0.0)[:, 0]

    def _state_from_labels(self, used: dict[int, int], motion: list[list[Array]]) -> StateIM:
        """The state's IM: the frame most of its rotating labels use, and the axes that
        carry at least ``axis_support`` of the demonstrated net motion seen from that
        frame (per demonstration ``|sum of d6|``, rotations times alpha: noise cancels
        in the sum, deliberate motion adds up), at most three."""
        by_frame: dict[str, int] = {}
        for j, n in used.items():
            lab = self.labels_[j]
            # Translation-only labels do not care about the frame.
            if lab.rotates:
                by_frame[lab.frame] = by_frame.get(lab.frame, 0) + n
        n_rot = sum(by_frame.values())
        frame = "ee"
        if by_frame and n_rot >= 0.5 * sum(used.values()):
            frame = max(by_frame, key=lambda k: by_frame[k])
        D = np.array(motion[self.frame_names_.index(frame)])
        mag = np.abs(D).sum(axis=0) * np.array([1, 1, 1, self.alpha, self.alpha, self.alpha])
        support = mag / max(float(mag.sum()), 1e-12)
        axes = [int(a) for a in np.argsort(-support, kind="stable") if support[a] >= self.axis_support]
        axes = sorted(axes[:3]) or [int(np.argmax(support))]
        if not any(a >= 3 for a in axes):
            frame = "ee"
        return StateIM(IMLabel(frame, tuple(axes)),
                       {AXIS_NAMES[a]: round(float(support[a]), 4) for a in range(6)})

    # --- transitions ------------------------------------------------------------------

    def frame_positions(self, T_obj_ee: Array, frame: str) -> Array:
        """Positions (n, 3) in the object frame of an ee-attached frame."""
        off = self.frame_offsets_[frame]
        return T_obj_ee[:, :3, :3] @ off[:3, 3] + T_obj_ee[:, :3, 3]

    def _reachable(self, state: StateIM, frame: str, normal: Array, poses: Array) -> bool:
        """Can the state's IM move ``frame``'s position along ``normal``?"""
        n = normal / np.linalg.norm(normal)
        p_h = self.frame_positions(poses, frame)
        T_f = poses @ self.frame_offsets_[state.label.frame]
        best = 0.0
        for a in state.label.axes:
            if a < 3:
                best = max(best, abs(n[a]))
            else:
                w = T_f[:, :3, a - 3]
                dp = np.cross(w, p_h - T_f[:, :3, 3]).mean(axis=0)
                norm = float(np.linalg.norm(dp))
                if norm >= 0.01:
                    best = max(best, abs(float(n @ dp)) / norm)
        return best >= 0.2

    def _fit_transitions(self, demos: list[Array]) -> None:
        self.transitions_ = []
        for k in range(len(self.states_) - 1):
            h = self.fit_transition(demos, k, k + 1)
            if h is not None:
                self.transitions_.append(h)

    def fit_transition(self, demos: list[Array], source: int, target: int) -> Hyperplane | None:
        """The hyperplane ``source -> target`` (a linear SVM between the two states' poses,
        eq. 4.17, in the frame ``demos`` are in: the object's, or the source state's own
        body's, :mod:`sctd.learn.objects`); None when a state has no pose.

        Parameters
        ----------
        demos : list of ndarray, each (n_i, 4, 4)
            The subsampled poses, labelled by :attr:`state_labels_` (one per displacement:
            its start pose).
        """
        from sklearn.svm import SVC

        sel = [(T[:-1], s) for T, s in zip(demos, self.state_labels_, strict=True)]
        A = np.concatenate([T[s == source] for T, s in sel])
        B = np.concatenate([T[s == target] for T, s in sel])
        if len(A) == 0 or len(B) == 0:
            return None
        # Poses near where the source state meets the target, where the IM must reach the
        # plane: its end on the way forward, its start on the way back.
        ahead = target > source
        tail = np.concatenate([T[s == source][-max(1, (s == source).sum() // 3):] if ahead
                               else T[s == source][:max(1, (s == source).sum() // 3)]
                               for T, s in sel if np.any(s == source)])
        best = None
        cands = {}
        for frame in self.frame_names_:
            X = np.concatenate([self.frame_positions(A, frame), self.frame_positions(B, frame)])
            y = np.concatenate([-np.ones(len(A)), np.ones(len(B))])
            # Metres, as the thesis' C = 1000 assumes (eq. 4.17).
            svm = SVC(kernel="linear", C=self.C, class_weight="balanced", max_iter=1_000_000,
                      random_state=self.random_state)
            svm.fit(X, y)
            w = svm.coef_[0]
            b = float(svm.intercept_[0])
            pred = np.sign(X @ w + b)
            acc = 0.5 * (np.mean(pred[y < 0] < 0) + np.mean(pred[y > 0] > 0))
            reach = self._reachable(self.states_[source], frame, w, tail)
            norm = float(np.linalg.norm(w))
            cands[frame] = {"accuracy": float(acc), "reachable": bool(reach)}
            key = (reach, round(acc, 3), -norm)
            if best is None or key > best[0]:
                best = (key, frame, w / norm, b / norm, acc, reach)
        assert best is not None
        _, frame, n, o, acc, reach = best
        return Hyperplane(source, target, frame, n, float(o), self.margin, float(acc), bool(reach), cands)

    def refit_state(self, k: int, d6: list[Array]) -> None:
        """State ``k``'s IM re-derived, as :meth:`fit` derives it, from displacements seen
        in another frame (the state's own body's, :mod:`sctd.learn.objects`): ``d6`` per
        demonstration (F, m_i, 6), every feature frame's displacements, labelled by
        :attr:`state_labels_`."""
        segments = [(gl[sl == k], D[:, sl == k])
                    for gl, sl, D in zip(self.graph_labels_, self.state_labels_, d6, strict=True)
                    if np.any(sl == k)]
        if segments:
            self.states_[k] = self._state_from_segments(segments)

    def displacements(self, T_obj_ee: Array) -> Array:
        """Every feature frame's displacements (F, n - 1, 6) along poses (n, 4, 4)."""
        return np.stack([frame_displacements(T_obj_ee, self.frame_offsets_[f]) for f in self.frame_names_])
