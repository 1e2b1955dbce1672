"""Moving a frame to a goal: the ``reach`` intent step.

``reach`` (a ``frame``: the hand, or a frame of what it holds) moves the frame to a
goal: a point ``to`` in the task object's frame, or the handle of a joint where the
joint's position has moved it (``handle``), raised while the frame is still far from it
(``lift``); done once the frame is within the ``reached`` tolerances of it or ``until``
holds; a person who cannot get any closer settles within ``accept``. The frame is kept
upright (``orientation: {upright: t}``) or its orientation is free. The steps after a
reach that turn or carry something (a tilt, an upright, a joint's move) move the frame
of the reach before them and hold it at that reach's goal: they find it with
:func:`anchor_of` (as they read) and :func:`anchor_mind` (as they run).

What a simulated person does (:class:`ReachMind`) and how a demonstration shows it (the
hand along a curve through a via point, :meth:`Reach.plan`) are part of the kind; so are
the person's view of a frame against its goal (:class:`Look`) and the hand's twist that
moves a frame so (:func:`frame_want`), which the steps after a reach share.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from sctd import se3

from ..judge import holds
from ..kinematics import handle_pose
from ..model import Outcome, Predicate, Scene, Step
from .base import Array, Floor, Person, Run, Sight, StepKind, StepMind, Want
from .teaching import HAND, Draft, SceneGeometry, StepPlan

if TYPE_CHECKING:  # (typing only)
    from ..model import Task, TeachStep
    from .joint import Joint

UP = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True)
class Lift:
    """A reach's goal raised while the frame is still far from it: by ``height`` times
    ``(radial - start) / span`` clipped to [0, 1], ``radial`` the frame's distance from
    the goal's vertical (m)."""

    height: float
    start: float
    span: float


@dataclass(frozen=True)
class Reached:
    """When a reach is done: the frame within ``radial`` m of the goal's vertical and
    within ``height`` m of the goal's height (either None: not asked)."""

    radial: float | None = None
    height: float | None = None


@dataclass(frozen=True)
class Accept:
    """The region a person who cannot get any closer settles for: within ``radial`` m of
    the goal's vertical, the frame's height in the goal's reference frame strictly
    between ``height`` (m; None: any) and its axis tilted less than ``tilt`` (rad; None:
    any)."""

    radial: float
    height: tuple[float, float] | None = None
    tilt: float | None = None


