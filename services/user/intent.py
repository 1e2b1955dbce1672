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

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sctd import se3
from sctd.task import Task, handle_jacobian, handle_pose
from sctd.task.judge import holds, thresholds
from sctd.task.kinds import Sight, StepKind, StepMind
from sctd.task.kinds.joint import Joint
from sctd.task.model import (
    DONE,
    Action,
    AllOf,
    AnyOf,
    Lift,
    MoveJoint,
    Near,
    Not,
    Predicate,
    Press,
    Reach,
    Tilt,
    Upright,
)
from sctd.task.reader import HAND

Array = NDArray[np.float64]
UP = np.array([0.0, 0.0, 1.0])


@dataclass
class Observation:
    """What the user sees at time ``t``: the hand and the objects in the world (4x4),
    the task's progress (the scene's outcome fields, its ``readings`` among them) and the
    mode the display shows (the skill's active state name)."""

    t: float
    T_world_ee: Array
    objects: dict[str, Array]
    scene: dict[str, Any]
    mode: str = ""


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


def _at_point(r: Array) -> Array:
    """The (6, 6) map from a twist [v, w] at the hand's origin to the twist at the point
    ``r`` from it (world axes): ``v_p = v + w x r``. The person's wish is about the frame
    (the bottle's opening): its weights apply there, so that "the position" of a wish
    is where the frame goes, not where the wrist goes while the bottle turns about it."""
    S = np.eye(6)
    S[:3, 3:] = -np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    return S


def _saturate(v: Array, limit: float) -> Array:
    n = float(np.linalg.norm(v))
    return v if n <= limit else v * (limit / n)


def _lifted(lift: Lift, radial: float) -> float:
    """How far the goal is raised at ``radial`` m from its vertical."""
    return lift.height * min(1.0, max(0.0, (radial - lift.start) / lift.span))


def _lever(joint: Joint) -> float:
    """m of the handle's path per unit of the joint: 1 (prismatic), the handle's distance
    from the hinge line (revolute)."""
    return 1.0 if joint.hinge is None else joint.hinge.lever


def _has_near(p: Predicate | None) -> bool:
    """Whether ``p`` asks where a frame is (and so needs the frames' positions)."""
    if isinstance(p, Near):
        return True
    if isinstance(p, AllOf | AnyOf):
        return any(_has_near(t) for t in p.terms)
    return isinstance(p, Not) and _has_near(p.term)


