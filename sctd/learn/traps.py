"""States that trap the user (thesis Ch. 6.2), checked when linear IMs are learned.

"The end-effector could be stuck, without the possibility to transition further": a
state whose input mapping cannot move the transition's frame across the hyperplane
to its successor from where the user enters it. For each learned transition
``k -> k + 1`` the check takes the poses where the demonstrations enter state k and
asks how much of the plane's unit normal n lies in the span of the motions state k's
mapping gives the plane's frame (its position p_h, object frame):

- a translation axis a moves every ee-attached frame along the object's axis e_a
  (learned mappings translate in the object's axes);
- a rotation axis a of the mapping's frame f (its own axes, origin p_f) moves p_h by
  ``w_a x (p_h - p_f)``, w_a the frame's a-th axis; a lever shorter than
  :data:`LEVER` counts as none (the thesis' example: a 1-DoF rotation about the very
  frame the plane is on).

The reach is ``|P n|`` (P the projection onto that span, 0..1); a state whose reach
is below :data:`MIN_REACH` from any entry pose is a trap. Learned states have no active
constraints, so the span is all the mapping can do. A trap with a free input axis
(fewer than three) gets the translation axis along which n is largest (which alone
reaches at least ``sqrt(1 - 2 MIN_REACH^2)``); one without is refused
(:class:`TrapError`). The way back (``k + 1 -> k`` on the same plane) is checked from
where the demonstrations enter ``k + 1`` and reported, not fixed: the runtime's escape
button is the way back (docs/wire-contract.md).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .linear import AXIS_NAMES, Hyperplane, IMLabel, LinearIMLearner, StateIM

Array = NDArray[np.float64]
IntArray = NDArray[np.int64]

MIN_REACH = 0.2  # share of the plane's normal the mapping must reach (as the learner's frame choice)
LEVER = 0.01  # m: a rotation whose lever to the plane's frame is shorter moves it too little


class TrapError(ValueError):
    """A learned state traps the user and has no free input axis to fix it."""


@dataclass(frozen=True)
class TrapFinding:
    """What the check found for state ``state`` and its transition to ``target``.

    ``reach`` is the lowest over the entry poses before any fix, ``added`` the axis the
    fix added (None: none needed), ``way_back`` whether ``target``'s mapping reaches
    the same plane back from where the demonstrations enter it.
    """

    state: int
    target: int
    frame: str
    reach: float
    added: str | None
    way_back: bool

    @property
    def trap(self) -> bool:
        return self.reach < MIN_REACH

    def summary(self, name: Callable[[int], str]) -> dict[str, Any]:
        """Plain data for the learning report; ``name`` turns a state index into its name."""
        return {"state": name(self.state), "to": name(self.target), "frame": self.frame,
                "reach": round(self.reach, 4), "trap": self.trap, "added": self.added,
                "way_back": self.way_back}


def motion_directions(label: IMLabel, T_obj_f: Array, p_h: Array) -> Array:
    """The motions (n, 3, k) of the point ``p_h`` (n, 3; object frame) per unit of each
    of the label's k axes, the mapping's frame at poses ``T_obj_f`` (n, 4, 4)."""
    cols = []
    for a in label.axes:
        if a < 3:
            e = np.zeros((len(p_h), 3))
            e[:, a] = 1.0
            cols.append(e)
        else:
            w = T_obj_f[:, :3, a - 3]
            cols.append(np.cross(w, p_h - T_obj_f[:, :3, 3]))
    return np.stack(cols, axis=2)


def reach(label: IMLabel, offsets: dict[str, Array], frame: str, normal: Array,
          T_obj_ee: Array) -> Array:
    """``|P n|`` (n,) at each pose: how much of the unit ``normal`` (3,) the label's
    motions of ``frame``'s position span, the ee at poses ``T_obj_ee`` (n, 4, 4) and
    ``offsets`` the frames' ``T_ee_frame`` (4, 4)."""
    n = normal / np.linalg.norm(normal)
    T_h = T_obj_ee @ offsets[frame]
    V = motion_directions(label, T_obj_ee @ offsets[label.frame], T_h[:, :3, 3])
    norms = np.linalg.norm(V, axis=1, keepdims=True)  # (n, 1, k)
    V = np.where(norms >= LEVER, V / np.maximum(norms, 1e-300), 0.0)
    if not len(V):
        return np.zeros(0)
    U, s, _ = np.linalg.svd(V, full_matrices=False)  # U (n, 3, k): the span's basis
    along = np.einsum("nik,i->nk", U, n) * (s > 1e-6)
    return np.linalg.norm(along, axis=1)