@dataclass(frozen=True)
class Reach(StepKind):
    """Move ``frame`` (``hand`` or a held frame) to a goal (see the module doc).

    Attributes
    ----------
    frame : str
    to : ndarray, shape (3,), or None
        The goal in the task object's frame, m (the reference frame of ``reached`` and
        ``accept``).
    handle : str or None
        Or a joint: the goal is its handle where the joint's position has moved it
        (:func:`~sctd.task.kinematics.handle_pose`; the reference frame is the handle's
        frame so moved).
    lift : Lift or None
    reached : Reached or None
        The tolerances that complete the step.
    accept : Accept or None
        What a person who cannot get closer settles for.
    until : Predicate or None
        Completes the step as well (the handle grasped).
    upright : float or None
        The frame is kept upright: a tilt of its z axis up to this (rad) is tolerated,
        more is undone, its spin about its own axis does not matter. None: its
        orientation is free.
    """

    key = "reach"
    teaches = ("yaw", "height", "miss")

    frame_name: str
    to: Array | None = None
    handle: str | None = None
    lift: Lift | None = None
    reached: Reached | None = None
    accept: Accept | None = None
    until: Predicate | None = None
    upright: float | None = None

    def __eq__(self, other: object) -> bool:  # (``to`` is an array)
        if not isinstance(other, Reach):
            return NotImplemented
        same_to = (self.to is None and other.to is None) or (
            self.to is not None and other.to is not None and np.array_equal(self.to, other.to))
        return same_to and (self.frame_name, self.handle, self.lift, self.reached, self.accept, self.until,
                            self.upright) == (other.frame_name, other.handle, other.lift, other.reached,
                                              other.accept, other.until, other.upright)

    __hash__ = None  # type: ignore[assignment]

    @classmethod
    def read(cls, r: Any, v: Any, path: str, scene: Scene, outcome: Outcome,
             before: tuple[Step, ...]) -> Reach:
        from ..reader import predicate  # (the reader imports the registry)

        d = r.fields(v, path, {"frame"},
                     {"to", "handle", "lift", "reached", "accept", "until", "orientation"})
        frame = r.string(d["frame"], f"{path}.frame")
        moving = [HAND, *(scene.held.frames if scene.held else ())]
        if frame not in moving:
            raise r.fail(f"{path}.frame", f"expected a frame that moves with the hand, got {frame!r} "
                                          f"(frames: {', '.join(moving)})")
        if ("to" in d) == ("handle" in d):
            raise r.fail(path, "expected one goal: to: [x, y, z] (in the task object's frame) or "
                               "handle: <joint>")
        handle = joint_name(r, d["handle"], f"{path}.handle", scene) if "handle" in d else None
        until = predicate(r, d["until"], f"{path}.until", scene) if "until" in d else None
        reached = _reached(r, d["reached"], f"{path}.reached") if "reached" in d else None
        if reached is None and until is None:
            raise r.fail(path, "expected reached, until or both: what completes the step")
        return cls(frame, r.vector(d["to"], f"{path}.to", 3) if "to" in d else None, handle,
                   _lift(r, d["lift"], f"{path}.lift") if "lift" in d else None, reached,
                   _accept(r, d["accept"], f"{path}.accept") if "accept" in d else None, until,
                   _orientation(r, d.get("orientation", "free"), f"{path}.orientation"))

    def to_yaml(self, scene: Scene) -> dict[str, Any]:
        from ..writer import _angle, _end, _floats, _predicate  # (the writer imports the reader)

        out: dict[str, Any] = {"frame": self.frame_name}
        if self.to is not None:
            out["to"] = _floats(self.to)
        if self.handle is not None:
            out["handle"] = self.handle
        if self.lift is not None:
            out["lift"] = {"height": float(self.lift.height),
                           "between": [float(self.lift.start), _end(self.lift.start, self.lift.span)]}
        if self.reached is not None:
            out["reached"] = {k: float(v) for k in ("radial", "height")
                              if (v := getattr(self.reached, k)) is not None}
        if self.accept is not None:
            out["accept"] = {"radial": float(self.accept.radial)}
            if self.accept.height is not None:
                out["accept"]["height"] = _floats(self.accept.height)
            if self.accept.tilt is not None:
                out["accept"]["tilt"] = _angle(self.accept.tilt)
        if self.until is not None:
            out["until"] = _predicate(self.until, scene)
        if self.upright is not None:  # (None: orientation free, the reader's default)
            out["orientation"] = {"upright": _angle(self.upright)}
        return out

    def read_teach(self, r: Any, d: dict[str, Any], path: str, scene: Scene) -> dict[str, Any]:
        if "height" not in d:
            return {}
        if self.to is None:
            raise r.fail(f"{path}.height", "only a reach to a point (to) has a goal height to vary")
        return {"height": r.pair(d["height"], f"{path}.height")}

    def teach_to_yaml(self, ts: TeachStep, scene: Scene) -> dict[str, Any]:
        return {} if ts.height is None else {"height": [float(x) for x in ts.height]}

    def frame(self) -> str:
        return self.frame_name

    def mind(self, run: Run, index: int) -> StepMind:
        return ReachMind(self, run, index)

    def floor_path(self, task: Task, before: tuple[Floor, ...]) -> Floor:
        """Its frame to its goal (a handle's at the joint's 0), when it is the first step
        that goes anywhere (the floor counts the first way to a goal only)."""
        if any(f.points for f in before):
            return Floor()
        sc = task.scene
        if self.to is not None:
            obj = sc.bodies[task.object].T_world
            goal = obj[:3, :3] @ self.to + obj[:3, 3]
        else:
            assert self.handle is not None  # (the reader asks for one goal)
            goal = sc.bodies[sc.joints[self.handle].handle].T_world[:3, 3]
        return Floor((goal,), frame=self.frame_name, clock="goal")

    def plan(self, draft: Draft, rng: np.random.Generator) -> StepPlan:
        """The hand to the goal through a via point: draws the yaw, the goal's height (when
        varied) and a mistake's direction (:func:`reach_goal`)."""
        var = draft.vary
        T_goal, R, yaw, height = reach_goal(draft.geometry, self, var.yaw, var.height,
                                            var.miss if draft.mistake else 0.0, draft.here, rng, draft.first)
        note = f"yaw {yaw:+.2f} rad" + (f", height {height:.3f} m" if not math.isnan(height) else "")
        return StepPlan(draft.name, "reach", self.frame_name, T_goal, yaw=yaw, value=height,
                        joint=self.handle or "", start=R if draft.first else None, note=note)


