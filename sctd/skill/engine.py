"""Running a skill: the FSM with hysteresis, input mappings and active constraints.

:class:`SkillEngine` runs one skill against its :class:`~sctd.skill.workspace.Workspace`
(frame offsets, KD-trees, what the last command left) and keeps the active state. The
runtime calls, each tick, :meth:`SkillEngine.update` with the measured end-effector
pose (transitions) and :meth:`SkillEngine.command` with the previous target and the
user input (mappings, then constraints). Poses are :class:`~sctd.se3.Flat` transforms
in the skill's object frame; no I/O, no clocks (time is passed in).
"""

from __future__ import annotations

import math
from collections.abc import Sequence, Set

import numpy as np
from numpy.typing import NDArray

from .. import se3
from .constraints import ActiveConstraint
from .model import Skill
from .transitions import Transition
from .workspace import Workspace

Array = NDArray[np.float64]
Flat = se3.Flat


class SkillEngine:
    """Active state and workspace of one running skill.

    Parameters
    ----------
    skill : Skill
        The validated skill (immutable, shared).
    """

    def __init__(self, skill: Skill):
        self.skill = skill
        self.workspace = Workspace(skill)
        self._out_of: list[list[Transition]] = [
            [t for t in skill.transitions if t.source == s.name] for s in skill.states]
        self._axes: list[tuple[int, ...]] = []
        for s in skill.states:
            axes: set[int] = set()
            for m in s.input_mappings:
                axes |= m.input_axes()
            self._axes.append(tuple(sorted(axes)))
        self.index = skill.state_index(skill.start)
        self.entered = 0.0

    # --- FSM ---------------------------------------------------------------------------

    @property
    def state(self) -> str:
        return self.skill.states[self.index].name

    @property
    def input_axes(self) -> tuple[int, ...]:
        """Indices of the input axes the active state's mappings read: how far the user
        pushes is measured on these alone, so an axis no mapping uses moves nothing."""
        return self._axes[self.index]

    @property
    def finished(self) -> bool:
        return self.state == self.skill.end

    @property
    def last_scale(self) -> float:
        """The vector-field scaling of the last command (1 before any; for status)."""
        return self.workspace.scale

    @property
    def last_membership(self) -> Array | None:
        """The fields' membership ``P(F | p)`` (shape (K,)) the last vector-field command
        used (``P(F | p, u)`` with ``combine: intent``); None before one. Evaluation
        records it next to each command."""
        return self.workspace.membership

    def reset(self, now: float, state: str | None = None) -> None:
        """Enter ``state`` (default: the start state) at time ``now``."""
        self.index = self.skill.state_index(state or self.skill.start)
        self.entered = now

    def update(self, F_obj_ee: Flat, now: float, force_obj: Array | None = None,
               pressed: Set[int] = frozenset()) -> bool:
        """Evaluate the active state's transitions on the measured pose; follow the first
        that fires. Returns True when the state changed.

        Parameters
        ----------
        F_obj_ee : Flat
            Measured end-effector pose in the object frame.
        now : float
            Monotonic time (s).
        force_obj : ndarray, shape (3,), optional
            Measured force at the end-effector, in the object frame (N).
        pressed : set of int
            Input buttons pressed since the last update (rising edges).
        """
        # A button press is an event, not a condition: it acts however long the state has
        # been active (the dwell only keeps geometric guards from chattering).
        if pressed:
            for t in self._out_of[self.index]:
                if t.pressed(pressed):
                    return self._enter(t.target, now)
        elapsed = now - self.entered
        if elapsed < self.skill.min_dwell:
            return False
        for t in self._out_of[self.index]:
            if t.fires(F_obj_ee, elapsed, force_obj, self.workspace):
                return self._enter(t.target, now)
        return False

    def _enter(self, state: str, now: float) -> bool:
        self.index = self.skill.state_index(state)
        self.entered = now
        return True

    # --- command -----------------------------------------------------------------------

    def command(self, F_obj_ee: Flat, u: Array | Sequence[float], dt: float) -> Flat:
        """Apply the active state's input mappings to a pose for input ``u`` over ``dt``
        seconds, then project it onto the state's active constraints.

        Parameters
        ----------
        F_obj_ee : Flat
            The pose to move (the previous target), object frame.
        u : ndarray, shape (k,), or sequence of k floats
            User input in [-1, 1]; axes beyond what a mapping uses are ignored, missing
            axes count as zero.
        dt : float
            Tick period (s).

        Returns
        -------
        Flat
            The new target pose in the object frame (``F_obj_ee`` itself when nothing
            moved it).
        """
        state = self.skill.states[self.index]
        ws = self.workspace
        uu = u.tolist() if isinstance(u, np.ndarray) else u
        # How far a neighbour-orientation correction may turn this tick: as far as the
        # user's push lets the hand turn (the runtime bounds the whole step by the same
        # push), so that turning towards the demonstrations never uses up the step the
        # user's own motion needs, and zero input turns nothing.
        n = len(uu)
        push = min(1.0, math.sqrt(sum(uu[j] * uu[j] for j in self.input_axes if j < n)))
        ws.turn_budget = push * self.skill.limits.max_angular_speed * dt
        F = F_obj_ee
        for m in state.input_mappings:
            F = m.apply(F, uu, dt, ws)
        G = None  # the constraint frame's pose, reused while F and the frame stay
        frame = None
        for c in state.active_constraints:
            if c.frame != frame or G is None:
                G, frame = ws.frame_pose(F, c.frame), c.frame
            F_next = c.project(F, G, ws)
            if F_next is not F:
                F, G = F_next, None
        ws.turn_budget = math.inf  # a projection outside a command is a whole one
        return F

    def project(self, F_obj_ee: Flat, c: ActiveConstraint) -> Flat:
        """Project a pose (object frame) onto constraint ``c`` of the skill, outside a
        command (so a neighbour orientation turns all the way); F itself when it
        already satisfies c."""
        return c.project(F_obj_ee, self.workspace.frame_pose(F_obj_ee, c.frame), self.workspace)
