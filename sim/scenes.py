"""Task scenes: what the arm interacts with and how well the task went (pure logic).

A scene is built from a task file (:mod:`sctd.task`: ``tasks/pour.yaml``,
``tasks/drawer.yaml``, or any other); none of its parts knows a task. Bodies stand in
the world, each a published frame; the hand holds an object (mass, centre of mass,
named frames fixed in the hand, such as a bottle's opening). Everything else is an
element of a registered kind (:mod:`sctd.task.kinds`), stepped by its kind's physics on
a :class:`~sctd.task.kinds.World`, in this order:

- the held object's facets: its **contents**, which flow out of the outlet frame while
  its axis is tilted past the flow angle, into a body's **container** if the outlet is
  over its opening, otherwise they are spilled (what is left of them the arm carries);
- the scene's sections: a **joint**'s handle (on a prismatic joint along its own x axis,
  a drawer, or on a revolute joint about a hinge line, a door), grasped when the hand
  comes within the grasp radius of where the handle is, then coupled to the hand by a
  stiff spring-damper, the joint resisting with a spring, viscous damping and Coulomb
  friction and stopping at its end stops (the handle's published frame stays at the
  joint's 0, so opening a drawer shows as hand motion along the frame's +x, and a door
  as motion along its arc); a person's **head**, whose contact spring pushes back on the
  hand and the held object's frames inside it; a **zone**, a goal pose of a frame of the
  hand timed while the frame stays inside;
- the bodies' facets, in the file's order: a body's solid **surface** (a plane through
  its origin, normal to its x axis) that pushes the points of the hand touching it back
  out with a contact spring-damper and friction, and a **button** in it (a light
  switch) that gives way under the push and switches past its click depth; a
  **support**, an **item** the fingers take, a **knob** they turn.

A scene is stepped once per cycle with the true ee pose and twist; it returns the
external wrench it exerts on the ee (world axes at the ee origin, N and N m), names its
objects' poses, and reports its readings (``<element>.<quantity>``) and the task's
predicates on them (done, success, progress). No Pinocchio, bus or Zenoh here.

World is the arm's base frame.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from sctd import se3
from sctd.task import Task
from sctd.task.judge import holds, thresholds
from sctd.task.kinds import FacetPhysics, World
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
        self.thresholds = thresholds(task.outcome.done)  # what a reading must reach: done
        self._T_world_ee = np.eye(4)  # the hand as last stepped (where its held frames are)
        self.fingers = Fingers()
        self.live = {n: T.copy() for n, T in self.poses.items()}  # the bodies now (an item moves)
        self.world = World(self._T_world_ee, np.zeros(6), self.live, self.fingers, {})
        for key, facet in sc.held.facets.items() if sc.held is not None else ():  # (its contents: first)
            phys = facet.physics(sc.held.name, sc)  # type: ignore[union-attr]
            if phys is not None:
                self.world.physics.setdefault(sc.held.name, {})[key] = phys  # type: ignore[union-attr]
        for key, entries in sc.sections.items():  # (then the sections, then the bodies' facets)
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
                                             for p in facets.values()]  # (in that order)
        self.reset()

    def reset(self) -> None:
        """Back to the initial state (contents full, joints at 0 and released, buttons out
        and off)."""
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
        wrench = np.zeros(6)
        self.fingers.advance(dt)
        self.world.T_world_ee, self.world.twist = T_world_ee, twist
        for p in self._physics:  # (the elements of every kind: the contents, a handle, a head, an item)
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
            left = sum(p.held_mass() for p in self._physics)  # (what is left of its contents)
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
        """Every element's ``<element>.<quantity>``."""
        out: dict[str, float | bool] = {}
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
        for p in self._physics:  # (the contents' poured and spilled, a joint's opening)
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