# -- reading ------------------------------------------------------------------------------
def joint_name(r: Any, v: Any, path: str, scene: Scene) -> str:
    """A joint of the scene, by name."""
    name = r.string(v, path)
    if name not in scene.joints:
        raise r.fail(path, f"unknown joint {name!r} (joints: {', '.join(scene.joints) or 'none'})")
    return str(name)


def anchor_of(r: Any, key: str, path: str, before: tuple[Step, ...]) -> Reach:
    """The reach before a step of kind ``key`` at ``path`` (whose frame it moves), or the
    error that there is none."""
    anchor = next((s.action for s in reversed(before) if isinstance(s.action, Reach)), None)
    if anchor is None:
        raise r.fail(path, f"a {key} step moves the frame of a reach before it: "
                           + ("the first step must be a reach" if not before else "no reach comes before it"))
    return anchor


def _lift(r: Any, v: Any, path: str) -> Lift:
    d = r.fields(v, path, {"height", "between"})
    start, end = r.pair(d["between"], f"{path}.between")
    if start < 0.0:
        raise r.fail(f"{path}.between", f"distances are >= 0, got {start}")
    return Lift(r.positive(d["height"], f"{path}.height"), start, end - start)


def _reached(r: Any, v: Any, path: str) -> Reached:
    d = r.fields(v, path, set(), {"radial", "height"})
    if not d:
        raise r.fail(path, "expected radial, height or both (m)")
    radial, height = (r.positive(d[k], f"{path}.{k}") if k in d else None for k in ("radial", "height"))
    return Reached(radial, height)


def _accept(r: Any, v: Any, path: str) -> Accept:
    d = r.fields(v, path, {"radial"}, {"height", "tilt"})
    return Accept(r.positive(d["radial"], f"{path}.radial"),
                  r.pair(d["height"], f"{path}.height") if "height" in d else None,
                  r.tilt(d["tilt"], f"{path}.tilt") if "tilt" in d else None)


def _orientation(r: Any, v: Any, path: str) -> float | None:
    """``free`` (None), or ``{upright: <tilt tolerated>}``."""
    if v == "free":
        return None
    if not isinstance(v, dict):
        raise r.fail(path, f"expected free or {{upright: <tilt>}}, got {v!r}")
    d = r.fields(v, path, {"upright"})
    return float(r.tilt(d["upright"], f"{path}.upright"))


# -- the person's view and motion, shared by the steps that hold a reach's frame -------------
@dataclass
class Look:
    """What the person sees of a step's frame and its goal.

    Attributes
    ----------
    p, z : ndarray, shape (3,)
        The frame's position and z axis (world).
    tilt : float
        Of its z axis from the vertical, rad.
    height : float
        Its height in the goal's reference frame (the task object's, or the handle's), m.
    goal_height : float
        The goal's, unlifted, in that frame, m.
    radial : float
        Its distance from the goal's vertical (that frame's z), m. (For a handle, the
        two are worked out only when the steps ask for them; NaN otherwise.)
    goal : tuple of 3 floats
        The goal (world), lifted.
    to_goal : float
        From the frame to the goal, m.
    """

    p: Array
    z: Array
    tilt: float
    height: float
    goal_height: float
    radial: float
    goal: tuple[float, float, float]
    to_goal: float


def saturate(v: Array, limit: float) -> Array:
    n = float(np.linalg.norm(v))
    return v if n <= limit else v * (limit / n)


def _at_point(r: Array) -> Array:
    """The (6, 6) map from a twist [v, w] at the hand's origin to the twist at the point
    ``r`` from it (world axes): ``v_p = v + w x r``. The person's wish is about the frame
    (the bottle's opening): its weights apply there, so that "the position" of a wish
    is where the frame goes, not where the wrist goes while the bottle turns about it."""
    S = np.eye(6)
    S[:3, 3:] = -np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    return S


