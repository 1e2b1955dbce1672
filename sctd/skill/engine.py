"""Running a skill: the FSM with hysteresis, input mappings and active constraints.

:class:`SkillEngine` runs one skill against its :class:`~sctd.skill.workspace.Workspace`
(frame offsets, KD-trees, what the last command left) and keeps the active state. The
runtime calls, each tick, :meth:`SkillEngine.update` with the measured end-effector
pose (transitions) and :meth:`SkillEngine.command` with the previous target and the
user input (mappings, then constraints). Poses are :class:`~sctd.se3.Flat` transforms
in the skill's object frame; no I/O, no clocks (time is passed in).

The engine also keeps the path that led to the active state, so that an escape press
returns along it (thesis Ch. 6.2: the way out of a state that traps the user), and
measures the progress towards the active state's transitions for the runtime's
:class:`~sctd.skill.stuck.StuckDetector`.

A state entered by a transition may ask the gripper for something
(:class:`~sctd.skill.gripper.GripperAction`, the state's ``gripper``): the engine holds
it until the runtime takes it (:meth:`SkillEngine.take_entry_action`), once per entry.
Starting a state (the skill's start, a swap, a restart: :meth:`SkillEngine.reset`) and
an escape back to a state enter nothing by a transition and ask the gripper for
nothing: what the hand holds stays held.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence, Set

import numpy as np
from numpy.typing import NDArray

from .. import se3
from .constraints import ActiveConstraint, StepLimit
from .gripper import GripperAction
from .model import Skill
from .transitions import MODE_BUTTON, Button, Transition
from .workspace import Workspace

Array = NDArray[np.float64]
Flat = se3.Flat

HISTORY = 64  # states remembered for escape (a path longer than that forgets its start)


class SkillEngine:
    """Active state and workspace of one running skill.

    Parameters
    ----------
    skill : Skill
        The validated skill (immutable, shared).
    """

    def __init__(self, skill: Skill):
        self.skill = skill
        self.workspace = Workspace(skill.limits.speeds, skill.frames, skill.models())
        self._out_of: list[list[Transition]] = [
            [t for t in skill.transitions if t.source == s.name] for s in skill.states]
        # What the stuck detector watches: the transitions whose progress the pose
        # measures (not buttons), none in the end state (the task is done there).
        self._watched: list[tuple[Transition, ...]] = [
            () if s.name == skill.end else tuple(t for t in out if math.isfinite(t.progress_step))
            for s, out in zip(skill.states, self._out_of, strict=True)]
        self._steps = [tuple(t.progress_step for t in w) for w in self._watched]
        # per state: the constraints that move the pose, in order, then those that bound
        # the step (they have the last word on how far a command moves), each with its
        # place among the state's active constraints (for :attr:`acted`)
        self._projected: list[tuple[tuple[int, ActiveConstraint], ...]] = [
            tuple((k, c) for k, c in enumerate(s.active_constraints) if not isinstance(c, StepLimit))
            for s in skill.states]
        self._limits: list[tuple[tuple[int, StepLimit], ...]] = [
            tuple((k, c) for k, c in enumerate(s.active_constraints) if isinstance(c, StepLimit))
            for s in skill.states]
        self._axes: list[tuple[int, ...]] = []
        for s in skill.states:
            axes: set[int] = set()
            for m in s.input_mappings:
                axes |= m.input_axes()
            self._axes.append(tuple(sorted(axes)))
        # per state: the body whose frame it is in (its own object, else the skill's)
        self._objects = tuple(skill.state_object(i) for i in range(len(skill.states)))
        self.index = skill.state_index(skill.start)
        self.entered = 0.0
        # The path that led to the active state (state indices, the newest last).
        self.history: deque[int] = deque(maxlen=HISTORY)
        self.escaped = False  # the last update's change was an escape
        self._disarmed: set[int] = set()  # the active state's guards an escape disarmed
        # Constraint activity since the active state was entered: commands computed, and
        # for each of its active constraints (the skill's order) how many it changed.
        self.entries = 0  # states entered (a new count of activity begins at each)
        self.commands = 0
        self.acted: list[int] = [0] * len(skill.states[self.index].active_constraints)
        # The gripper action of the state a transition entered, until the runtime takes it.
        self.entry_action: GripperAction | None = None

    # --- FSM ---------------------------------------------------------------------------

    @property
    def state(self) -> str:
        return self.skill.states[self.index].name

    @property
    def object(self) -> str:
        """The body whose frame the active state is in (the poses :meth:`update`,
        :meth:`progress` and :meth:`command` take are in its frame): the state's own
        ``object``, else the skill's. It changes with the state: a caller that holds
        poses in the old state's frame re-expresses them (the runtime's controller does,
        from the target's world pose)."""
        return self._objects[self.index]

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

    @property
    def previous(self) -> str | None:
        """The state the active one was entered from (where escape returns), or None."""
        return self.skill.states[self.history[-1]].name if self.history else None

    def leads_to(self, button: int = MODE_BUTTON) -> str | None:
        """The state a press of input button ``button`` enters from the active state (its
        first button transition on that button), or None: the button changes nothing
        here. What a display tells the person of the mode button."""
        for t in self._out_of[self.index]:
            if isinstance(t, Button) and t.button == button:
                return t.target
        return None

    def reset(self, now: float, state: str | None = None) -> None:
        """Enter ``state`` (default: the start state) at time ``now``; a new path for
        escape unless it is the active state already (a re-seed keeps its way back)."""
        index = self.skill.state_index(state or self.skill.start)
        if index != self.index:
            self.history.clear()
            self._disarmed = set()
            self._count_from(index)
        self.index = index
        self.entered = now

    def update(self, F_obj_ee: Flat, now: float, force_obj: Array | None = None,
               pressed: Set[int] = frozenset(), escape: int | None = None,
               grasped: bool | None = None) -> bool:
        """Evaluate the active state's transitions on the measured pose; follow the first
        that fires. Returns True when the state changed (``escaped`` says whether by
        escape).

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
        escape : int, optional
            The escape button: pressed while no button transition of the active state
            takes it, it returns to the state the active one was entered from (thesis
            Ch. 6.2: the way out of a state that traps the user); nothing at the start
            of the path.
        grasped : bool, optional
            Whether the gripper holds something, by the newest state's reading; None
            when the robot reports no gripper or its state is stale (``gripper``
            transitions then never fire).
        """
        self.escaped = False
        self.workspace.grasped = grasped
        # A button press is an event, not a condition: it acts however long the state has
        # been active (the dwell only keeps geometric guards from chattering).
        if pressed:
            for t in self._out_of[self.index]:
                if t.pressed(pressed):
                    return self._enter(t.target, now)
            if escape is not None and escape in pressed and self.history:
                return self._escape(now)
        elapsed = now - self.entered
        if elapsed < self.skill.min_dwell:
            return False
        disarmed = self._disarmed
        for i, t in enumerate(self._out_of[self.index]):
            if t.fires(F_obj_ee, elapsed, force_obj, self.workspace):
                if i not in disarmed:
                    return self._enter(t.target, now)
            elif disarmed:
                disarmed.discard(i)
        return False

    def _escape(self, now: float) -> bool:
        """Back to the state the active one was entered from. The guards that lead from
        there to the state escaped from are disarmed until they have not held once: the
        hand is still where it crossed them, and escape would otherwise be undone at the
        next tick."""
        left = self.state
        self._enter(self.skill.states[self.history[-1]].name, now, act=False)
        self.escaped = True
        self._disarmed = {i for i, t in enumerate(self._out_of[self.index]) if t.target == left}
        return True

    def _enter(self, state: str, now: float, act: bool = True) -> bool:
        """Enter ``state`` by a transition (``act``: its gripper action is to be taken)
        or by an escape."""
        index = self.skill.state_index(state)
        if act:
            self.entry_action = self.skill.states[index].gripper
        if self.history and self.history[-1] == index:
            self.history.pop()  # back the way it came: the path gets shorter
        else:
            self.history.append(self.index)
        self._count_from(index)
        self.index = index
        self.entered = now
        self._disarmed = set()
        return True

    def take_entry_action(self) -> GripperAction | None:
        """The gripper action of the state the last transition entered, once: None
        after it was taken, and when that state has none (module doc)."""
        action, self.entry_action = self.entry_action, None
        return action

    def _count_from(self, index: int) -> None:
        """A new count of constraint activity, for state ``index`` entered."""
        self.entries += 1
        self.commands = 0
        self.acted = [0] * len(self.skill.states[index].active_constraints)

    # --- progress (the stuck detector's view) -------------------------------------------

    @property
    def progress_steps(self) -> tuple[float, ...]:
        """Each watched transition's ``progress_step`` (the order of :meth:`progress`)."""
        return self._steps[self.index]

    def progress(self, F_obj_ee: Flat, now: float, force_obj: Array | None = None
                 ) -> list[float | None]:
        """The progress towards each of the active state's watched transitions (those
        the pose measures; none in the end state), for
        :class:`~sctd.skill.stuck.StuckDetector`. Same parameters as :meth:`update`."""
        elapsed = now - self.entered
        ws = self.workspace
        return [t.progress(F_obj_ee, elapsed, force_obj, ws) for t in self._watched[self.index]]

    # --- command -----------------------------------------------------------------------

    def command(self, F_obj_ee: Flat, u: Array | Sequence[float], dt: float) -> Flat:
        """Apply the active state's input mappings to a pose for input ``u`` over ``dt``
        seconds, then project it onto the state's active constraints, then bound the step
        by its step limits (:class:`~sctd.skill.constraints.StepLimit`: ``speed_near``).

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
        ws.own_turn = False
        for m in state.input_mappings:
            F = m.apply(F, uu, dt, ws)
        ws.turn_axis = turn_axis(F_obj_ee, F) if ws.own_turn and F is not F_obj_ee else None
        G = None  # the constraint frame's pose, reused while F and the frame stay
        frame = None
        acted = self.acted
        self.commands += 1
        for k, c in self._projected[self.index]:
            if c.frame != frame or G is None:
                G, frame = ws.frame_pose(F, c.frame), c.frame
            F_next = c.project(F, G, ws)
            if F_next is not F:
                F, G = F_next, None
                acted[k] += 1
        for k, limit in self._limits[self.index]:
            F_next = limit.limit(F_obj_ee, F, ws, dt)
            if F_next is not F:
                F = F_next
                acted[k] += 1
        ws.turn_budget = math.inf  # a projection outside a command is a whole one
        ws.turn_axis = None
        return F

    def project(self, F_obj_ee: Flat, c: ActiveConstraint) -> Flat:
        """Project a pose (object frame) onto constraint ``c`` of the skill, outside a
        command (so a neighbour orientation turns all the way); F itself when it
        already satisfies c."""
        return c.project(F_obj_ee, self.workspace.frame_pose(F_obj_ee, c.frame), self.workspace)


def turn_axis(A: Flat, B: Flat) -> tuple[float, float, float] | None:
    """The unit axis (in the frame both poses are in) of the turn from pose A's
    orientation to B's, ``R_B R_A^T``; None when they turn less than about 1e-9 rad
    apart. (On floats: it runs every tick.)"""
    # twice the turn's sine times its axis: the antisymmetric part of R_B R_A^T
    x = (B[6] * A[3] + B[7] * A[4] + B[8] * A[5]) - (B[3] * A[6] + B[4] * A[7] + B[5] * A[8])
    y = (B[0] * A[6] + B[1] * A[7] + B[2] * A[8]) - (B[6] * A[0] + B[7] * A[1] + B[8] * A[2])
    z = (B[3] * A[0] + B[4] * A[1] + B[5] * A[2]) - (B[0] * A[3] + B[1] * A[4] + B[2] * A[5])
    n = math.sqrt(x * x + y * y + z * z)
    return None if n < 2e-9 else (x / n, y / n, z / n)
