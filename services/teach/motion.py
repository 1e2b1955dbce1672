"""Smooth hand motions in the task object's frame, as functions of time (pure numpy).

A motion is ``T_obj_ee(t)`` for ``t`` in ``[0, duration]``: a :class:`Line` (the hand
translated along a curve through a via point while it turns from one orientation to
another), a :class:`TipTurn` (the hand turned about a point fixed in it, the bottle's
opening, about one of its own axes), or motions one after another (:class:`Chain`; a
press, :class:`PressMotion`, is in two parts, with a hold between them). Each runs
along a speed profile in ``tau = t / duration`` (:data:`PROFILES`): from rest to its
mean speed (a demonstration's first step, as :mod:`sctd_sim.demogen`'s: a person does
not stop between carrying and pouring), at its mean speed (a step between two others),
from its mean speed to rest (the last), or rest to rest (minimum jerk, the moves between
demonstrations).

:func:`task_motions` turns a :class:`~sctd_services.teach.plan.DemoPlan` into one
motion per step of the task's intent; :func:`move` is the unrecorded move from anywhere
to a pose.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from sctd import se3
from sctd.task import handle_jacobian, handle_pose
from sctd.task.kinds import Leg
from sctd.task.kinds.joint import Joint

from .plan import PRESS_STANDOFF, DemoPlan, SceneGeometry, Speeds, StepPlan

Array = NDArray[np.float64]


def _from_rest(tau: float) -> float:
    """s(0) = 0, s'(0) = 0, s(1) = 1, s'(1) = 1 (ends at its mean speed; peak 4/3)."""
    return 2.0 * tau * tau - tau ** 3


def _to_rest(tau: float) -> float:
    """s(0) = 0, s'(0) = 1, s(1) = 1, s'(1) = 0 (starts at its mean speed; peak 4/3)."""
    return 1.0 - _from_rest(1.0 - tau)


def _through(tau: float) -> float:
    """s = tau: at its mean speed throughout (a step between two others)."""
    return tau


def _rest_to_rest(tau: float) -> float:
    """Minimum jerk: s, s', s'' zero at both ends (peak speed 15/8 of the mean)."""
    return tau ** 3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)


PROFILES: dict[str, Callable[[float], float]] = {
    "from_rest": _from_rest, "to_rest": _to_rest, "through": _through, "rest_to_rest": _rest_to_rest}
"""Speed profiles ``s(tau)`` by name: the fraction of the motion done at ``tau``."""
PEAK = {"from_rest": 4.0 / 3.0, "to_rest": 4.0 / 3.0, "through": 1.0, "rest_to_rest": 15.0 / 8.0}
"""Each profile's peak speed over its mean."""


class Motion(Protocol):
    """``T_obj_ee(t)`` for ``t`` in ``[0, duration]`` (held at the ends beyond)."""

    @property
    def duration(self) -> float:
        """s"""

    def pose(self, t: float) -> Array:
        """The hand's pose at ``t``, shape (4, 4)."""


def _tau(t: float, duration: float) -> float:
    return min(1.0, max(0.0, t / duration)) if duration > 0 else 1.0


@dataclass(frozen=True)
class Line:
    """The hand along the quadratic through ``a`` (at 0), ``via`` (at ``via_at``) and
    ``b`` (at 1), turning from ``R_a`` to ``R_b`` along the geodesic, both by the profile.

    Attributes
    ----------
    a, via, b : ndarray, shape (3,)
    via_at : float
    R_a, R_b : ndarray, shape (3, 3)
    duration : float
    profile : str
        A name of :data:`PROFILES`.
    """

    a: Array
    via: Array
    via_at: float
    b: Array
    R_a: Array
    R_b: Array
    duration: float
    profile: str

    def position(self, s: float) -> Array:
        """The curve at parameter ``s`` in [0, 1] (Lagrange through the three points)."""
        f = self.via_at
        la = (s - f) * (s - 1.0) / f
        lv = s * (s - 1.0) / (f * (f - 1.0))
        lb = s * (s - f) / (1.0 - f)
        return la * self.a + lv * self.via + lb * self.b

    def pose(self, t: float) -> Array:
        s = PROFILES[self.profile](_tau(t, self.duration))
        w = se3.rotvec_from_matrix(self.R_a.T @ self.R_b)
        return se3.transform_from_rt(self.R_a @ se3.matrix_from_rotvec(s * w), self.position(s))