@dataclass
class _Look:
    """What the person sees of a reach's frame and its goal.

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


@dataclass
class TaskIntent:
    """Runs the steps of ``task.intent`` for a person who does the task.

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
    _axis: tuple[int, Array] | None = field(default=None, repr=False)  # (step, axis) being tilted about
    _inverses: dict[str, tuple[bytes, Array]] = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        steps = self.task.intent
        self._anchors: list[int] = []  # per step (and done): the reach whose frame it moves
        for i, s in enumerate(steps):  # (a press may come first: it names its own frame)
            self._anchors.append(i if isinstance(s.action, Reach) or not self._anchors else self._anchors[-1])
        self._anchors.append(self._anchors[-1])
        done = thresholds(self.task.outcome.done)  # (the reader checks a moved joint has one)
        # per step: the readings a tilt waits for, a joint's position to move it to
        self._waits = [thresholds(s.action.until) if isinstance(s.action, Tilt) else {} for s in steps]
        self._ends = [done[f"{s.action.joint}.position"] + s.action.overshoot
                      if isinstance(s.action, MoveJoint) else 0.0 for s in steps]
        self._pasts = [self.past / _lever(self.task.scene.joints[s.action.joint])  # (the joint's unit)
                       if isinstance(s.action, MoveJoint) else 0.0 for s in steps]
        self._near = any(_has_near(getattr(s.action, k, None)) for s in steps for k in ("until", "back"))
        # the reaches whose frame's place about the goal's vertical is asked for
        self._placed = {self._anchors[i] for i, s in enumerate(steps)
                        if (isinstance(s.action, Tilt) and s.action.off_by is not None)
                        or (isinstance(s.action, Reach) and (s.action.to is not None or s.action.lift
                                                             or s.action.reached or s.action.accept))}
        self._surfaces = [n for n, b in self.task.scene.bodies.items() if b.surface is not None]
        # a step of a registered kind behaves as its kind says
        self._minds: dict[int, StepMind] = {i: s.action.mind(self.task.scene, steps, self)
                                            for i, s in enumerate(steps) if isinstance(s.action, StepKind)}

    @property
    def phase(self) -> str:
        """The name of the step the user is in (``done`` after the last)."""
        steps = self.task.intent
        return steps[self.index].name if self.index < len(steps) else DONE

    def desire(self, obs: Observation, steer: bool = True) -> Desire:
        """What the hand should do now; with ``steer`` False (an observer judging
        progress, which never steers) the twist and the weights are left zero."""
        readings: Mapping[str, Any] = obs.scene.get("readings", {})
        positions = self._positions(obs) if self._near or self._minds else {}
        sight = Sight(obs.T_world_ee, obs.objects, readings, positions) if self._minds else None
        looks: dict[int, _Look] = {}

        def look(i: int) -> _Look:
            a = self._action(i)
            if isinstance(a, Press):  # its own frame, against its button
                if -1 - i not in looks:
                    looks[-1 - i] = self._press_look(a, obs, readings)
                return looks[-1 - i]
            k = self._anchors[i]
            if k not in looks:
                looks[k] = self._look(self._reach(k), k in self._placed, obs, readings)
            return looks[k]

        for i in range(len(self.task.intent)):  # forwards, as far as it goes; back once
            if self.index == i:
                if i in self._minds:
                    assert sight is not None
                    self.index = i + self._minds[i].move(sight)
                else:
                    self.index = i + self._move(i, self._action(i), look(i), readings, positions)
        i = self.index
        if self._last(i) in self._minds:
            assert sight is not None
            return self._kind_desire(i, sight, obs, steer)
        seen = look(i)
        err = self._error(i, seen, obs, readings)
        done = i == len(self.task.intent)
        close = self._close(seen)
        if not steer:
            return Desire(NO_TWIST, NO_WEIGHTS, err, self.phase, done, close)
        W = self._weights(i, seen) @ _at_point(seen.p - obs.T_world_ee[:3, 3])
        return Desire(self._twist(i, seen, obs, readings), W, err, self.phase, done, close)

    def _kind_desire(self, i: int, sight: Sight, obs: Observation, steer: bool) -> Desire:
        """What a step of a registered kind wants (once done, the last step's error, no motion)."""
        mind = self._minds[self._last(i)]
        err = mind.error(sight)
        done = i == len(self.task.intent)
        if not steer:
            return Desire(NO_TWIST, NO_WEIGHTS, err, self.phase, done)
        if done:
            return Desire(np.zeros(6), np.eye(6), err, self.phase, True)
        want = mind.want(sight)
        return Desire(want.twist, want.W, err, self.phase, False, False, want.grip)

    def touching(self, obs: Observation) -> bool:
        """Whether the scene reports the hand pressed against a surface (a wall, a
        button)."""
        readings = obs.scene.get("readings", {})
        return any(readings.get(f"{n}.touching") for n in self._surfaces)

    def settle(self) -> None:
        """Take the reach as done although short of its goal (the frame is within its
        ``accept`` region: :attr:`Desire.close_enough`): on to the next step. Nothing
        else is settled for."""
        steps = self.task.intent
        if self.index < len(steps):
            a = steps[self.index].action
            if isinstance(a, Reach) and a.accept is not None:
                self.index += 1

    # -- what is seen --------------------------------------------------------------------

    def _reach(self, k: int) -> Reach:
        a = self.task.intent[k].action
        assert isinstance(a, Reach)  # (anchors are reaches)
        return a

    def _last(self, i: int) -> int:
        """Step ``i``, or once done the last step (whose error and weights it keeps)."""
        return min(i, len(self.task.intent) - 1)

    def _action(self, i: int) -> Action:
        a = self.task.intent[self._last(i)].action
        assert not isinstance(a, StepKind)  # (a registered kind's step is its mind's: _kind_desire)
        return a

    @staticmethod
    def _positions(obs: Observation) -> dict[str, Array]:
        out = {n: T[:3, 3] for n, T in obs.objects.items()}
        out[HAND] = obs.T_world_ee[:3, 3]
        return out

    def _joint_position(self, joint: str, readings: Mapping[str, Any]) -> float:
        return float(readings.get(f"{joint}.position", 0.0))

    def _inverse(self, name: str, T: Array) -> Array:
        """``T`` inverted, worked out again only when the frame ``name`` moved."""
        key = T.tobytes()
        kept = self._inverses.get(name)
        if kept is None or kept[0] != key:
            kept = self._inverses[name] = (key, se3.invert_transform(T))
        return kept[1]

    def _look(self, reach: Reach, placed: bool, obs: Observation, readings: Mapping[str, Any]) -> _Look:
        """The reach's frame against its goal (see :class:`_Look`; ``placed``: where the
        frame is about the goal's vertical is asked for)."""
        T_f = obs.T_world_ee if reach.frame == HAND else obs.objects[reach.frame]
        (_, _, _, tx), (_, _, _, ty), (_, _, zz, tz), _ = T_f.tolist()  # the frame, its axis' z
        here = (tx, ty, tz, 1.0)
        if reach.to is not None:
            T_ref = obs.objects[self.task.object]
            gx, gy, gz = reach.to.tolist()
            mx, my, height, _ = (self._inverse(self.task.object, T_ref) @ np.array(here)).tolist()
            radial = math.hypot(mx - gx, my - gy)
            lift = 0.0 if reach.lift is None else _lifted(reach.lift, radial)
            wx, wy, wz = (T_ref[:3, :3] @ np.array([gx, gy, gz + lift]) + T_ref[:3, 3]).tolist()
        else:  # the handle where the joint has moved it
            assert reach.handle is not None  # (the reader asks for one goal)
            gz = 0.0
            wx, wy, wz, height, radial = self._at_handle(self.task.scene.joints[reach.handle], reach, placed,
                                                         obs, readings, here)
        ex, ey, ez = wx - tx, wy - ty, wz - tz
        tilt = math.acos(max(-1.0, min(1.0, zz)))
        return _Look(T_f[:3, 3], T_f[:3, 2], tilt, height, gz, radial, (wx, wy, wz),
                     math.sqrt(ex * ex + ey * ey + ez * ez))

    def _at_handle(self, joint: Joint, reach: Reach, placed: bool, obs: Observation,
                   readings: Mapping[str, Any], here: tuple[float, float, float, float]
                   ) -> tuple[float, float, float, float, float]:
        """The goal at ``joint``'s handle where the joint has moved it (world, lifted),
        and the frame's height and distance from the goal's vertical in the handle's
        frame so moved (NaN unless ``placed``)."""
        H = obs.objects[joint.handle]
        o = self._joint_position(joint.name, readings)
        T = handle_pose(joint, H, o)
        (_, _, c0, wx), (_, _, c1, wy), (_, _, c2, wz), _ = T.tolist()  # its z, origin
        height = radial = math.nan
        if placed and joint.hinge is None:  # the frame at 0, moved along its x
            mx, my, height, _ = (self._inverse(joint.handle, H) @ np.array(here)).tolist()
            radial = math.hypot(mx - o, my)
        elif placed:  # turned: the frame at the handle now
            mx, my, height, _ = (self._inverse(joint.name, T) @ np.array(here)).tolist()
            radial = math.hypot(mx, my)
        if reach.lift is not None:
            lift = _lifted(reach.lift, radial)
            wx, wy, wz = wx + lift * c0, wy + lift * c1, wz + lift * c2
        return wx, wy, wz, height, radial

    def _press_look(self, a: Press, obs: Observation, readings: Mapping[str, Any]) -> _Look:
        """The press's frame against its button: its goal the face's centre pushed in to
        the button's travel; its height and radial in the button's frame, the radial its
        distance from the button's axis (the body's x)."""
        T_f = obs.T_world_ee if a.frame == HAND else obs.objects[a.frame]
        T_B = obs.objects[a.button]
        button = self.task.scene.bodies[a.button].button
        assert button is not None  # (the reader checks the press names a button)
        _, y, z, _ = (self._inverse(a.button, T_B) @ np.append(T_f[:3, 3], 1.0)).tolist()
        goal = T_B[:3, 3] - button.travel * T_B[:3, 0]
        tilt = math.acos(max(-1.0, min(1.0, float(T_f[2, 2]))))
        return _Look(T_f[:3, 3], T_f[:3, 2], tilt, z, 0.0, math.hypot(y, z), tuple(goal.tolist()),
                     float(np.linalg.norm(goal - T_f[:3, 3])))

    def _pressing(self, a: Press, seen: _Look, obs: Observation, readings: Mapping[str, Any]) -> Array:
        """The press's frame's velocity: onto the button's axis, ``clearance`` in front of
        its face while off the axis; on it, in towards the face (at ``press_speed`` within
        ``slow`` of it) and, once the scene reports a push, at ``press_speed`` slowed as
        the force grows past half the step's bound, backing off beyond it."""
        T_B = obs.objects[a.button]
        button = self.task.scene.bodies[a.button].button
        assert button is not None
        x, y, z, _ = (self._inverse(a.button, T_B) @ np.append(seen.p, 1.0)).tolist()
        face = -float(readings.get(f"{a.button}.position", 0.0))  # where the face is now
        force = float(readings.get(f"{a.button}.force", 0.0))
        on_axis = seen.radial < self.aim * button.radius or (force > 0.0 and seen.radial < button.radius)
        if not on_axis:
            along = self.gain * (face + self.clearance - x)
        elif force > 0.0:
            along = -self.press_speed * max(-1.0, min(1.0, 2.0 * (1.0 - force / a.force)))
        else:
            along = -(self.gain * max(0.0, x - face - self.slow) + self.press_speed)
        v = T_B[:3, :3] @ np.array([along, -self.gain * y, -self.gain * z])
        return _saturate(v, self.v_max)

    # -- the steps -----------------------------------------------------------------------

    def _move(self, i: int, a: Action, seen: _Look, readings: Mapping[str, Any],
              positions: Mapping[str, Array]) -> int:
        """+1: step ``i`` is complete; -1: back to the step before; 0: stay."""
        if isinstance(a, Reach):
            r = a.reached
            if r is not None and (r.radial is None or seen.radial < r.radial) and \
                    (r.height is None or abs(seen.height - seen.goal_height) < r.height):
                return 1
            return 1 if a.until is not None and holds(a.until, readings, positions) else 0
        if isinstance(a, Tilt):
            if holds(a.until, readings, positions):
                return 1
            return -1 if a.off_by is not None and seen.radial > a.off_by else 0
        if isinstance(a, Upright):
            return 1 if seen.tilt < a.below else 0
        if isinstance(a, Press):
            return 1 if holds(a.until, readings, positions) else 0
        if a.back is not None and holds(a.back, readings, positions):  # let go: that first
            return -1
        reached = self._ends[i] - a.overshoot + self._pasts[i]
        return 1 if self._joint_position(a.joint, readings) >= reached else 0

    def _close(self, seen: _Look) -> bool:
        """Whether the frame is within the current reach's ``accept`` region."""
        if self.index == len(self.task.intent):
            return False
        a = self.task.intent[self.index].action
        if not isinstance(a, Reach) or a.accept is None:
            return False
        c = a.accept
        return (seen.radial < c.radial and (c.height is None or c.height[0] < seen.height < c.height[1])
                and (c.tilt is None or seen.tilt < c.tilt))

    def _error(self, i: int, seen: _Look, obs: Observation, readings: Mapping[str, Any]) -> float:
        """How far from done step ``i`` is (m and m-equivalents); once done, the last
        step's."""
        a = self._action(i)
        if isinstance(a, Reach):
            if a.upright is None:
                return seen.to_goal
            return seen.to_goal + self.per_rad * max(0.0, seen.tilt - a.upright)
        if isinstance(a, Tilt):  # tilting far enough, then the readings it waits for
            err = seen.to_goal + self.per_rad * max(0.0, a.to - seen.tilt)
            for reading, target in self._waits[self._last(i)].items():
                err += a.weight * max(0.0, target - float(readings.get(reading, 0.0)))
            return err
        if isinstance(a, Upright):
            return seen.to_goal + self.per_rad * seen.tilt
        if isinstance(a, Press):  # to the face's centre pushed in to its travel
            return seen.to_goal
        return self._joint_error(i, a, seen, obs, readings)

    def _path(self, a: MoveJoint, obs: Observation, readings: Mapping[str, Any]
              ) -> tuple[float, Array, Array, float]:
        """Joint ``a.joint``'s position, its handle there (world), the unit direction the
        handle moves in as the joint opens (a drawer's axis, a door's arc's tangent) and
        m of that path per unit of the joint (1 for a prismatic joint, the lever for a
        revolute one)."""
        joint = self.task.scene.joints[a.joint]
        H = obs.objects[joint.handle]
        o = self._joint_position(a.joint, readings)
        lever = _lever(joint)
        return o, handle_pose(joint, H, o)[:3, 3], handle_jacobian(joint, H, o) / lever, lever

    def _joint_error(self, i: int, a: MoveJoint, seen: _Look, obs: Observation,
                     readings: Mapping[str, Any]) -> float:
        """The handle's path still to go (m) and the frame's distance off that path."""
        o, handle, axis, lever = self._path(a, obs, readings)
        target = self._ends[self._last(i)]
        (a0, a1, a2), (h0, h1, h2) = axis.tolist(), handle.tolist()
        x, y, z = seen.p.tolist()
        d0, d1, d2 = h0 - x, h1 - y, h2 - z  # to the handle
        da = 0.0 + d0 * a0 + d1 * a1 + d2 * a2  # (summed as numpy's dot)
        l0, l1, l2 = d0 - da * a0, d1 - da * a1, d2 - da * a2  # lateral
        err = max(0.0, target - o) * lever + math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
        upright = self._reach(self._anchors[i]).upright
        return err if upright is None else err + self.per_rad * max(0.0, seen.tilt - upright)

    # -- the motion ----------------------------------------------------------------------

    def _spin_free(self, i: int) -> bool:
        """Whether only the frame's axis matters at step ``i`` (its spin about it does
        not), rather than nothing of its orientation."""
        a = self._action(i)
        if isinstance(a, Press):  # (a press's orientation is free)
            return False
        return isinstance(a, Tilt | Upright) or self._reach(self._anchors[i]).upright is not None

    def _weights(self, i: int, seen: _Look) -> Array:
        W = np.zeros((6, 6))
        W[:3, :3] = np.eye(3) / self.v_max
        if self._spin_free(i):
            W[3:, 3:] = (np.eye(3) - np.outer(seen.z, seen.z)) / self.w_max
        else:
            W[3:, 3:] = np.eye(3) * self.free_weight
        return W

    def _twist(self, i: int, seen: _Look, obs: Observation, readings: Mapping[str, Any]) -> Array:
        """The hand's twist: the frame to its goal (along the joint's axis when moving
        it), its axis tilted, brought up or left as it is."""
        a = self._action(i)
        if not isinstance(a, Tilt) or i == len(self.task.intent):
            self._axis = None
        if i == len(self.task.intent):
            return np.zeros(6)
        if isinstance(a, MoveJoint):
            v = self._along_joint(i, a, seen, obs, readings)
        elif isinstance(a, Press):
            v = self._pressing(a, seen, obs, readings)
        else:
            v = _saturate(self.gain * (np.array(seen.goal) - seen.p), self.v_max)
        if not self._spin_free(i):
            return np.concatenate([v, np.zeros(3)])
        if isinstance(a, Tilt):
            w = self._tilt_axis(i, obs.T_world_ee, seen) * self.gain * (a.to - seen.tilt)
        elif isinstance(a, Upright):
            w = self._uprighting(seen, seen.tilt)
        else:  # only a tilt beyond what the reach tolerates needs undoing
            upright = self._reach(self._anchors[i]).upright
            assert upright is not None  # (spin free)
            w = self._uprighting(seen, max(0.0, seen.tilt - upright))
        w = _saturate(w, self.w_max)
        # the hand's twist that moves the frame so: v_ee = v_frame - w x (p_frame - p_ee)
        v_ee = v - np.cross(w, seen.p - obs.T_world_ee[:3, 3])
        return np.concatenate([v_ee, w])

    def _along_joint(self, i: int, a: MoveJoint, seen: _Look, obs: Observation,
                     readings: Mapping[str, Any]) -> Array:
        """The frame's velocity moving the handle: onto the handle across its path, and
        along the path towards the target (aiming at most ``ahead`` m ahead; on a door's
        arc, along its tangent at the handle)."""
        o, handle, axis, lever = self._path(a, obs, readings)
        target = self._ends[i]
        p = seen.p
        lateral = handle - p - float((handle - p) @ axis) * axis
        along = max(0.0, target - o) * lever
        return _saturate(self.gain * (lateral + min(along, self.ahead) * axis), self.v_max)

    def _uprighting(self, seen: _Look, excess: float) -> Array:
        """The angular velocity that brings ``excess`` rad of the frame's tilt back."""
        back = np.cross(seen.z, UP)  # rotating about it brings the axis up
        n = float(np.linalg.norm(back))
        return back / n * self.gain * excess if n > 1e-9 else np.zeros(3)

    def _tilt_axis(self, i: int, T_world_ee: Array, seen: _Look) -> Array:
        """The horizontal axis to tilt about, kept once chosen for step ``i``: the way the
        frame already leans when it leans clearly (``lean``), else the hand's y axis."""
        if self._axis is None or self._axis[0] != i:
            a = np.cross(UP, seen.z) if seen.tilt > self.lean else T_world_ee[:3, 1].copy()
            a[2] = 0.0
            n = float(np.linalg.norm(a))
            self._axis = (i, a / n if n > 1e-9 else np.array([0.0, 1.0, 0.0]))
        return self._axis[1]
