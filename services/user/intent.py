"""What a person wants the hand to do next: the task file's intent, run on the scene alone.

The intent is written in the task file (``intent``, ``docs/tasks.md``), once per task and
independent of any skill: ordered sub-goals in the task object's frame (reach a region,
tilt until a reading holds, bring the frame upright, move a joint's handle, press a
button).
:class:`TaskIntent` runs them on what a person in the chair sees (the hand, the objects,
the scene's readings: how full the mug is, how far the drawer is open) and says how the
hand should move next, as a desired twist of the end-effector in the world frame, with a
weight matrix saying which components matter. It never looks at the skill, its states or
its mappings.

What belongs to the person rather than to the task (how fast they want the hand to move,
how much a radian of tilt counts against a metre, which way they tilt, how gently they
push a button) are :class:`TaskIntent`'s own parameters.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sctd.task import Task
from sctd.task.kinds import Run, Sight
from sctd.task.model import DONE
from sctd.task.reader import HAND

Array = NDArray[np.float64]


@dataclass
class Observation:
    """What the user sees at time ``t``: the hand and the objects in the world (4x4),
    the task's progress (the scene's outcome fields, its ``readings`` among them), the
    mode the display shows (the skill's active state name) and whether it shows that
    the mode button changes the mode now (``status.mode_button``; True where it says
    nothing of it)."""

    t: float
    T_world_ee: Array
    objects: dict[str, Array]
    scene: dict[str, Any]
    mode: str = ""
    switches: bool = True


@dataclass
class Desire:
    """How the hand should move: ``twist`` [v, w] (world axes, at the ee origin; m/s,
    rad/s), ``W`` (6, 6) the weights of the errors of the frame's twist, as a map from the
    hand's twist (its first three rows weigh where the frame goes, the last three how it
    turns; m/s and rad/s compare), ``error`` a distance to the current sub-goal (progress), ``phase`` the
    intent's own step, ``done`` the task is achieved as far as the user can tell,
    ``close_enough`` the hand is short of the sub-goal but within what the task
    tolerates (a user who cannot get any closer moves on: :meth:`TaskIntent.settle`),
    ``grip`` what the fingers should do (``close``, ``open``; None: as they are)."""

    twist: Array
    W: Array
    error: float
    phase: str
    done: bool = False
    close_enough: bool = False  # the sub-goal is not reached, but within what the task tolerates
    grip: str | None = None  # what the fingers should do: close, open, or None (as they are)


NO_TWIST = np.zeros(6)  # what an observer's desire() holds instead of a twist and weights
NO_WEIGHTS = np.zeros((6, 6))
NO_TWIST.flags.writeable = NO_WEIGHTS.flags.writeable = False


@dataclass
class TaskIntent:
    """Runs the steps of ``task.intent`` for a person who does the task.

    Each step behaves as its kind says (:meth:`~sctd.task.kinds.StepKind.mind`: the minds
    of one run share a :class:`~sctd.task.kinds.Run`, the steps' minds and this person).
    Each call of :meth:`desire` first moves through the steps in order as what is seen
    completes them (a reach within its ``reached`` tolerances or its ``until`` holding; a
    tilt's ``until``; a frame upright below ``below``; a joint past its target), or back
    to the step before (a tilted frame off the goal's vertical by more than ``off_by``,
    checked after ``until``; a handle let go, checked before the joint's target), then
    says what the step it is in wants.

    Parameters
    ----------
    task : Task
    gain : float
        1/s: desired speed per unit error.
    v_max : float
        m/s: the fastest the user wants the moving frame to go.
    w_max : float
        rad/s.
    per_rad : float
        m of error a radian of tilt still to go counts as (progress).
    lean : float
        rad: a frame leaning further than this is tilted the way it leans; one that
        leans less, about the hand's y axis (a lean of a few degrees left over from
        carrying it is no decision to tilt sideways).
    ahead : float
        m: how far ahead along a joint's path (a drawer's axis, a door's arc) the user
        aims while moving its handle.
    past : float
        m: how far along its path past its target a joint's handle must be for the user
        to see it there.
    free_weight : float
        Weight of the hand's angular velocity where its orientation is free (it hardly
        matters).
    press_speed : float
        m/s: how fast the user comes onto a button's face and pushes it in; slower once
        the force is past half the step's bound, not at all at the bound, backing off
        beyond it (``v = press_speed min(1, 2 (1 - F / force))``, at most
        ``press_speed`` back).
    slow : float
        m: within this of a button's face the user comes on at ``press_speed`` only.
    clearance : float
        m: how far in front of a button's face the user brings the frame onto its axis.
    aim : float
        The frame is on a button's axis within this fraction of its face's radius (and,
        once touching it, within the face).

    Attributes
    ----------
    index : int
        The step the user is in; ``len(task.intent)`` once done.
    """

    task: Task
    gain: float = 2.0
    v_max: float = 0.10
    w_max: float = 0.6
    per_rad: float = 0.05
    lean: float = 0.25
    ahead: float = 0.05
    past: float = 1e-3
    free_weight: float = 0.1
    press_speed: float = 0.008
    slow: float = 0.02
    clearance: float = 0.02
    aim: float = 0.5
    index: int = 0
    _run: Run = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        # every step behaves as its kind says; its mind is made with those before it
        self._run = Run(self.task, self)
        for i, s in enumerate(self.task.intent):
            self._run.minds.append(s.action.mind(self._run, i))
        self._surfaces = [n for n, b in self.task.scene.bodies.items() if b.surface is not None]

    @property
    def phase(self) -> str:
        """The name of the step the user is in (``done`` after the last)."""
        steps = self.task.intent
        return steps[self.index].name if self.index < len(steps) else DONE

    def desire(self, obs: Observation, steer: bool = True) -> Desire:
        """What the hand should do now; with ``steer`` False (an observer judging
        progress, which never steers) the twist and the weights are left zero."""
        readings: Mapping[str, Any] = obs.scene.get("readings", {})
        sight = Sight(obs.T_world_ee, obs.objects, readings, self._positions(obs))
        minds = self._run.minds
        for i in range(len(minds)):  # forwards, as far as it goes; back once
            if self.index == i:
                self.index = i + minds[i].move(sight)
        i = self.index
        done = i == len(minds)
        mind = minds[min(i, len(minds) - 1)]  # once done, the last step's (its error, its weights)
        err = mind.error(sight)
        close = not done and mind.close_enough(sight)
        if not steer:
            return Desire(NO_TWIST, NO_WEIGHTS, err, self.phase, done, close)
        want = mind.rest(sight) if done else mind.want(sight)
        self._run.wanted = i
        return Desire(want.twist, want.W, err, self.phase, done, close, want.grip)

    def touching(self, obs: Observation) -> bool:
        """Whether the scene reports the hand pressed against a surface (a wall, a
        button)."""
        readings = obs.scene.get("readings", {})
        return any(readings.get(f"{n}.touching") for n in self._surfaces)

    def settle(self) -> None:
        """Take the step as done although short of its goal (within what it tolerates:
        :attr:`Desire.close_enough`; a reach's ``accept`` region), where its kind says a
        person settles so: on to the next step."""
        minds = self._run.minds
        if self.index < len(minds) and minds[self.index].settle():
            self.index += 1

    @staticmethod
    def _positions(obs: Observation) -> dict[str, Array]:
        out = {n: T[:3, 3] for n, T in obs.objects.items()}
        out[HAND] = obs.T_world_ee[:3, 3]
        return out
