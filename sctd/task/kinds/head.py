"""A person's head the hand must not press into: the ``heads`` section of a scene.

A **head** is a sphere whose surface passes through the origin of the body ``behind``
(the mouth: the middle of the lips), its centre ``radius`` behind it along that frame's
-x (x points out of the mouth), so it moves with the mouth where a trial puts it. A
frame of the hand (its origin, the held object's frames) inside the sphere meets a
contact spring: ``stiffness`` (N/m) times its depth inside, plus ``damping`` (N s/m)
times its speed inwards, pushing it out along the normal (never pulling). It reports the
norm of that force now (``<name>.force``, N) and the highest so far (``max_force``).

The hand and the held frames must start outside every head, and no reach's goal may lie
inside one, at the file's poses: the first contact would be a blow, not a touch, and a
person never wants the hand pressed into a face.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sctd import se3

from ..model import Scene, Step
from .base import Array, FacetPhysics, Section, Shape, World
from .reach import Reach

MIN_HEAD, MAX_HEAD = 0.03, 0.30
"""m: the radii a head's sphere may have."""
HAND = "hand"  # (the reader's name for the hand: the reader imports the registry)


@dataclass(frozen=True)
class Head(Section):
    """A person's head: a sphere the hand and what it holds must not press into (see the
    module doc).

    Attributes
    ----------
    name : str
        What its readings are called (``<name>.force``).
    behind : str
        The body on its surface, in front of it.
    radius : float
        m.
    stiffness, damping : float
    """

    key = "heads"
    noun = "head"
    order = 10
    quantities = ("force", "max_force")

    name: str
    behind: str
    radius: float
    stiffness: float
    damping: float

    @classmethod
    def read(cls, r: Any, name: str, v: Any, path: str, scene: Scene) -> Head:
        d = r.fields(v, path, {"behind", "radius", "contact"})
        front = r.string(d["behind"], f"{path}.behind")
        if front not in scene.bodies:
            raise r.fail(f"{path}.behind", f"unknown body {front!r} (bodies: {', '.join(scene.bodies)})")
        radius = r.number(d["radius"], f"{path}.radius", lo=MIN_HEAD, hi=MAX_HEAD)
        c = r.fields(d["contact"], f"{path}.contact", {"stiffness", "damping"})
        return cls(name, front, radius, r.positive(c["stiffness"], f"{path}.contact.stiffness"),
                   r.nonneg(c["damping"], f"{path}.contact.damping"))

    def to_yaml(self) -> dict[str, Any]:
        return {"behind": self.behind, "radius": float(self.radius),
                "contact": {"stiffness": float(self.stiffness), "damping": float(self.damping)}}

    def centre(self, T_world_front: Array) -> Array:
        """The sphere's centre (world, shape (3,)) for the body ``behind`` at
        ``T_world_front``."""
        return T_world_front[:3, 3] - self.radius * T_world_front[:3, 0]

    def check(self, r: Any, scene: Scene, path: str) -> None:
        """Refuse a scene whose hand starts inside it (the hand, or a frame of what it
        holds), at the file's poses."""
        T_start = scene.start.T_world
        points = {HAND: T_start[:3, 3]}
        if scene.held is not None:
            points |= {n: (T_start @ T)[:3, 3] for n, T in scene.held.frames.items()}
        centre = self.centre(scene.bodies[self.behind].T_world)
        for name, p in points.items():
            depth = self.radius - float(np.linalg.norm(p - centre))
            if depth >= 0.0:
                raise r.fail(f"{path}.start", f"{name} starts {depth:.3f} m inside the head {self.name!r} "
                                              f"(its sphere of {self.radius} m behind {self.behind!r})")

    def check_intent(self, r: Any, scene: Scene, obj: str, intent: tuple[Step, ...]) -> None:
        """Refuse a reach whose goal (``to``, in the task object's frame) lies inside it
        at the file's poses."""
        T_obj = scene.bodies[obj].T_world
        centre = self.centre(scene.bodies[self.behind].T_world)
        for i, s in enumerate(intent):
            a = s.action
            if not isinstance(a, Reach) or a.to is None:  # (a reach to a point)
                continue
            goal = T_obj[:3, :3] @ a.to + T_obj[:3, 3]
            depth = self.radius - float(np.linalg.norm(goal - centre))
            if depth >= 0.0:
                raise r.fail(f"intent[{i}].reach.to", f"the goal lies {depth:.3f} m inside the head "
                                                      f"{self.name!r}")

    def physics(self, scene: Scene) -> FacetPhysics:
        points = [np.eye(4), *(scene.held.frames.values() if scene.held is not None else ())]
        return HeadPhysics(self, points)

    def body(self) -> str:
        return self.behind

    def shapes(self) -> list[Shape]:
        return [Shape("sphere", (self.radius, self.radius, self.radius),
                      se3.transform_from_rt(np.eye(3), [-self.radius, 0.0, 0.0]),
                      (225 / 255, 185 / 255, 150 / 255), 0.8)]

    def footprint(self, scene: Scene) -> list[tuple[Array, float]]:
        return [(self.centre(scene.bodies[self.behind].T_world), self.radius)]


class HeadPhysics(FacetPhysics):
    """A head's contact spring against the hand's points inside it.

    The points are the hand's origin and the held object's frames (``T_ee_points``).
    Each one at depth ``e = r - |p - c|`` inside the sphere (centre ``c``, radius
    ``r``), moving along the outward normal ``n`` at ``v_n``, is pushed out by
    ``f = max(0, k e - d v_n) n``: a spring and a damper that push and never pull.
    The forces act on the hand at their points, as a wrench at the ee's origin.

    Attributes
    ----------
    force : float
        The norm of the contact force on the head now, N.
    max_force : float
        The highest ``force`` so far, N.
    """

    def __init__(self, head: Head, T_ee_points: list[Array]):
        self.head = head
        self.name = head.name
        self.points = [T[:3, 3].copy() for T in T_ee_points]
        self.force = self.max_force = 0.0

    def reset(self, world: World) -> None:
        """No contact."""
        self.force = 0.0
        self.max_force = 0.0

    def step(self, world: World, dt: float) -> Array:
        """The wrench the head exerts on the hand (world axes at the ee's origin), shape (6,)."""
        h = self.head
        c = h.centre(world.poses[h.behind])
        T_world_ee, twist = world.T_world_ee, world.twist
        R, p_ee = T_world_ee[:3, :3], T_world_ee[:3, 3]
        v, w = twist[:3], twist[3:]
        wrench = np.zeros(6)
        for offset in self.points:
            arm = R @ offset  # from the ee's origin to the point
            d = p_ee + arm - c
            dist = float(np.linalg.norm(d))
            depth = h.radius - dist
            if depth <= 0.0 or dist < 1e-9:  # (outside, or at the centre: no normal)
                continue
            n = d / dist
            v_n = float((v + np.cross(w, arm)) @ n)
            push = max(0.0, h.stiffness * depth - h.damping * v_n)
            wrench[:3] += push * n
            wrench[3:] += np.cross(arm, push * n)
        self.force = float(np.linalg.norm(wrench[:3]))
        self.max_force = max(self.max_force, self.force)
        return wrench

    def readings(self, world: World) -> dict[str, float | bool]:
        n = self.name
        return {f"{n}.force": self.force, f"{n}.max_force": self.max_force}
