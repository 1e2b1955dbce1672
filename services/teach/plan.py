"""What each demonstration will be: the variation a person shows, seeded (pure numpy).

A demonstration follows the task's intent (:mod:`sctd.task`): each step of it becomes
one motion of the hand, planned by its kind (:meth:`~sctd.task.kinds.StepKind.plan`,
into a :class:`~sctd.task.kinds.teaching.StepPlan`) in the task object's frame
(``T_obj_ee``):

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
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sctd.task.kinds.press import PRESS_STANDOFF
from sctd.task.kinds.reach import facing
from sctd.task.kinds.teaching import Draft, SceneGeometry, StepPlan, scene_geometry
from sctd.task.model import Teach

Array = NDArray[np.float64]
__all__ = ["PRESS_STANDOFF", "DemoPlan", "SceneGeometry", "Speeds", "StepPlan", "facing",
           "plan_demonstration", "scene_geometry"]


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
        parts = [s.describe() for s in self.steps if not s.quiet]
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
    steps: list[StepPlan] = []
    here = T_start  # the hand where the step before ends
    for s in task.intent:  # each step's variations, as its kind draws them
        p = s.action.plan(Draft(geometry, s.name, V.step(s.name), here, not steps, mistake), rng)
        if p.start is not None:  # the demonstration starts in the first reach's orientation
            T_start[:3, :3] = p.start
        steps.append(p)
        here = p.T_obj_goal if p.T_obj_goal is not None else here
    a_point = T_start[:3, 3]
    with_vias: list[StepPlan] = []
    for p in steps:  # the via points, last: a path's bend varies apart from the rest
        if p.T_obj_goal is not None:  # (a reach, a press)
            b_point = p.T_obj_goal[:3, 3]
            via, via_at = _via_point(a_point, b_point, rng, V)
            p = dataclasses.replace(p, via=via, via_at=via_at)
            a_point = b_point
        with_vias.append(p)
    return DemoPlan(task.name, attempt, T_start, speed, tuple(with_vias), mistake)


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
