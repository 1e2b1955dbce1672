"""Task scenes: what the arm interacts with and how well the task went (pure logic).

A scene is built from a task file (:mod:`sctd.task`: ``tasks/pour.yaml``,
``tasks/drawer.yaml``, or any other) out of a few kinds of element, none of which
knows a task:

- **bodies** standing in the world, each a published frame (a container's opening is
  its origin, z up);
- the **held object** (mass, centre of mass, named frames fixed in the hand, such as a
  bottle's opening) and its **contents** (:class:`Flow`): they flow out of the outlet
  frame while its axis is tilted past the flow angle, into the container if the outlet
  is over its opening, otherwise they are spilled;
- the elements of registered kinds (:mod:`sctd.task.kinds`): a section's entries (a
  **joint**'s handle, on a prismatic joint along its own x axis, a drawer, or on a
  revolute joint about a hinge line, a door, grasped when the hand comes within the
  grasp radius of where the handle is, then coupled to the hand by a stiff
  spring-damper, the joint resisting with a spring, viscous damping and Coulomb
  friction and stopping at its end stops: the handle's published frame stays at the
  joint's 0, so opening a drawer shows as hand motion along the frame's +x, and a door
  as motion along its arc; a person's head, whose contact spring pushes back on the hand and the held object's
  frames inside it; a zone, a goal pose of a frame of the hand timed while the frame
  stays inside) and the bodies' facets (an item the fingers take), each stepped by its
  kind's physics on a :class:`~sctd.task.kinds.World`. Among the facets: a body's solid
  **surface** (a plane through its origin, normal to its x axis) that pushes the points
  of the hand touching it back out with a contact spring-damper and friction, and a
  **button** in it (a light switch) that gives way under the push against its spring
  and switches when pushed past its click depth.

A scene is stepped once per cycle with the true ee pose and twist; it returns the
external wrench it exerts on the ee (world axes at the ee origin, N and N m), names its
objects' poses, and reports its readings (``<element>.<quantity>``) and the task's
predicates on them (done, success, progress). No Pinocchio, bus or Zenoh here.

World is the arm's base frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from sctd import se3
from sctd.task import Task
from sctd.task.judge import holds, thresholds
from sctd.task.kinds import FacetPhysics, World
from sctd.task.model import Container, Contents, Held
from sctd.wire.codec import GripperCmd, GripperReading

from .fingers import Fingers

GRAVITY = 9.81


class Scene(Protocol):
    """What :class:`sctd_sim.simulation.Simulation` needs from a scene."""

    name: str
    task_object: str

    def reset(self) -> None:
        """Back to the initial state."""

    def start_pose(self) -> np.ndarray:
        """Suggested initial ``T_world_ee`` (4x4)."""

    def step(self, T_world_ee: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
        """Advance by ``dt``; return the wrench on the ee, shape (6,)."""

    def objects(self, T_world_ee: np.ndarray) -> dict[str, np.ndarray]:
        """Object poses ``T_world_obj`` (4x4) by name."""

    def outcome(self) -> dict[str, Any]:
        """Task outcome so far (plain JSON/msgpack types)."""

    def payload(self) -> tuple[float, np.ndarray] | None:
        """The load the arm carries as its controller is configured with it (a real arm's
        load data): mass (kg) and centre of mass in the ee frame (m); None for none."""

    def grip(self, cmd: GripperCmd) -> bool:
        """Take a gripper command (once per number); whether it was new."""

    def gripper(self) -> GripperReading:
        """The fingers now (the state's ``gripper``)."""


# -- contents that flow --------------------------------------------------------------
@dataclass(frozen=True)
class OutletGeometry:
    """Where the outlet is relative to the container's opening.

    Attributes
    ----------
    outlet_in_container : ndarray, shape (3,)
        The outlet in the container's frame, m.
    above_rim : float
        Height of the outlet above the container's opening, m.
    radial : float
        Horizontal distance of the outlet from the container's axis, m.
    tilt : float
        Angle between the outlet's axis and world up, rad (0 upright, pi upside down).
    over_opening : bool
        Whether a stream from the outlet lands inside the container.
    """

    outlet_in_container: np.ndarray
    above_rim: float
    radial: float
    tilt: float
    over_opening: bool


def outlet_geometry(T_world_outlet: np.ndarray, container: Container, T_container_world: np.ndarray
                    ) -> OutletGeometry:
    """The outlet relative to the container's opening (``T_container_world``: the
    inverse of the container body's pose), and the outlet's tilt."""
    p = (T_container_world @ T_world_outlet)[:3, 3]
    x, y, above = p.tolist()
    radial = math.hypot(x, y)
    tilt = math.acos(min(1.0, max(-1.0, float(T_world_outlet[2, 2]))))
    over = radial <= container.radius - container.rim_margin and 0.0 <= above <= container.max_drop
    return OutletGeometry(p.copy(), above, radial, tilt, over)


def outlet_stream(tilt: float, contents: Contents) -> float:
    """The stream out of the outlet at ``tilt`` (fraction of the full contents per
    second): none up to the contents' flow angle, then growing with the tilt past it."""
    past = tilt - contents.flow_angle
    if past <= 0.0:
        return 0.0
    return contents.flow_rate * math.sin(min(past, math.pi / 2))


class Flow:
    """The held object's contents, poured into a container body or spilled.

    Attributes
    ----------
    remaining, poured, spilled : float
        Fractions of the full contents: still held, in the container, spilled.
    """

    def __init__(self, held: Held, contents: Contents, container: Container):
        self.name = held.name
        self.contents = contents
        self.container = container
        self.T_ee_outlet = held.frames[contents.outlet]
        # the outlet's axis in the ee frame: the outlet's tilt from the hand's rotation
        self._outlet_axis = tuple(self.T_ee_outlet[:3, 2].tolist())
        self._key = b""  # the container pose (bytes) _T_container_world inverts
        self._T_container_world = np.eye(4)
        self.reset()

    def reset(self) -> None:
        """Full, nothing poured."""
        self.remaining = 1.0
        self.poured = 0.0
        self.spilled = 0.0
        self._tilt: float | None = None
        self._at: tuple[np.ndarray, np.ndarray] | None = None  # (T_world_ee, T_container_world)
        self._geometry: OutletGeometry | None = None

    def step(self, T_world_ee: np.ndarray, T_world_container: np.ndarray, dt: float) -> None:
        """Pour for ``dt`` s from the hand at ``T_world_ee`` (which must not change
        afterwards: :attr:`geometry` is worked out from it when asked)."""
        # Only the outlet's tilt decides the flow; where it points (the geometry) is
        # worked out when something pours, or when asked.
        a0, a1, a2 = self._outlet_axis
        r20, r21, r22 = T_world_ee[2, :3].tolist()
        self._tilt = tilt = math.acos(min(1.0, max(-1.0, r20 * a0 + r21 * a1 + r22 * a2)))
        self._at = (T_world_ee, self._inverse(T_world_container))
        self._geometry = None
        out = min(self.remaining, outlet_stream(tilt, self.contents) * dt)
        if out > 0.0:
            self.remaining -= out
            g = self.geometry
            if g is not None and g.over_opening:
                self.poured += out
            else:
                self.spilled += out

    @property
    def geometry(self) -> OutletGeometry | None:
        """Where the outlet was at the last :meth:`step` (None before one)."""
        if self._geometry is None and self._at is not None:
            T_world_ee, T_container_world = self._at
            self._geometry = outlet_geometry(T_world_ee @ self.T_ee_outlet, self.container,
                                             T_container_world)
        return self._geometry

    def _inverse(self, T: np.ndarray) -> np.ndarray:
        """``T_container_world``, computed again only when the container moved."""
        key = T.tobytes()
        if key != self._key:
            self._T_container_world, self._key = se3.invert_transform(T), key
        return self._T_container_world

    @property
    def flowing(self) -> bool:
        tilt = self._tilt
        return tilt is not None and outlet_stream(tilt, self.contents) > 0.0 and self.remaining > 0.0

    def readings(self) -> dict[str, float | bool]:
        n = self.name
        return {f"{n}.poured": self.poured, f"{n}.spilled": self.spilled, f"{n}.remaining": self.remaining,
                f"{n}.flowing": self.flowing}

    def outcome(self, thresholds: dict[str, float]) -> dict[str, Any]:
        """The poured, spilled and remaining fractions, the fraction to pour (the task's
        ``thresholds``: 1 when it names none) and the outlet's geometry."""
        out: dict[str, Any] = {"poured": self.poured, "spilled_amount": self.spilled,
                               "spilled": self.spilled > 1e-9, "remaining": self.remaining,
                               "fill_target": thresholds.get(f"{self.name}.poured", 1.0)}
        g = self.geometry
        if g is not None:
            out.update(outlet_in_container=g.outlet_in_container.tolist(), above_rim=g.above_rim,
                       radial=g.radial, tilt=g.tilt, over_opening=g.over_opening, pouring=self.flowing)
        return out


# -- the scene of a task ----------------------------------------------------------------
class TaskScene:
    """The scene a task file describes (see the module doc).

    Parameters
    ----------
    task : Task

    Attributes
    ----------
    poses : dict of str to ndarray (4, 4)
        Each body's pose this trial (:func:`randomize` moves them).
    start_position, start_yaw
        The hand's start this trial: position (world) and yaw about the vertical.
    """

    def __init__(self, task: Task):
        self.task = task
        self.name = task.name
        self.task_object = task.object
        sc = task.scene
        self.poses = {n: b.T_world.copy() for n, b in sc.bodies.items()}
        self.start_position = sc.start.T_world[:3, 3].copy()
        self.start_yaw = 0.0
        self.held = sc.held
        self.flow: Flow | None = None
        if sc.held is not None and sc.held.contents is not None:
            container = sc.bodies[sc.held.contents.into].container
            assert container is not None  # (the reader checks: contents go into a container)
            self.flow = Flow(sc.held, sc.held.contents, container)
        self.thresholds = thresholds(task.outcome.done)  # what a reading must reach: done
        self._T_world_ee = np.eye(4)  # the hand as last stepped (where its held frames are)
        self.fingers = Fingers()
        self.live = {n: T.copy() for n, T in self.poses.items()}  # the bodies now (an item moves)
        self.world = World(self._T_world_ee, np.zeros(6), self.live, self.fingers, {})
        for key, entries in sc.sections.items():  # (sections first: stepped before the facets)
            for name, entry in entries.items():
                section = entry.physics(sc)
                if section is not None:
                    self.world.physics.setdefault(name, {})[key] = section
        for name, body in sc.bodies.items():
            for key, facet in body.facets.items():
                phys = facet.physics(name, sc)
                if phys is not None:
                    self.world.physics.setdefault(name, {})[key] = phys
        self._physics: list[FacetPhysics] = [p for facets in self.world.physics.values()
                                             for p in facets.values()]  # (sections, then the facets)
        self.reset()

    def reset(self) -> None:
        """Back to the initial state (contents full, joints at 0 and released, buttons out
        and off)."""
        if self.flow is not None:
            self.flow.reset()
        self.live.clear()
        self.live.update({n: T.copy() for n, T in self.poses.items()})
        self.fingers.reset()
        for p in self._physics:
            p.reset(self.world)

    @property
    def handles(self) -> list[FacetPhysics]:
        """The physics of the joints' handles, in the file's order."""
        return [p for facets in self.world.physics.values() for k, p in facets.items() if k == "joints"]

    @property
    def contacts(self) -> list[FacetPhysics]:
        """The physics of the bodies' surfaces (a button's among them), in the file's order."""
        return [p for facets in self.world.physics.values() for k, p in facets.items() if k == "surface"]

    def grip(self, cmd: GripperCmd) -> bool:
        """Take a gripper command (once per number); whether it was new."""
        return self.fingers.command(cmd)

    def gripper(self) -> GripperReading:
        """The fingers now."""
        return self.fingers.reading()

    def start_pose(self) -> np.ndarray:
        """The hand's start: the file's orientation turned by ``start_yaw`` about the
        vertical, at ``start_position``."""
        R = se3.matrix_from_rotvec([0.0, 0.0, self.start_yaw]) @ self.task.scene.start.T_world[:3, :3]
        return se3.transform_from_rt(R, self.start_position)

    def step(self, T_world_ee: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
        """Advance by ``dt``; return the wrench of the held load, the grasped handles, the
        surfaces the hand touches and the heads pressed into."""
        self._T_world_ee = T_world_ee = T_world_ee.copy()  # (kept: never changed in place)
        live = self.live
        if self.flow is not None:
            self.flow.step(T_world_ee, live[self.flow.contents.into], dt)
        wrench = np.zeros(6)
        self.fingers.advance(dt)
        self.world.T_world_ee, self.world.twist = T_world_ee, twist
        for p in self._physics:  # (the registered kinds' elements: a head, an item in the hand or not)
            wrench += p.step(self.world, dt)
        load = self.payload()
        if load is not None:
            mass, com = load
            fz = -mass * GRAVITY
            # r = R com, and [force, r x force] with force = (0, 0, fz), on floats
            (a0, a1, a2, _), (b0, b1, b2, _), _, _ = T_world_ee.tolist()
            c0, c1, c2 = com.tolist()
            r0, r1 = a0 * c0 + a1 * c1 + a2 * c2, b0 * c0 + b1 * c1 + b2 * c2
            wrench[2] += fz
            wrench[3] += r1 * fz
            wrench[4] -= r0 * fz
        return wrench

    def payload(self) -> tuple[float, np.ndarray] | None:
        """The held object with what is left in it (the arm's load data follows it as it
        empties, as a real arm's load estimate from its force-torque sensing would);
        None when the hand holds nothing (a grasped handle is not a load it carries)."""
        loads = [p.load() for p in self._physics]
        carried = [x for x in loads if x is not None]
        if self.held is not None:
            left = self.held.contents.mass * self.flow.remaining if self.flow is not None and \
                self.held.contents is not None else 0.0
            if not carried:
                return self.held.mass + left, self.held.com
            carried.append((self.held.mass + left, self.held.com))
        if not carried:
            return None
        mass = sum(m for m, _ in carried)
        return mass, sum((m * c for m, c in carried), np.zeros(3)) / mass

    def objects(self, T_world_ee: np.ndarray) -> dict[str, np.ndarray]:
        """The bodies' frames (where they are now), then the held object's frames, then the
        frames of the bodies' facets (an item's)."""
        out = {n: T.copy() for n, T in self.live.items()}
        if self.held is not None:
            out.update({n: T_world_ee @ T for n, T in self.held.frames.items()})
        for p in self._physics:
            out.update(p.frames(self.world))
        return out

    def readings(self) -> dict[str, float | bool]:
        """Every element's ``<element>.<quantity>`` (:data:`sctd.task.model.READINGS`)."""
        out: dict[str, float | bool] = {}
        if self.flow is not None:
            out.update(self.flow.readings())
        for p in self._physics:
            out.update(p.readings(self.world))
        return out

    def positions(self) -> dict[str, np.ndarray]:
        """World positions of the hand (as last stepped), the bodies and the held frames."""
        out = {n: T[:3, 3] for n, T in self.live.items()}
        if self.held is not None:  # (where the hand holds them: turned with it)
            out.update({n: (self._T_world_ee @ T)[:3, 3] for n, T in self.held.frames.items()})
        for p in self._physics:
            out.update({n: T[:3, 3] for n, T in p.frames(self.world).items()})
        out["hand"] = self._T_world_ee[:3, 3]
        return out

    def outcome(self) -> dict[str, Any]:
        """The readings, the task's ``done``, ``success`` (done and successful),
        ``progress`` and ``thresholds`` (:func:`sctd.task.judge.thresholds` of ``done``), and
        each element's own fields."""
        r = self.readings()
        o = self.task.outcome
        pos = self.positions()
        done = holds(o.done, r, pos)
        out: dict[str, Any] = {"scene": self.name, "readings": r, "done": done,
                               "success": done and holds(o.success, r, pos),
                               "progress": float(r[str(o.progress)]), "thresholds": dict(self.thresholds)}
        g = self.fingers.reading()  # (the fingers as a person sees them)
        out["gripper"] = {"width": g.width, "grasped": g.grasped, "moving": g.moving,
                          "closing": self.fingers.closing}
        if self.task.parts:  # several tasks in one room: each judged on the same readings
            out["tasks"] = {t.name: _judged(t, r, pos) for t in self.task.parts}
        if self.flow is not None:
            out.update(self.flow.outcome(self.thresholds))
        for p in self._physics:  # (a joint's opening)
            out.update(p.outcome(self.world, self.thresholds))
        return out


def _judged(task: Task, readings: dict[str, float | bool],
            positions: dict[str, np.ndarray]) -> dict[str, Any]:
    """One part of a composed task: done, success and progress on the room's readings."""
    done = holds(task.outcome.done, readings, positions)
    return {"done": done, "success": done and holds(task.outcome.success, readings, positions),
            "progress": float(readings[str(task.outcome.progress)])}


class EmptyScene:
    """No objects (benchmarks, controller tests)."""

    name = "empty"
    task_object = ""

    def __init__(self) -> None:
        self.fingers = Fingers()

    def reset(self) -> None:
        """The fingers open, as at the start."""
        self.fingers.reset()

    def grip(self, cmd: GripperCmd) -> bool:
        """Take a gripper command (once per number); whether it was new."""
        return self.fingers.command(cmd)

    def gripper(self) -> GripperReading:
        """The fingers now."""
        return self.fingers.reading()

    def start_pose(self) -> np.ndarray:
        """Hand in front, pointing down (the arm's rest posture's neighbourhood)."""
        return se3.transform_from_rt(np.diag([-1.0, 1.0, -1.0]), [0.55, 0.0, 0.20])

    def step(self, T_world_ee: np.ndarray, twist: np.ndarray, dt: float) -> np.ndarray:
        """The fingers move; no wrench."""
        self.fingers.advance(dt)
        return np.zeros(6)

    def objects(self, T_world_ee: np.ndarray) -> dict[str, np.ndarray]:
        """No objects."""
        return {}

    def payload(self) -> tuple[float, np.ndarray] | None:
        """No load."""
        return None

    def outcome(self) -> dict[str, Any]:
        """Nothing to score."""
        return {"scene": self.name}


def make_scene(task: Task, trial_seed: int | None = None, attempt: int = 0) -> Scene:
    """The scene of ``task`` (resolved from its name or file where the program starts,
    :func:`sctd.task.find_task`; :class:`EmptyScene` is the scene of no objects); with
    ``trial_seed``, a seeded random start (:func:`randomize`; ``attempt`` draws another
    one for the same seed, for a start the arm cannot reach)."""
    scene = TaskScene(task)
    if trial_seed is not None:
        randomize(scene, trial_seed, attempt)
    return scene


def randomize(scene: Scene, seed: int, attempt: int = 0) -> None:
    """A seeded random start for an evaluation trial, as the task file's ``vary``
    fields say: the hand's start position (each axis) and yaw, then each body's
    position (and yaw), in the file's order."""
    if not isinstance(scene, TaskScene):
        return
    rng = np.random.default_rng([seed, attempt] if attempt else seed)
    sc = scene.task.scene
    scene.default_start_pose = scene.start_pose()  # type: ignore[attr-defined]  # (start_posture's via)
    v = sc.start.vary
    scene.start_position = scene.start_position + rng.uniform(-v.position, v.position)
    scene.start_yaw = float(rng.uniform(-v.yaw, v.yaw))
    for name, body in sc.bodies.items():
        if not (np.any(body.vary.position) or body.vary.yaw):
            continue
        T = scene.poses[name].copy()
        T[:3, 3] += rng.uniform(-body.vary.position, body.vary.position)
        if body.vary.yaw:
            yaw = float(rng.uniform(-body.vary.yaw, body.vary.yaw))
            T[:3, :3] = se3.matrix_from_rotvec([0.0, 0.0, yaw]) @ T[:3, :3]
        scene.poses[name] = T
    scene.reset()
