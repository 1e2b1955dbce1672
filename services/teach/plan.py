"""What each demonstration will be: the variation a person shows, seeded (pure numpy).

A demonstration follows the task's intent (:mod:`sctd.task`): each step of it becomes
one motion of the hand, planned in the task object's frame (``T_obj_ee``):

- a **reach** moves the step's frame (the hand, or a frame of what it holds such as a
  bottle's opening) to its goal, along a curve through a via point. Towards a point
  (``to``) the hand faces the task object's vertical axis from where it starts (its x
  towards the axis, as at the scene's start) turned by a yaw, and keeps that
  orientation; towards a joint's handle it starts turned by a yaw from the handle's
  orientation and takes the handle's on the way (it grasps it on arrival);
- a **tilt** turns the hand about the frame's point, about the hand's own y axis (the
  top of what it holds towards the object), to the planned tilt, then holds until the
  step's predicate holds;
- an **upright** turns the frame's axis back up about its point;
- a **joint's move** takes the handle along its path (a prismatic joint's axis; a
  revolute joint's arc about its hinge, the hand keeping its orientation) to the
  planned position;
- a **press** brings the step's frame, the hand keeping its orientation, through a via
  point onto the button's axis :data:`PRESS_STANDOFF` in front of its face, pushes it
  in to the planned depth (past the click), holds until the step's predicate holds and
  pulls back out to where it came onto the axis;
- a step of a **registered kind** (a grasp, a place, a turn: :mod:`sctd.task.kinds`)
  runs the legs its kind plans (:meth:`~sctd.task.kinds.StepKind.legs`), drawn from a
  seed the plan draws for it.

Between demonstrations (the task file's ``teach`` section, :class:`~sctd.task.model.Teach`)
the hand starts elsewhere, each reach bends through a different via point, the hand
moves faster or slower, and each step varies as the file says (a reach's yaw and goal
height, a tilt's angle, how far a joint is moved, how far past its click a button is
pushed).

:func:`plan_demonstration` is a pure function of the task, the seed and the attempt's
number: the same seed gives the same variations.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sctd import se3
from sctd.task import Task
from sctd.task.judge import thresholds
from sctd.task.kinds import StepKind
from sctd.task.model import PRESS_MARGIN, MoveJoint, Press, Reach, Teach, TeachStep, Tilt, Upright

Array = NDArray[np.float64]
HAND = "hand"
UP = np.array([0.0, 0.0, 1.0])
PRESS_STANDOFF = 0.03
"""m in front of a button's face where a demonstration comes onto its axis, before it
pushes in along it (and where it pulls back out to)."""


@dataclass(frozen=True)
class Speeds:
    """Speeds of the unrecorded moves between demonstrations (a demonstration's own are
    its task's, :class:`~sctd.task.model.Teach`).

    Attributes
    ----------
    move, turn : float
        Mean speed (m/s) and turn rate (rad/s).
    """

    move: float = 0.12
    turn: float = 0.6


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
        is not an upright (bringing the frame upright after the task is a finish, not part
        of what is shown)."""
        steps = self.task.intent
        return max(i + 1 for i, s in enumerate(steps) if not isinstance(s.action, Upright))


def scene_geometry(t: Task) -> SceneGeometry:
    """The geometry of task ``t``."""
    T_world_obj = t.scene.bodies[t.object].T_world
    return SceneGeometry(t, se3.invert_transform(T_world_obj) @ t.scene.start.T_world)


@dataclass(frozen=True)
class StepPlan:
    """One step of a demonstration as planned (task object's frame, SI units).

    Attributes
    ----------
    name : str
        The intent step's name (the targets' ``state`` while it runs).
    kind : {"reach", "tilt", "upright", "move_joint", "press"}
    frame : str
        The frame it moves (the reach's, or the frame of the reach before it).
    T_obj_goal : ndarray (4, 4) or None
        A reach: the hand's pose where it ends; a press: where it comes onto the button's
        axis (and ends).
    via : ndarray (3,) or None
        A reach, a press: the hand's via point.
    via_at : float
        A reach, a press: where along the path the via point lies.
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
        A step of a registered kind (:mod:`sctd.task.kinds`): the seed its legs' variations
        are drawn from (:meth:`~sctd.task.kinds.StepKind.legs`).
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

    def describe(self) -> str:
        if self.kind == "reach":
            text = f"{self.name}: yaw {self.yaw:+.2f} rad"
            return text + (f", height {self.value:.3f} m" if not math.isnan(self.value) else "")
        if self.kind == "tilt":
            return f"{self.name}: tilt {math.degrees(self.value):.0f} deg"
        if self.kind == "move_joint":
            return f"{self.name}: {self.joint} to {self.value:.3f}"
        if self.kind == "press":
            return f"{self.name}: {self.button} {self.value * 1000:.1f} mm in"
        return self.name


@dataclass(frozen=True)
class DemoPlan:
    """One demonstration as planned (object frame, SI units).

    Attributes
    ----------
    task : str
    attempt : int
        Its number among the attempts (from 1).
    T_obj_start : ndarray, shape (4, 4)
        The hand where the demonstration starts.
    speed : float
        Factor on the task's nominal speeds.
    steps : tuple of StepPlan
        One per step of the intent.
    mistake : bool
        Whether the demonstrator errs in it: every reach misses its goal by its step's
        ``miss`` (a bottle's opening beside the mug, so it spills; a hand beside the
        handle, so it never grasps).
    """

    task: str
    attempt: int
    T_obj_start: Array
    speed: float
    steps: tuple[StepPlan, ...] = field(default=())
    mistake: bool = False

    def step(self, name: str) -> StepPlan:
        return next(s for s in self.steps if s.name == name)

    def describe(self) -> str:
        """One line: what varies in it."""
        p = self.T_obj_start[:3, 3]
        text = f"start ({p[0]:+.3f}, {p[1]:+.3f}, {p[2]:+.3f}) m, speed x{self.speed:.2f}"
        parts = [s.describe() for s in self.steps if s.kind != "upright"]
        return "; ".join([text, *parts]) + (", a mistake" if self.mistake else "")


def plan_demonstration(geometry: SceneGeometry, seed: int, attempt: int, mistake: bool = False
                       ) -> DemoPlan:
    """The seeded variation of attempt ``attempt`` (from 1) of a session seeded ``seed``.

    A pure function: its random numbers come from ``numpy.random.default_rng([seed,
    attempt])``, drawn in a fixed order (the speed, the start, each step's variations in
    the intent's order, then each reach's via point), so the same seed gives the same
    plans, attempt by attempt, whatever came of the earlier attempts; a mistake changes
    nothing but where the reaches end.
    """
    if attempt < 1:
        raise ValueError(f"attempt: must be >= 1, got {attempt}")
    rng = np.random.default_rng([seed, attempt])
    task, V = geometry.task, geometry.teach
    speed = 1.0 + float(rng.uniform(-V.speed, V.speed))
    T_start = geometry.T_obj_start.copy()
    low, high = [-V.start, -V.start, -V.start], [V.start, V.start, V.start]
    if V.start_height is not None:
        low[2], high[2] = V.start_height
    T_start[:3, 3] += rng.uniform(low, high)
    done = thresholds(task.outcome.done)
    steps: list[StepPlan] = []
    here, frame = T_start, HAND  # the hand where the step before ends, and its frame
    for s in task.intent:
        a, var = s.action, V.step(s.name)
        if isinstance(a, Reach):
            frame = a.frame
            T_goal, R, yaw, height = _reach_goal(geometry, a, var.yaw, var.height,
                                                 var.miss if mistake else 0.0, here, rng, first=not steps)
            if not steps:  # the demonstration starts in the first reach's orientation
                T_start[:3, :3] = R
            steps.append(StepPlan(s.name, "reach", frame, T_goal, yaw=yaw, value=height,
                                  joint=a.handle or ""))
            here = T_goal
        elif isinstance(a, Tilt):
            tilt = float(rng.uniform(*var.to)) if var.to is not None else a.to
            steps.append(StepPlan(s.name, "tilt", frame, value=tilt))
        elif isinstance(a, MoveJoint):
            end = float(rng.uniform(*var.to)) if var.to is not None else \
                done[f"{a.joint}.position"] + a.overshoot
            steps.append(StepPlan(s.name, "move_joint", frame, value=end, joint=a.joint))
        elif isinstance(a, Press):
            T_goal, depth = _press_goal(geometry, a, var, mistake, here, rng)
            steps.append(StepPlan(s.name, "press", a.frame, T_goal, value=depth, button=a.button))
            here = T_goal
        elif isinstance(a, StepKind):  # (its legs are drawn where it runs, from this seed)
            steps.append(StepPlan(s.name, a.key, a.frame(), draw=int(rng.integers(2**31))))
        else:
            steps.append(StepPlan(s.name, "upright", frame))
    a_point = T_start[:3, 3]
    with_vias: list[StepPlan] = []
    for p in steps:  # the via points, last: a path's bend varies apart from the rest
        if p.T_obj_goal is not None:  # (a reach)
            b_point = p.T_obj_goal[:3, 3]
            via, via_at = _via_point(a_point, b_point, rng, V)
            p = dataclasses.replace(p, via=via, via_at=via_at)
            a_point = b_point
        with_vias.append(p)
    return DemoPlan(task.name, attempt, T_start, speed, tuple(with_vias), mistake)


def _reach_goal(geometry: SceneGeometry, a: Reach, yaw_range: float, height: tuple[float, float] | None,
                miss: float, here: Array, rng: np.random.Generator, first: bool
                ) -> tuple[Array, Array, float, float]:
    """The hand's pose at the end of reach ``a`` from ``here`` (the hand where it starts),
    the hand's orientation while it goes there, the yaw drawn and the goal's height (nan
    for a handle). Draws the yaw, the height (when varied) and the mistake's direction."""
    yaw = float(rng.uniform(-yaw_range, yaw_range))
    T_ee_f = geometry.frame(a.frame)
    if a.to is not None:  # a point: facing the object's axis from here, turned by the yaw
        R = facing(here[:3, 3], geometry) @ se3.matrix_from_rotvec([0.0, 0.0, yaw])
        goal = a.to.copy()
        if height is not None:
            goal[2] = rng.uniform(*height)
        off = _horizontal(rng) * miss  # drawn always: a mistake changes nothing else
        goal[:2] += off
        return se3.transform_from_rt(R, goal - R @ T_ee_f[:3, 3]), R, yaw, float(goal[2])
    assert a.handle is not None  # (the reader asks for one goal)
    base = geometry.T_obj_start if first else here
    R = base[:3, :3] @ se3.matrix_from_rotvec([0.0, 0.0, yaw])
    T_handle = geometry.handle(a.handle)
    side = miss * float(rng.choice([-1.0, 1.0]))
    T_goal = T_handle @ se3.invert_transform(T_ee_f) if a.frame != HAND else T_handle.copy()
    if side:
        T_goal[:3, 3] += side * T_handle[:3, 1]
    return T_goal, R, yaw, math.nan


def _press_goal(geometry: SceneGeometry, a: Press, var: TeachStep, mistake: bool, here: Array,
                rng: np.random.Generator) -> tuple[Array, float]:
    """The hand's pose where press ``a`` comes onto the button's axis (the frame
    :data:`PRESS_STANDOFF` in front of the face's centre, the hand's orientation kept from
    ``here``; a mistake's beside it by the step's ``miss`` along the body's y) and how far
    past the face it pushes the frame (the button's click depth and a margin drawn from
    the step's). Draws the margin, then the mistake's side."""
    button = geometry.task.scene.bodies[a.button].button
    assert button is not None  # (the reader checks a press names a button)
    depth = button.click + float(rng.uniform(*(var.margin or PRESS_MARGIN)))
    side = var.miss * float(rng.choice([-1.0, 1.0]))  # drawn always: a mistake changes nothing else
    T_obj_button = geometry.body(a.button)
    x, y = T_obj_button[:3, 0], T_obj_button[:3, 1]
    p = T_obj_button[:3, 3] + PRESS_STANDOFF * x + (side if mistake else 0.0) * y
    R = here[:3, :3]
    return se3.transform_from_rt(R, p - R @ geometry.frame(a.frame)[:3, 3]), depth


def facing(p_obj_ee: Array, geometry: SceneGeometry) -> Array:
    """The scene's start orientation turned about the vertical so that the hand at
    ``p_obj_ee`` (object frame) faces the object's vertical axis as the scene's start
    faces it (its x towards the object's axis), shape (3, 3). Spreading the planes of a
    tilt so (each demonstration tilts about a differently yawed axis) is what lets a
    learner tell a sphere about the opening from a cylinder."""
    p0 = geometry.T_obj_start[:3, 3]
    turn = math.atan2(-p_obj_ee[1], -p_obj_ee[0]) - math.atan2(-p0[1], -p0[0])
    return se3.matrix_from_rotvec([0.0, 0.0, turn]) @ geometry.T_obj_start[:3, :3]


def _horizontal(rng: np.random.Generator) -> Array:
    a = float(rng.uniform(-math.pi, math.pi))
    return np.array([math.cos(a), math.sin(a)])


def _via_point(a: Array, b: Array, rng: np.random.Generator, V: Teach) -> tuple[Array, float]:
    """A point a fraction ``f`` (within ``via_at``) of the way from ``a`` to ``b``, off the
    straight path by up to ``via`` along its horizontal normal and along the normal in
    the vertical plane; (point, f)."""
    d = (b - a) / max(float(np.linalg.norm(b - a)), 1e-9)
    side = np.cross([0.0, 0.0, 1.0], d)
    if float(np.linalg.norm(side)) < 1e-6:  # a vertical path: any horizontal direction
        side = np.array([1.0, 0.0, 0.0])
    side /= np.linalg.norm(side)
    up = np.cross(d, side)
    f = float(rng.uniform(*V.via_at))
    off = rng.uniform(-V.via, V.via, 2)
    return a + f * (b - a) + off[0] * side + off[1] * up, f
