"""What a demonstration of a task is planned as, step by step (``sctd teach``; pure data).

A step's kind plans its part (:meth:`~sctd.task.kinds.StepKind.plan`) from a
:class:`Draft` (the task's geometry in its object's frame, how the step varies, where
the hand is) and the plan's random numbers, into a :class:`StepPlan`: which of the
demonstrator's motions shows it and what that motion needs. The demonstrator
(``sctd_services.teach``) turns the plans into motions of the arm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from sctd import se3

from .base import Array

if TYPE_CHECKING:  # (typing only)
    from ..model import Predicate, Task, Teach, TeachStep

HAND = "hand"
"""The frame name steps use for the hand (the end-effector)."""


@dataclass(frozen=True)
class SceneGeometry:
    """What planning needs to know about a task, in the task object's frame.

    Attributes
    ----------
    task : Task
    T_obj_start : ndarray, shape (4, 4)
        The scene's start pose of the hand (relative to the task object it does not
        change when the object stands elsewhere).
    """

    task: Task
    T_obj_start: Array

    @property
    def name(self) -> str:
        return self.task.name

    @property
    def teach(self) -> Teach:
        return self.task.teach

    def frame(self, name: str) -> Array:
        """``T_ee_frame`` of a reach's frame: the hand's own, or a held frame."""
        held = self.task.scene.held
        return np.eye(4) if name == HAND or held is None else held.frames[name]

    def handle(self, joint: str) -> Array:
        """``T_obj_handle``: the joint's handle at the joint's 0, in the task object's frame
        (from the file's defaults)."""
        body = self.task.scene.joints[joint].handle
        if body == self.task.object:
            return np.eye(4)
        bodies = self.task.scene.bodies
        return se3.invert_transform(bodies[self.task.object].T_world) @ bodies[body].T_world

    def body(self, name: str) -> Array:
        """``T_obj_body``: a body's pose in the task object's frame (from the file's
        defaults)."""
        bodies = self.task.scene.bodies
        if name == self.task.object:
            return np.eye(4)
        return se3.invert_transform(bodies[self.task.object].T_world) @ bodies[name].T_world

    @property
    def recorded(self) -> int:
        """How many of the intent's steps a demonstration records: up to the last one that
        does not finish the task (:attr:`~sctd.task.kinds.StepKind.finish`: bringing the
        frame upright after the task is a finish, not part of what is shown)."""
        steps = self.task.intent
        return max(i + 1 for i, s in enumerate(steps) if not type(s.action).finish)


def scene_geometry(t: Task) -> SceneGeometry:
    """The geometry of task ``t``."""
    T_world_obj = t.scene.bodies[t.object].T_world
    return SceneGeometry(t, se3.invert_transform(T_world_obj) @ t.scene.start.T_world)


@dataclass(frozen=True)
class Draft:
    """What a step's kind plans its part of a demonstration from.

    Attributes
    ----------
    geometry : SceneGeometry
    name : str
        The step's name.
    vary : TeachStep
        How the task's ``teach`` section varies it.
    here : ndarray (4, 4)
        The hand where the step before ends (or where the demonstration starts), task
        object's frame.
    first : bool
        Whether it is the first step planned.
    mistake : bool
        Whether the demonstrator errs in this demonstration.
    """

    geometry: SceneGeometry
    name: str
    vary: TeachStep
    here: Array
    first: bool
    mistake: bool


@dataclass(frozen=True)
class StepPlan:
    """One step of a demonstration as planned (task object's frame, SI units).

    Attributes
    ----------
    name : str
        The intent step's name (the targets' ``state`` while it runs).
    kind : str
        The demonstrator's motion that shows it: ``reach`` (the hand to ``T_obj_goal``
        through ``via``), ``tilt`` (about the frame's point to ``value`` rad), ``upright``
        (the frame's axis brought up), ``move_joint`` (the handle of ``joint`` along its
        path to ``value``), ``press`` (onto the axis of ``button``'s face at
        ``T_obj_goal``, pushed in ``value`` past it, out again); any other: the legs of
        its step's kind (:meth:`~sctd.task.kinds.StepKind.legs`, drawn from ``draw``).
    frame : str
        The frame it moves.
    T_obj_goal : ndarray (4, 4) or None
        The hand's pose where it ends (a press: where it comes onto the button's axis);
        a plan with one bends through a via point on its way there.
    via : ndarray (3,) or None
        The hand's via point (drawn once every step is planned).
    via_at : float
        Where along the path the via point lies.
    yaw : float
        A reach: its yaw (from facing the object, or from the handle's orientation), rad.
    value : float
        A reach to a point: the goal's height (m); a tilt: its tilt (rad); a joint's
        move: the position it moves the joint to (m or rad); a press: how far past the
        face's rest plane the frame is pushed (m); else nan.
    joint : str
        A reach to a handle, a joint's move: the joint.
    button : str
        A press: the button's body.
    draw : int
        A step shown by its kind's legs: the seed they are drawn from.
    start : ndarray (3, 3) or None
        The hand's orientation where the demonstration starts, when it is the first step
        (a reach's).
    until : Predicate or None
        What the demonstrator holds still for once the motion is done (a tilt until the
        mug is full; a press, pushed in, until the light is on).
    grasped : str
        A reading the demonstrator waits for, true, before the motion (a handle held
        before the joint is moved); empty: none.
    note : str
        What varies in it, in words (its part of the plan's one line).
    quiet : bool
        Left out of the plan's line (a finish: the frame brought upright).
    """

    name: str
    kind: str
    frame: str
    T_obj_goal: Array | None = None
    via: Array | None = None
    via_at: float = 0.5
    yaw: float = 0.0
    value: float = math.nan
    joint: str = ""
    button: str = ""
    draw: int = 0
    start: Array | None = None
    until: Predicate | None = None
    grasped: str = ""
    note: str = ""
    quiet: bool = False

    def describe(self) -> str:
        return f"{self.name}: {self.note}" if self.note else self.name


__all__ = ["HAND", "Draft", "SceneGeometry", "StepPlan", "scene_geometry"]