def entry_poses(T_obj_ee: list[Array], state_labels: list[IntArray], k: int) -> Array:
    """The poses (m, 4, 4) where the demonstrations enter state ``k``: each one's first
    displacement in it (demonstrations that skip it give none)."""
    out = [T[int(np.argmax(s == k))] for T, s in zip(T_obj_ee, state_labels, strict=True)
           if np.any(s == k)]
    return np.stack(out) if out else np.zeros((0, 4, 4))


def _entry_reach(state: StateIM, h: Hyperplane, k: int, offsets: dict[str, Array],
                 T_obj_ee: list[Array], state_labels: list[IntArray]) -> float:
    """The lowest reach of ``state``'s mapping for ``h``'s plane where the demonstrations
    enter state ``k`` (1 when none does)."""
    r = reach(state.label, offsets, h.frame, h.normal, entry_poses(T_obj_ee, state_labels, k))
    return float(r.min()) if len(r) else 1.0


def fixed_state(state: StateIM, h: Hyperplane, lowest: float) -> StateIM | None:
    """``state`` with the missing DoF for ``h`` when its entry reach ``lowest`` makes it
    a trap, else None.

    Raises
    ------
    TrapError
        The state traps the user and already has three input axes.
    """
    if lowest >= MIN_REACH:
        return None
    label = state.label
    if label.dof >= 3:
        raise TrapError(
            f"state s{h.source} ({label.name}) traps the user: from where the demonstrations "
            f"enter it, its input mapping reaches {lowest:.2f} < {MIN_REACH} of the normal of "
            f"the plane to s{h.target} (frame {h.frame}), and it has no free input axis to "
            "add the missing DoF; learn with other candidate frames or hyperparameters")
    free = [a for a in range(3) if a not in label.axes]
    a = max(free, key=lambda j: abs(float(h.normal[j])))
    return StateIM(IMLabel(label.frame, tuple(sorted((*label.axes, a)))), state.support)


def fix_traps(learner: LinearIMLearner, T_obj_ee: Sequence[ArrayLike],
              in_frame_of: Callable[[int], Sequence[ArrayLike]] | None = None) -> list[TrapFinding]:
    """Check every learned transition of a fitted ``learner`` (its demonstrations'
    poses ``T_obj_ee``, each (n_i, 4, 4), as it was fitted on); a trap's state gets the
    missing DoF in ``learner.states_`` and its transition is then ``reachable``.
    ``in_frame_of(k)``, where states are in frames of their own
    (:mod:`sctd.learn.objects`), gives the poses in state k's frame: a transition is
    judged in its source state's.

    Returns
    -------
    list of TrapFinding, one per transition, in order (the way back judged with the
    fixed states).

    Raises
    ------
    TrapError
        A trap that cannot be fixed (its message names the state and the plane).
    """
    poses = [np.asarray(T, dtype=float) for T in T_obj_ee]

    def args(k: int) -> tuple:
        """What a reach is judged on: state k's poses in its own frame."""
        T = poses if in_frame_of is None else [np.asarray(x, dtype=float) for x in in_frame_of(k)]
        return learner.frame_offsets_, T, learner.state_labels_

    states = learner.states_
    found = []
    for h in learner.transitions_:
        lowest = _entry_reach(states[h.source], h, h.source, *args(h.source))
        fixed = fixed_state(states[h.source], h, lowest)
        added = None
        if fixed is not None:
            added = AXIS_NAMES[next(a for a in fixed.label.axes if a not in states[h.source].label.axes)]
            states[h.source] = fixed
            h.reachable = True  # a translation along the normal's largest part reaches it
        found.append((h, lowest, added))
    return [TrapFinding(h.source, h.target, h.frame, lowest, added,
                        _entry_reach(states[h.target], h, h.target, *args(h.target)) >= MIN_REACH)
            for h, lowest, added in found]