def line(T_a: Array, T_b: Array, speed: float, turn_rate: float, profile: str,
         via: Array | None = None, via_at: float = 0.5) -> Line:
    """A :class:`Line` from pose ``T_a`` to ``T_b`` (through ``via``, default the
    midpoint) taking as long as its length at mean ``speed`` (m/s) or its turn at mean
    ``turn_rate`` (rad/s) needs, whichever is longer."""
    a, b = T_a[:3, 3], T_b[:3, 3]
    v = a + via_at * (b - a) if via is None else via
    shape = Line(a, v, via_at, b, T_a[:3, :3], T_b[:3, :3], 1.0, profile)
    s = np.linspace(0.0, 1.0, 65)
    pts = np.array([shape.position(x) for x in s])
    length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    angle = se3.angle_between3(T_a[:3, :3], T_b[:3, :3])
    duration = max(length / speed, angle / turn_rate, 1e-3)
    return Line(a, v, via_at, b, T_a[:3, :3], T_b[:3, :3], duration, profile)


@dataclass(frozen=True)
class TipTurn:
    """The hand turned by ``angle`` about its own ``axis`` (unit, hand frame) through the
    point ``pivot`` (hand frame): ``T(s) = T_start T_pivot Rot(axis, s angle) T_pivot^-1``.

    Attributes
    ----------
    T_start : ndarray, shape (4, 4)
    pivot, axis : ndarray, shape (3,)
    angle : float
        rad
    duration : float
    profile : str
    """

    T_start: Array
    pivot: Array
    axis: Array
    angle: float
    duration: float
    profile: str

    def pose(self, t: float) -> Array:
        s = PROFILES[self.profile](_tau(t, self.duration))
        R = se3.matrix_from_rotvec(self.axis * (s * self.angle))
        T_turn = se3.transform_from_rt(R, self.pivot - R @ self.pivot)
        return self.T_start @ T_turn


def task_motions(plan: DemoPlan, geometry: SceneGeometry) -> list[tuple[StepPlan, Motion]]:
    """The motion of each step of ``plan``, in order (each starts where the one before
    ends), as its plan's ``kind`` names it (:class:`~sctd.task.kinds.teaching.StepPlan`):
    a reach is a :class:`Line` through its via point; a tilt a :class:`TipTurn` about the
    frame's point and the hand's y axis; an upright a :class:`TipTurn` bringing the
    frame's axis up; a joint's move a :class:`Line` along a prismatic joint's axis or a
    :class:`HandlePath` along a revolute joint's arc; a press a :class:`PressMotion`;
    another its kind's legs (:class:`LegsMotion`).

    The recorded steps (:attr:`SceneGeometry.recorded`) run as one movement: from rest
    into the first, at their mean speeds through the middle ones, to rest at the end of
    the last; the ones after (uprights) rest to rest at the moves' turn rate. A press ends
    at rest (it held the button), so the step after it starts from rest."""
    V, k, n = geometry.teach, plan.speed, geometry.recorded
    out: list[tuple[StepPlan, Motion]] = []
    here = plan.T_obj_start
    for i, s in enumerate(plan.steps):
        profile = _profile(i, n)
        if i > 0 and plan.steps[i - 1].kind == "press":
            profile = _from_rest_profile(profile)
        m: Motion
        if s.kind == "reach":
            assert s.T_obj_goal is not None and s.via is not None
            m = line(here, s.T_obj_goal, k * V.reach_speed, k * V.turn_rate, profile, s.via, s.via_at)
        elif s.kind == "tilt":
            pivot = geometry.frame(s.frame)[:3, 3].copy()
            angle = s.value - _tilt(here, geometry.frame(s.frame))
            m = TipTurn(here, pivot, np.array([0.0, 1.0, 0.0]), angle, abs(angle) / (k * V.tilt_rate),
                        profile)
        elif s.kind == "upright":
            m = upright(here, geometry.frame(s.frame)[:3, 3], Speeds(), profile if i < n else "rest_to_rest")
        elif s.kind == "press":
            m = press_motion(here, s, geometry, k * V.reach_speed, k * V.press_speed, k * V.turn_rate,
                             profile)
        elif s.kind == "move_joint":
            m = _joint_motion(here, s, geometry, k * V.joint_speed, k * V.turn_rate, profile)
        else:
            m = legs_motion(here, s, geometry, k * V.reach_speed, k * V.turn_rate, plan.mistake)
        out.append((s, m))
        here = s.T_obj_goal if s.T_obj_goal is not None else m.pose(m.duration)
    return out