def frame_weights(person: Person, seen: Look, T_world_ee: Array, spin_free: bool) -> Array:
    """The weights (6, 6) of a wish about the frame ``seen``, as a map from the hand's
    twist: where it goes; how its axis turns when only its axis matters (``spin_free``),
    else its orientation hardly at all."""
    W = np.zeros((6, 6))
    W[:3, :3] = np.eye(3) / person.v_max
    if spin_free:
        W[3:, 3:] = (np.eye(3) - np.outer(seen.z, seen.z)) / person.w_max
    else:
        W[3:, 3:] = np.eye(3) * person.free_weight
    return W @ _at_point(seen.p - T_world_ee[:3, 3])


def frame_want(person: Person, seen: Look, T_world_ee: Array, v: Array, w: Array | None) -> Want:
    """The hand's twist that moves the frame ``seen`` at ``v`` and turns it at ``w``
    (None: its orientation free), with :func:`frame_weights`."""
    W = frame_weights(person, seen, T_world_ee, w is not None)
    if w is None:
        return Want(np.concatenate([v, np.zeros(3)]), W)
    w = saturate(w, person.w_max)
    # the hand's twist that moves the frame so: v_ee = v_frame - w x (p_frame - p_ee)
    v_ee = v - np.cross(w, seen.p - T_world_ee[:3, 3])
    return Want(np.concatenate([v_ee, w]), W)


def uprighting(person: Person, seen: Look, excess: float) -> Array:
    """The angular velocity that brings ``excess`` rad of the frame's tilt back."""
    back = np.cross(seen.z, UP)  # rotating about it brings the axis up
    n = float(np.linalg.norm(back))
    return back / n * person.gain * excess if n > 1e-9 else np.zeros(3)


def _lifted(lift: Lift, radial: float) -> float:
    """How far the goal is raised at ``radial`` m from its vertical."""
    return lift.height * min(1.0, max(0.0, (radial - lift.start) / lift.span))


def lever(joint: Joint) -> float:
    """m of the handle's path per unit of the joint: 1 (prismatic), the handle's distance
    from the hinge line (revolute)."""
    return 1.0 if joint.hinge is None else joint.hinge.lever


def anchor_mind(run: Run, index: int) -> ReachMind:
    """The mind of the reach before step ``index`` (whose frame that step moves)."""
    return next(m for m in reversed(run.minds[:index]) if isinstance(m, ReachMind))


