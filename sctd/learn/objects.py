"""Which body's frame each learned state is in (a state's own ``object``).

A pick-and-place reaches and grasps relative to the item and carries and puts down
relative to where it goes; seen from the item, a carry does not move at all. Where the
demonstrations carry the scene's other bodies (:attr:`sctd.learn.demos.Demo.bodies`),
:func:`choose_objects` picks for every learned state the body in whose frame the
demonstrations' segments of that state are most consistent:

1. the candidates are the task object and every body all demonstrations carry;
2. a body that moves with the hand in the state's segments is never chosen: the hand's
   path in its frame is shorter than ``still_fraction`` of the longest path among the
   candidates (the median over the demonstrations; a carried cup);
3. each remaining candidate's **spread** is the RMS distance of the segments' end
   positions (the hand where each demonstration's last run of the state ends, in that
   body's frame) from their mean, over the demonstrations;
4. the task object stays unless it was excluded or another candidate's spread is
   below ``ratio`` times its own and its own is over ``floor`` (a clearly better frame,
   not noise); otherwise the candidate with the smallest spread wins;
5. a state the demonstrations use in more than one gripper phase (the skill copies it
   into each, :mod:`sctd.learn.gripper`) stays in the frame learned in: one choice
   cannot fit a reach and a carry at once.

Without other bodies every state is in the task object's frame: the choice is the
skill's ``object`` throughout, and nothing about a skill learned from old
demonstrations changes.

The segmentation needs to see the motion: in the frame of a task object the hand
carries (the cup of a pick-and-place), the carry is no motion at all. So before
learning, :func:`learning_frame` looks at the demonstrations' gripper phases (the whole
demonstration without gripper events): where the task object moves with the hand in
one of them, the demonstrations are learned in the frame of a body that moves with it
in none (:func:`rebased`; the one whose frame sees the demonstrations end most alike),
the task object becoming one of the bodies a state may choose. The skill's ``object``
stays the task object; a state in another frame says so.

:func:`reframe_linear` then re-derives a fitted linear learner's states in their own
frames (:meth:`~sctd.learn.linear.LinearIMLearner.refit_state`: the IM's axes from the
displacements seen from the state's body) and its transitions in their source state's
frame (:meth:`~sctd.learn.linear.LinearIMLearner.fit_transition`): a transition is
evaluated in the frame of the state it leaves, so ``k -> k + 1`` is fitted in state k's
and, where state k + 1 is in another body's frame, the way back in state k + 1's. The
segmentation stays as it was learned in the task object's frame. Pure: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .. import se3
from .demos import Demo
from .linear import Hyperplane, LinearIMLearner
from .preprocess import Prepared

Array = NDArray[np.float64]


@dataclass(frozen=True)
class ObjectChoice:
    """One state's choice: the ``object`` chosen, and per candidate its ``spread`` (m)
    of the segments' end positions, or None for a body that moves with the hand there
    (empty: no candidates, or no demonstration's segment shows the state)."""

    state: int
    object: str
    spread: dict[str, float | None]
    shared: bool = False  # used in more than one gripper phase: the frame learned in (rule 5)

    def line(self, name: str) -> str:
        """For a skill file's header: where and why."""
        parts = ", ".join(f"{b} {'moves with the hand' if s is None else f'{s * 100:.1f} cm'}"
                          for b, s in self.spread.items()) or "no demonstration shows the state"
        why = "; in several gripper phases: the frame learned in" if self.shared else ""
        return f"{name}: in the frame of {self.object} (segment ends' spread: {parts}{why})"


def candidate_bodies(demos: list[Demo]) -> tuple[str, ...]:
    """The bodies every demonstration carries, in the first one's order."""
    if not demos:
        return ()
    return tuple(b for b in demos[0].bodies if all(b in d.bodies for d in demos[1:]))


def _runs(labels: list[int], k: int) -> tuple[int, int] | None:
    """(first row, last row) of the last run of displacements labelled ``k`` (row i -> i + 1
    is displacement i), or None."""
    idx = np.flatnonzero(np.asarray(labels) == k)
    if len(idx) == 0:
        return None
    gaps = np.flatnonzero(np.diff(idx) > 1)
    start = int(idx[gaps[-1] + 1]) if len(gaps) else int(idx[0])
    return start, int(idx[-1]) + 1


def choose_objects(demos: list[Demo], labels: dict[str, list[int]], n_states: int, task_object: str,
                   still_fraction: float = 0.2, ratio: float = 0.5, floor: float = 0.005,
                   min_path: float = 0.01, phases: dict[str, list[int]] | None = None) -> list[ObjectChoice]:
    """For each of ``n_states`` learned states, the body whose frame it is in (module doc).

    Parameters
    ----------
    demos : list of Demo
        The raw demonstrations (poses in ``task_object``'s frame).
    labels : dict of str -> list of int
        Per demonstration, the state of each raw displacement (row i -> i + 1).
    n_states : int
    task_object : str
        The skill's ``object``, the demonstrations' own frame.
    still_fraction : float
        A body whose frame sees the hand's path shorter than this fraction of the longest
        candidate's moves with the hand.
    ratio, floor : float
        Another body replaces the task object when its spread is below ``ratio`` times
        the task object's and the task object's is over ``floor`` (m).
    min_path : float
        m: a state whose longest path is shorter than this shows no motion to judge by:
        the task object.
    phases : dict of str -> list of int, optional
        Per demonstration the gripper phase of each raw displacement (rule 5).

    Returns
    -------
    list of ObjectChoice, one per state
    """
    bodies = candidate_bodies(demos)
    out = []
    for k in range(n_states):
        if not bodies:
            out.append(ObjectChoice(k, task_object, {}))
            continue
        ends: dict[str, list[Array]] = {b: [] for b in (task_object, *bodies)}
        paths: dict[str, list[float]] = {b: [] for b in ends}
        for d in demos:
            run = _runs(labels[d.name], k)
            if run is None:
                continue
            first, last = run
            for b in ends:
                P = (d.poses if b == task_object else d.poses_in(b))[first:last + 1, :3]
                ends[b].append(P[-1])
                paths[b].append(float(np.sum(np.linalg.norm(np.diff(P, axis=0), axis=1))))
        choice = _choose(k, task_object, ends, paths, still_fraction, ratio, floor, min_path)
        if phases is not None and len({p for d in demos for p, lab in zip(phases[d.name], labels[d.name],
                                                                          strict=True) if lab == k}) > 1:
            choice = ObjectChoice(k, task_object, choice.spread, shared=True)
        out.append(choice)
    return out


def _choose(k: int, task_object: str, ends: dict[str, list[Array]], paths: dict[str, list[float]],
            still_fraction: float, ratio: float, floor: float, min_path: float) -> ObjectChoice:
    """One state's choice from its segments' end positions and path lengths per body."""
    if not ends[task_object]:  # no demonstration shows the state: nothing to judge by
        return ObjectChoice(k, task_object, {})
    path = {b: float(np.median(p)) for b, p in paths.items()}
    longest = max(path.values())
    spread: dict[str, float | None] = {}
    for b, e in ends.items():
        E = np.asarray(e)
        moving = longest >= min_path and path[b] < still_fraction * longest
        spread[b] = None if moving else float(np.sqrt(np.mean(np.sum((E - E.mean(axis=0)) ** 2, axis=1))))
    if longest < min_path:
        return ObjectChoice(k, task_object, spread)
    ranked = sorted((s, b) for b, s in spread.items() if s is not None)
    own = spread[task_object]
    if not ranked:
        return ObjectChoice(k, task_object, spread)
    best_spread, best = ranked[0]
    if own is not None and (own <= floor or best_spread >= ratio * own):
        best = task_object
    return ObjectChoice(k, best, spread)


def poses_in_frames(prepared: list[Prepared], demos: list[Demo], body: str, task_object: str) -> list[Array]:
    """The subsampled poses (n_i, 4, 4) of every prepared demonstration in ``body``'s
    frame (the task object's: as prepared), ``T_body_ee = T_obj_body^-1 T_obj_ee`` with
    the body's pose at each kept raw row."""
    by_name = {d.name: d for d in demos}
    out = []
    for p in prepared:
        T = se3.transform_from_pose(p.poses)
        if body != task_object:
            T = np.linalg.inv(se3.transform_from_pose(by_name[p.name].bodies[body][p.keep])) @ T
        out.append(T)
    return out


def reframe_linear(learner: LinearIMLearner, prepared: list[Prepared], demos: list[Demo],
                   objects: list[str], task_object: str) -> tuple[dict[int, Hyperplane], list[list[Array]]]:
    """Re-derive a fitted ``learner``'s states and transitions in each state's frame
    (``objects[k]``, module doc); nothing changes where every state is in the task
    object's.

    Returns
    -------
    back : dict of int -> Hyperplane
        The way back ``k + 1 -> k`` by k, where it is in another frame than ``k -> k + 1``
        (elsewhere the way back is the same plane, the other way).
    poses : list of list of ndarray
        Per state, the subsampled poses in its frame (what a trap is judged on).
    """
    frames = {b: poses_in_frames(prepared, demos, b, task_object) for b in dict.fromkeys(objects)}
    for k, b in enumerate(objects):
        if b != task_object:
            learner.refit_state(k, [learner.displacements(T) for T in frames[b]])
    back: dict[int, Hyperplane] = {}
    for i, h in enumerate(learner.transitions_):
        a, t = objects[h.source], objects[h.target]
        if a != task_object:
            learner.transitions_[i] = learner.fit_transition(frames[a], h.source, h.target) or h
        if a != t:
            way_back = learner.fit_transition(frames[t], h.target, h.source)
            if way_back is not None:
                back[h.source] = way_back
    return back, [frames[b] for b in objects]


def _moves_with_hand(demos: list[Demo], segments: dict[str, list[tuple[int, int]]], body: str,
                     frames: tuple[str, ...], own: str, still_fraction: float, min_path: float) -> bool:
    """Whether ``body`` moves with the hand in one of the segments (rows first..last per
    demonstration, the same count in each): the median hand path in its frame is below
    ``still_fraction`` of the longest among ``frames`` (``own``: the demonstrations' own)."""
    n = len(next(iter(segments.values())))
    for i in range(n):
        paths: dict[str, list[float]] = {b: [] for b in frames}
        for d in demos:
            first, last = segments[d.name][i]
            for b in frames:
                P = (d.poses if b == own else d.poses_in(b))[first:last + 1, :3]
                paths[b].append(float(np.sum(np.linalg.norm(np.diff(P, axis=0), axis=1))))
        med = {b: float(np.median(p)) for b, p in paths.items()}
        longest = max(med.values())
        if longest >= min_path and med[body] < still_fraction * longest:
            return True
    return False


def learning_frame(demos: list[Demo], task_object: str, phases: dict[str, list[int]] | None = None,
                   still_fraction: float = 0.2, min_path: float = 0.01) -> str:
    """The frame to learn in (module doc): ``task_object``, unless the demonstrations
    carry other bodies and the task object moves with the hand in one of the phases
    (``phases``: per demonstration the phase of each raw displacement, as
    :class:`~sctd.learn.gripper.GripperPlan` has them; None: one phase); then the body
    that moves with the hand in no phase and whose frame sees the demonstrations' last
    poses closest together (the task object when there is none)."""
    bodies = candidate_bodies(demos)
    if not bodies:
        return task_object
    segments: dict[str, list[tuple[int, int]]] = {}
    for d in demos:
        ph = np.asarray(phases[d.name]) if phases is not None else np.zeros(len(d) - 1, dtype=int)
        segments[d.name] = [(int(np.flatnonzero(ph == p)[0]), int(np.flatnonzero(ph == p)[-1]) + 1)
                            for p in range(int(ph.max()) + 1) if np.any(ph == p)]
    if len({len(v) for v in segments.values()}) != 1:
        return task_object
    frames = (task_object, *bodies)

    def moves(b: str) -> bool:
        return _moves_with_hand(demos, segments, b, frames, task_object, still_fraction, min_path)

    if not moves(task_object):
        return task_object
    still = [b for b in bodies if not moves(b)]
    if not still:
        return task_object

    def end_spread(b: str) -> float:
        E = np.array([d.poses_in(b)[-1, :3] for d in demos])
        return float(np.sqrt(np.mean(np.sum((E - E.mean(axis=0)) ** 2, axis=1))))

    return min(still, key=end_spread)


def rebased(demos: list[Demo], base: str, task_object: str) -> list[Demo]:
    """The demonstrations in ``base``'s frame (one of their bodies): the hand's poses
    ``T_base_ee``, and the bodies' poses in it, the task object among them
    (``T_base_obj``); the gripper's columns as they were."""
    out = []
    for d in demos:
        T_base_obj = np.linalg.inv(se3.transform_from_pose(d.bodies[base]))
        bodies = {task_object: _canonical(se3.pose_from_transform(T_base_obj))}
        for b, P in d.bodies.items():
            if b != base:
                bodies[b] = _canonical(se3.pose_from_transform(T_base_obj @ se3.transform_from_pose(P)))
        out.append(Demo(d.name, d.t, d.poses_in(base), d.width, d.grasped, bodies))
    return out


def _canonical(P: Array) -> Array:
    """Poses (n, 7) with qw >= 0."""
    P = np.array(P)
    P[:, 3:] *= np.where(P[:, 6:7] < 0.0, -1.0, 1.0)
    return P