@dataclass(frozen=True)
class LegsMotion:
    """A step of a registered kind as its legs (:class:`~sctd.task.kinds.Leg`): each a
    rest-to-rest :class:`Line` (object frame), then what the fingers do and the wait its
    leg says (the demonstrator runs them leg by leg)."""

    legs: tuple[tuple[Line, Leg], ...]

    @property
    def duration(self) -> float:
        return sum(line.duration for line, _ in self.legs)

    def pose(self, t: float) -> Array:
        for line, _ in self.legs:
            if t <= line.duration:
                return line.pose(t)
            t -= line.duration
        return self.legs[-1][0].pose(self.legs[-1][0].duration)


def legs_motion(here: Array, s: StepPlan, geometry: SceneGeometry, speed: float, turn_rate: float,
                mistake: bool) -> LegsMotion:
    """The legs of step ``s`` (of a registered kind) from ``here``, planned in the task
    object's frame with the bodies at their defaults in it, drawn from ``s.draw``."""
    action = next(x.action for x in geometry.task.intent if x.name == s.name)
    poses = {n: geometry.body(n) for n in geometry.task.scene.bodies}
    legs = action.legs(geometry.task.scene, poses, here, np.random.default_rng(s.draw), mistake)
    out = []
    for leg in legs:
        out.append((line(here, leg.T_world_ee, leg.speed * speed, leg.speed * turn_rate, "rest_to_rest"),
                    leg))
        here = leg.T_world_ee
    return LegsMotion(tuple(out))


def _profile(i: int, recorded: int) -> str:
    """The speed profile of step ``i`` of a demonstration recording ``recorded`` steps."""
    if i >= recorded or recorded == 1:
        return "rest_to_rest"
    return "from_rest" if i == 0 else "to_rest" if i == recorded - 1 else "through"


def _from_rest_profile(profile: str) -> str:
    """``profile`` starting at rest instead of at its mean speed."""
    return {"through": "from_rest", "to_rest": "rest_to_rest"}.get(profile, profile)


def _tilt(T_obj_ee: Array, T_ee_frame: Array) -> float:
    """How far the frame's z axis is tilted from the vertical, rad."""
    z = T_obj_ee[:3, :3] @ T_ee_frame[:3, 2]
    return math.acos(min(1.0, max(-1.0, float(z[2]))))


def _joint_motion(here: Array, s: StepPlan, geometry: SceneGeometry, speed: float, turn_rate: float,
                  profile: str) -> Motion:
    """The hand taking the joint's handle from 0 to the planned position: along a
    prismatic joint's axis (the handle's x), along a revolute joint's arc (a
    :class:`HandlePath`)."""
    joint = geometry.task.scene.joints[s.joint]
    T_handle = geometry.handle(s.joint)
    if joint.hinge is None:
        T_end = here.copy()
        T_end[:3, 3] += s.value * T_handle[:3, 0]
        return line(here, T_end, speed, turn_rate, profile)
    lever = float(np.linalg.norm(handle_jacobian(joint, T_handle, 0.0)))
    return HandlePath(here, joint, T_handle, s.value, max(lever * abs(s.value) / speed, 1e-3), profile)


@dataclass(frozen=True)
class HandlePath:
    """The hand carrying a joint's handle along its path from 0 to ``end`` (a door's
    handle along its arc), keeping its offset from the handle and its orientation (the
    grasp couples positions only: a person's wrist turns as it must).

    Attributes
    ----------
    T_start : ndarray, shape (4, 4)
        The hand where it grasped the handle (the joint at 0).
    joint : Joint
    T_handle0 : ndarray, shape (4, 4)
        The handle at 0, in the same frame as ``T_start``.
    end : float
        The joint's position at the end, m or rad.
    duration : float
    profile : str
    """

    T_start: Array
    joint: Joint
    T_handle0: Array
    end: float
    duration: float
    profile: str

    def pose(self, t: float) -> Array:
        s = PROFILES[self.profile](_tau(t, self.duration))
        T = self.T_start.copy()
        moved = handle_pose(self.joint, self.T_handle0, s * self.end)[:3, 3] - self.T_handle0[:3, 3]
        T[:3, 3] += moved
        return T