class ReachMind(StepMind):
    """A person moving a frame to a reach's goal; its :meth:`look` is shared by the steps
    that hold the frame there after it (the module doc)."""

    def __init__(self, step: Reach, run: Run, index: int):
        self.step, self.run, self.index = step, run, index
        self.person = run.person
        # whether where the frame is about the goal's vertical is asked for (a tilt after
        # it may ask too: :meth:`ask_placed`)
        self.placed = step.to is not None or bool(step.lift or step.reached or step.accept)

    def ask_placed(self) -> None:
        """A step after it asks where the frame is about the goal's vertical."""
        self.placed = True

    def look(self, sight: Sight) -> Look:
        """The frame against the goal (worked out once a sight)."""
        key = ("reach", self.index)
        if key not in sight.memo:
            sight.memo[key] = self._look(sight)
        return sight.memo[key]

    def _look(self, sight: Sight) -> Look:
        reach, task = self.step, self.run.task
        T_f = sight.T_world_ee if reach.frame_name == HAND else sight.objects[reach.frame_name]
        (_, _, _, tx), (_, _, _, ty), (_, _, zz, tz), _ = T_f.tolist()  # the frame, its axis' z
        here = (tx, ty, tz, 1.0)
        if reach.to is not None:
            T_ref = sight.objects[task.object]
            gx, gy, gz = reach.to.tolist()
            mx, my, height, _ = (self.run.inverse(task.object, T_ref) @ np.array(here)).tolist()
            radial = math.hypot(mx - gx, my - gy)
            lift = 0.0 if reach.lift is None else _lifted(reach.lift, radial)
            wx, wy, wz = (T_ref[:3, :3] @ np.array([gx, gy, gz + lift]) + T_ref[:3, 3]).tolist()
        else:  # the handle where the joint has moved it
            assert reach.handle is not None  # (the reader asks for one goal)
            gz = 0.0
            wx, wy, wz, height, radial = self._at_handle(task.scene.joints[reach.handle], sight, here)
        ex, ey, ez = wx - tx, wy - ty, wz - tz
        tilt = math.acos(max(-1.0, min(1.0, zz)))
        return Look(T_f[:3, 3], T_f[:3, 2], tilt, height, gz, radial, (wx, wy, wz),
                    math.sqrt(ex * ex + ey * ey + ez * ez))

    def _at_handle(self, joint: Joint, sight: Sight, here: tuple[float, float, float, float]
                   ) -> tuple[float, float, float, float, float]:
        """The goal at ``joint``'s handle where the joint has moved it (world, lifted),
        and the frame's height and distance from the goal's vertical in the handle's
        frame so moved (NaN unless :attr:`placed`)."""
        H = sight.objects[joint.handle]
        o = float(sight.readings.get(f"{joint.name}.position", 0.0))
        T = handle_pose(joint, H, o)
        (_, _, c0, wx), (_, _, c1, wy), (_, _, c2, wz), _ = T.tolist()  # its z, origin
        height = radial = math.nan
        if self.placed and joint.hinge is None:  # the frame at 0, moved along its x
            mx, my, height, _ = (self.run.inverse(joint.handle, H) @ np.array(here)).tolist()
            radial = math.hypot(mx - o, my)
        elif self.placed:  # turned: the frame at the handle now
            mx, my, height, _ = (self.run.inverse(joint.name, T) @ np.array(here)).tolist()
            radial = math.hypot(mx, my)
        if self.step.lift is not None:
            lift = _lifted(self.step.lift, radial)
            wx, wy, wz = wx + lift * c0, wy + lift * c1, wz + lift * c2
        return wx, wy, wz, height, radial

    def move(self, sight: Sight) -> int:
        a, seen = self.step, self.look(sight)
        r = a.reached
        if r is not None and (r.radial is None or seen.radial < r.radial) and \
                (r.height is None or abs(seen.height - seen.goal_height) < r.height):
            return 1
        return 1 if a.until is not None and holds(a.until, sight.readings, sight.positions) else 0

    def error(self, sight: Sight) -> float:
        seen = self.look(sight)
        if self.step.upright is None:
            return seen.to_goal
        return seen.to_goal + self.person.per_rad * max(0.0, seen.tilt - self.step.upright)

    def want(self, sight: Sight) -> Want:
        """The frame to its goal; only a tilt beyond what the reach tolerates undone."""
        seen = self.look(sight)
        v = saturate(self.person.gain * (np.array(seen.goal) - seen.p), self.person.v_max)
        if self.step.upright is None:
            return frame_want(self.person, seen, sight.T_world_ee, v, None)
        w = uprighting(self.person, seen, max(0.0, seen.tilt - self.step.upright))
        return frame_want(self.person, seen, sight.T_world_ee, v, w)

    def rest(self, sight: Sight) -> Want:
        seen = self.look(sight)
        W = frame_weights(self.person, seen, sight.T_world_ee, self.step.upright is not None)
        return Want(np.zeros(6), W)

    def close_enough(self, sight: Sight) -> bool:
        c = self.step.accept
        if c is None:
            return False
        seen = self.look(sight)
        return (seen.radial < c.radial and (c.height is None or c.height[0] < seen.height < c.height[1])
                and (c.tilt is None or seen.tilt < c.tilt))

    def settle(self) -> bool:
        return self.step.accept is not None


# -- the demonstration --------------------------------------------------------------------
def reach_goal(geometry: SceneGeometry, a: Reach, yaw_range: float, height: tuple[float, float] | None,
               miss: float, here: Array, rng: np.random.Generator, first: bool
               ) -> tuple[Array, Array, float, float]:
    """The hand's pose at the end of reach ``a`` from ``here`` (the hand where it starts),
    the hand's orientation while it goes there, the yaw drawn and the goal's height (nan
    for a handle). Draws the yaw, the height (when varied) and the mistake's direction."""
    yaw = float(rng.uniform(-yaw_range, yaw_range))
    T_ee_f = geometry.frame(a.frame_name)
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
    T_goal = T_handle @ se3.invert_transform(T_ee_f) if a.frame_name != HAND else T_handle.copy()
    if side:
        T_goal[:3, 3] += side * T_handle[:3, 1]
    return T_goal, R, yaw, math.nan


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