@dataclass(frozen=True)
class Chain:
    """Motions one after another, each starting where the one before ends.

    Attributes
    ----------
    parts : tuple of Motion
    """

    parts: tuple[Motion, ...]

    @property
    def duration(self) -> float:
        return sum(m.duration for m in self.parts)

    def pose(self, t: float) -> Array:
        for m in self.parts[:-1]:
            if t <= m.duration:
                return m.pose(t)
            t -= m.duration
        return self.parts[-1].pose(t)


@dataclass(frozen=True)
class PressMotion:
    """A press: ``inward`` (onto the button's axis in front of its face, then in along
    it to the planned depth) and ``outward`` (back out along it); the demonstrator holds
    between them until the step's predicate holds. As a motion, the two one after the
    other.

    Attributes
    ----------
    inward : Chain
    outward : Line
    """

    inward: Chain
    outward: Line

    @property
    def duration(self) -> float:
        return self.inward.duration + self.outward.duration

    def pose(self, t: float) -> Array:
        return Chain((*self.inward.parts, self.outward)).pose(t)


def press_motion(here: Array, s: StepPlan, geometry: SceneGeometry, speed: float, press_speed: float,
                 turn_rate: float, profile: str) -> PressMotion:
    """Press ``s`` from ``here``: through its via point onto the button's axis (coming to
    rest there; from rest too when ``profile`` starts at rest), in along the button's -x
    by :data:`~.plan.PRESS_STANDOFF` and the planned depth at ``press_speed``, rest to
    rest, and back out at ``speed``."""
    assert s.T_obj_goal is not None and s.via is not None  # (a press's plan has both)
    onto = "rest_to_rest" if profile in ("from_rest", "rest_to_rest") else "to_rest"
    approach = line(here, s.T_obj_goal, speed, turn_rate, onto, s.via, s.via_at)
    T_in = s.T_obj_goal.copy()
    T_in[:3, 3] -= (PRESS_STANDOFF + s.value) * geometry.body(s.button)[:3, 0]
    push = line(s.T_obj_goal, T_in, press_speed, turn_rate, "rest_to_rest")
    return PressMotion(Chain((approach, push)), line(T_in, s.T_obj_goal, speed, turn_rate, "rest_to_rest"))


def move(T_a: Array, T_b: Array, speeds: Speeds | None = None) -> Line:
    """The unrecorded move from ``T_a`` to ``T_b``: straight, rest to rest, at the
    moves' mean speed and turn rate (``speeds``, default :class:`Speeds`)."""
    speeds = speeds or Speeds()
    return line(T_a, T_b, speeds.move, speeds.turn, "rest_to_rest")


def upright(T_obj_ee: Array, pivot: Array, speeds: Speeds | None = None,
            profile: str = "rest_to_rest") -> TipTurn:
    """Turn the frame whose point is ``pivot`` (in the hand's frame) upright about that
    point (which stays where it is) at the moves' turn rate: after a pour, the drops land
    where the stream did. The frame's axis is taken to be the hand's z."""
    speeds = speeds or Speeds()
    pivot = np.asarray(pivot, dtype=float).copy()
    z = T_obj_ee[:3, 2]
    axis_obj = np.cross(z, [0.0, 0.0, 1.0])  # turning about it brings z up
    n = float(np.linalg.norm(axis_obj))
    angle = math.atan2(n, float(z[2]))
    if n < 1e-9:
        return TipTurn(T_obj_ee, pivot, np.array([0.0, 1.0, 0.0]), 0.0, 1e-3, profile)
    axis = T_obj_ee[:3, :3].T @ (axis_obj / n)  # in the hand's frame
    return TipTurn(T_obj_ee, pivot, axis, angle, angle / speeds.turn, profile)
