"""A handle on a joint the hand grasps and moves (a drawer, a hinged door): the ``joints``
section of a scene.

A **joint** (``scene.joints.<name>``) moves the body ``handle``: a prismatic joint along
that body's own x axis from 0 (its default pose) to ``travel`` (m), a revolute joint
about ``hinge`` (a line in the handle's frame at 0) from 0 to ``travel`` (rad). The
handle body's published frame stays at 0 (:func:`~sctd.task.kinematics.handle_pose`
gives it at a position). The hand grasps the handle when it comes within the grasp
radius of where the handle is and lets go beyond the release distance; while held, a
stiff spring-damper joins them, and the joint resists with a spring, viscous damping
and Coulomb friction, and stops at its end stops. Quantities are in the joint's unit: m
for a prismatic joint, rad for a revolute one. A joint reports its ``position``,
``speed``, whether its handle is ``held``, how often it was grasped (``grasps``) and the
furthest position reached (``max_position``); a revolute joint's positions are angles
(a file may write their bounds in degrees).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from sctd import se3

from ..kinematics import handle_pose
from ..model import Scene
from .base import Array, FacetPhysics, Section, Shape, World

JOINT_KINDS = ("prismatic", "revolute")
"""The kinds of joint, as a file's ``type`` names them."""
JOINT_FIELDS = {"prismatic": set(), "revolute": {"hinge"}}
"""The fields a kind of joint has besides those every joint has."""
MIN_LEVER = 0.01
"""m: the nearest a revolute joint's handle may be to its hinge line."""
FRICTION_SPEED = 0.01
"""m/s (rad/s): ``friction_speed`` when the file leaves it out."""
BOX_FRONT = (0.40, 0.16)  # m: a prismatic joint's box (a drawer) as drawn: its front's width and height
BOX_DEPTH = 0.30  # m: the box's depth behind its front
HANDLE_OUT = 0.03  # m: how far a handle stands out of its drawer front or door
PANEL_THICKNESS = 0.02  # m: a revolute joint's panel (a door)
WOOD = (150 / 255, 110 / 255, 70 / 255)


@dataclass(frozen=True)
class Grasp:
    """How the hand takes hold of a joint's handle.

    Attributes
    ----------
    radius : float
        The hand grasps the handle when it comes this close, m.
    release : float
        It lets go when pulled this far from the handle, m.
    stiffness, damping : float
        Spring (N/m) and damper (N s/m) between the hand and the grasped handle.
    """

    radius: float
    release: float
    stiffness: float
    damping: float


@dataclass(frozen=True)
class Hinge:
    """The line a revolute joint turns its handle about, in the handle's frame at 0.

    Attributes
    ----------
    point : ndarray, shape (3,)
        A point on the line, m.
    axis : ndarray, shape (3,)
        Its unit direction: a positive joint position turns the handle about it by the
        right-hand rule.
    """

    point: Array
    axis: Array

    @property
    def lever(self) -> float:
        """The handle's distance from the line, m (the handle is the frame's origin)."""
        d = -self.point
        return float(np.linalg.norm(d - float(d @ self.axis) * self.axis))


@dataclass(frozen=True)
class Joint(Section):
    """A handle on a joint: a drawer (prismatic) or a hinged door (revolute) (see the
    module doc).

    Attributes
    ----------
    name : str
    kind : {"prismatic", "revolute"}
    handle : str
        The body that moves with the joint.
    travel : float
        Range of the joint from its default pose (0) to the end stop, m or rad.
    mass : float
        Moving mass as the hand feels it at the handle, kg; a revolute joint's inertia
        about its hinge is ``mass * hinge.lever**2`` (:attr:`inertia`).
    spring, damping, friction : float
        Towards 0 (N/m or N m/rad), viscous (N s/m or N m s/rad) and Coulomb friction
        (N or N m).
    friction_speed : float
        Speed over which the friction builds up (tanh), m/s or rad/s.
    grasp : Grasp
    hinge : Hinge or None
        A revolute joint's hinge line; None for a prismatic joint.
    """

    key = "joints"
    noun = "joint"
    order = 5
    quantities = ("position", "speed", "held", "grasps", "max_position")
    flags = ("held",)

    name: str
    kind: Literal["prismatic", "revolute"]
    handle: str
    travel: float
    mass: float
    spring: float
    damping: float
    friction: float
    friction_speed: float
    grasp: Grasp
    hinge: Hinge | None = None

    def __post_init__(self) -> None:
        if (self.kind == "revolute") != (self.hinge is not None):
            raise ValueError(f"joint {self.name!r}: a revolute joint has a hinge, a prismatic one none")

    @property
    def inertia(self) -> float:
        """What resists the joint's acceleration: kg (prismatic, the mass) or kg m^2
        (revolute, ``mass * lever**2``)."""
        return self.mass if self.hinge is None else self.mass * self.hinge.lever ** 2

    @property
    def unit(self) -> str:
        """The unit of its position: ``m`` or ``rad``."""
        return "rad" if self.kind == "revolute" else "m"

    def is_angular(self, quantity: str) -> bool:
        """A revolute joint's ``position`` and ``max_position`` are angles."""
        return self.kind == "revolute" and quantity in ("position", "max_position")

    @classmethod
    def read(cls, r: Any, name: str, v: Any, path: str, scene: Scene) -> Joint:
        m = r.mapping(v, path)
        if "type" not in m:  # (it says which other fields there are)
            raise r.fail(f"{path}.type", "missing")
        kind = r.choice(m["type"], f"{path}.type", JOINT_KINDS)
        d = r.fields(v, path, {"type", "handle", "travel", "mass", "grasp", *JOINT_FIELDS[kind]},
                     {"spring", "damping", "friction", "friction_speed"})
        handle = r.string(d["handle"], f"{path}.handle")
        if handle not in scene.bodies:
            raise r.fail(f"{path}.handle", f"unknown body {handle!r} (bodies: {', '.join(scene.bodies)})")
        g = r.fields(d["grasp"], f"{path}.grasp", {"radius", "release", "stiffness", "damping"})
        radius, release, stiffness, damping = (r.positive(g[k], f"{path}.grasp.{k}")
                                               for k in ("radius", "release", "stiffness", "damping"))
        grasp = Grasp(radius, release, stiffness, damping)
        if grasp.release <= grasp.radius:
            raise r.fail(f"{path}.grasp.release", f"must be above the grasp radius {grasp.radius}, "
                                                  f"got {grasp.release}")
        spring, viscous, friction = (r.nonneg(d.get(k, 0.0), f"{path}.{k}")
                                     for k in ("spring", "damping", "friction"))
        mass = r.positive(d["mass"], f"{path}.mass")
        friction_speed = r.positive(d.get("friction_speed", FRICTION_SPEED), f"{path}.friction_speed")
        if kind == "prismatic":
            return cls(name, "prismatic", handle, r.positive(d["travel"], f"{path}.travel"), mass, spring,
                       viscous, friction, friction_speed, grasp)
        # at most a full turn: past it the handle would come round to where it was
        travel = r.angle(d["travel"], f"{path}.travel", lo=0.0, hi=2 * math.pi, lo_open=True)
        return cls(name, "revolute", handle, travel, mass, spring, viscous, friction, friction_speed, grasp,
                   _hinge(r, d["hinge"], f"{path}.hinge"))

    def to_yaml(self) -> dict[str, Any]:
        from ..writer import _angle  # (the writer imports the reader, the registry)

        out: dict[str, Any] = {"type": self.kind, "handle": self.handle}
        if self.hinge is not None:
            out["hinge"] = {"point": [float(x) for x in self.hinge.point],
                            "axis": [float(x) for x in self.hinge.axis]}
        out["travel"] = _angle(self.travel) if self.kind == "revolute" else float(self.travel)
        out["mass"] = float(self.mass)
        for key in ("spring", "damping", "friction"):
            if getattr(self, key) != 0.0:
                out[key] = float(getattr(self, key))
        if self.friction_speed != FRICTION_SPEED:
            out["friction_speed"] = float(self.friction_speed)
        g = self.grasp
        out["grasp"] = {"radius": float(g.radius), "release": float(g.release),
                        "stiffness": float(g.stiffness), "damping": float(g.damping)}
        return out

    def physics(self, scene: Scene) -> FacetPhysics:
        return HANDLES[self.kind](self)

    def body(self) -> str:
        return self.handle

    def label(self) -> str:
        return f"{self.name} ({self.kind})"

    def drawn_at(self, T_world: dict[str, Array], readings: dict[str, Any]) -> Array | None:
        """Its handle where the joint's position in ``readings`` has moved it (0 when
        missing)."""
        T0 = T_world.get(self.handle)
        if T0 is None:
            return None
        return handle_pose(self, T0, float(readings.get(f"{self.name}.position", 0.0)))

    def shapes(self) -> list[Shape]:
        """What moves with its handle, in the handle's frame (x out of it): a drawer's box
        behind its front, a door's panel from the hinge line past the handle."""
        if self.hinge is None:
            w, h = BOX_FRONT
            T = se3.transform_from_rt(np.eye(3), [-HANDLE_OUT - BOX_DEPTH / 2, 0.0, 0.0])
            return [Shape("box", (BOX_DEPTH, w, h), T, WOOD, 0.8, "moving")]
        # the panel in the plane of the hinge's axis and the handle's arm, behind the handle
        a = self.hinge.axis / np.linalg.norm(self.hinge.axis)
        p = self.hinge.point
        arm = -p - float(-p @ a) * a
        lever = float(np.linalg.norm(arm))
        u = arm / lever
        n = np.cross(a, u)
        height = min(max(1.5 * lever, 0.3), 0.6)
        foot = p + float(-p @ a) * a  # the hinge line's point level with the handle
        back = -(np.sign(float(n[0])) or 1.0) * n  # its thickness goes away from the handle (-x)
        centre = foot + (lever + 0.05) / 2 * u + PANEL_THICKNESS / 2 * back
        T = se3.transform_from_rt(np.column_stack([u, a, np.cross(u, a)]), centre)
        return [Shape("box", (lever + 0.05, height, PANEL_THICKNESS), T, WOOD, 0.8, "moving")]

    def footprint(self, scene: Scene) -> list[tuple[Array, float]]:
        """Its handle's path, at 9 points from 0 to its travel."""
        T0 = scene.bodies[self.handle].T_world
        return [(handle_pose(self, T0, float(q))[:3, 3], 0.0) for q in np.linspace(0.0, self.travel, 9)]


def _hinge(r: Any, v: Any, path: str) -> Hinge:
    """``{point: [3], axis: [3]}`` in the handle's frame; the axis normalised, the handle
    (the frame's origin) at least :data:`MIN_LEVER` from the line."""
    d = r.fields(v, path, {"point", "axis"})
    hinge = Hinge(r.vector(d["point"], f"{path}.point", 3), r.vector(d["axis"], f"{path}.axis", 3, unit=True))
    if not hinge.lever >= MIN_LEVER:
        raise r.fail(f"{path}.point", f"the handle (the frame's origin) is {hinge.lever:.4g} m from the "
                                      f"hinge line: it must be at least {MIN_LEVER} m off it")
    return hinge


# -- its physics ----------------------------------------------------------------------
def joint_force(position: float, speed: float, joint: Joint) -> float:
    """Resistance of the joint in its own unit, N along a prismatic joint's axis or N m
    about a revolute joint's hinge (negative: resists opening)."""
    return (-joint.spring * position - joint.damping * speed
            - joint.friction * math.tanh(speed / joint.friction_speed))


class Handle(FacetPhysics):
    """A handle on a joint, pulled by the hand that grasped it: the parts every kind of
    joint shares. A kind says where its handle is and how it moves (:meth:`_path`).

    The hand grasps the handle when it comes within the grasp radius of where the handle
    is now and lets go beyond the release distance; while held, a spring-damper joins
    them, ``F_ee = -k (p_ee - p_handle) - c (v_ee - J qdot)`` with ``J = dp_handle/dq``.
    The joint is driven by the generalised force ``J . (-F_ee)`` (for a hinge the torque
    ``((p_handle - p_hinge) x F_handle) . axis``), resisted by :func:`joint_force`, and
    stops at 0 and at its travel.

    Attributes
    ----------
    position : float
        From 0, m or rad.
    speed : float
        m/s or rad/s.
    attached : bool
        Whether the hand holds the handle.
    """

    def __init__(self, joint: Joint):
        self.joint = joint
        self.name = joint.name
        self.inertia = joint.inertia
        self._clear()

    def reset(self, world: World) -> None:
        self._clear()

    def _clear(self) -> None:
        """At 0, released."""
        self.position = 0.0
        self.speed = 0.0
        self.attached = False
        self.max_position = 0.0
        self.grasps = 0

    def handle_transform(self, T_world_handle0: Array) -> Array:
        """``T_world_handle`` at the current position (``T_world_handle0``: at 0)."""
        return handle_pose(self.joint, T_world_handle0, self.position)

    def _path(self, T_world_handle0: Array) -> tuple[float, float, float, float, float, float]:
        """The handle's origin at the current position and its derivative by the
        position (world), as floats."""
        raise NotImplementedError

    def step(self, world: World, dt: float) -> Array:
        """Grasp or release, move by ``dt``; return the wrench on the ee, shape (6,): the
        grasp's force, at the hand's origin (no moment)."""
        # (on floats: the same numbers as on 3-vectors, without numpy's per-call cost)
        T_world_ee, twist, T_world_handle0 = world.T_world_ee, world.twist, world.poses[self.joint.handle]
        J, G = self.joint, self.joint.grasp
        px, py, pz, jx, jy, jz = self._path(T_world_handle0)  # the handle, d handle / d position
        (_, _, _, ex), (_, _, _, ey), (_, _, _, ez), _ = T_world_ee.tolist()
        dx, dy, dz = ex - px, ey - py, ez - pz
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        if not self.attached and dist <= G.radius:
            self.attached = True
            self.grasps += 1
        elif self.attached and dist > G.release:
            self.attached = False
        fx = fy = fz = pull = 0.0  # force on the ee, and the generalised force on the joint
        if self.attached:
            k, c, s = G.stiffness, G.damping, self.speed
            vx, vy, vz = twist[:3].tolist()
            fx, fy, fz = (-k * dx - c * (vx - s * jx), -k * dy - c * (vy - s * jy),
                          -k * dz - c * (vz - s * jz))
            pull = 0.0 + -fx * jx + -fy * jy + -fz * jz  # (summed as numpy's dot sums)
        accel = (pull + joint_force(self.position, self.speed, J)) / self.inertia
        self.speed += accel * dt
        self.position += self.speed * dt
        if self.position <= 0.0:
            self.position, self.speed = 0.0, max(self.speed, 0.0)
        elif self.position >= J.travel:
            self.position, self.speed = J.travel, min(self.speed, 0.0)
        self.max_position = max(self.max_position, self.position)
        return np.array((fx, fy, fz, 0.0, 0.0, 0.0))

    def readings(self, world: World) -> dict[str, float | bool]:
        n = self.name
        return {f"{n}.position": self.position, f"{n}.speed": self.speed, f"{n}.held": self.attached,
                f"{n}.grasps": float(self.grasps), f"{n}.max_position": self.max_position}

    def outcome(self, world: World, thresholds: dict[str, float]) -> dict[str, Any]:
        """Opening (the joint's unit), the opening to reach (the task's ``thresholds``:
        the travel when it names none), whether the handle is held, how often it was
        grasped."""
        return {"opening": self.position, "open_fraction": self.position / self.joint.travel,
                "max_opening": self.max_position, "attached": self.attached, "grasps": self.grasps,
                "target_opening": thresholds.get(f"{self.name}.position", self.joint.travel)}


class PrismaticHandle(Handle):
    """A handle on a prismatic joint along the handle body's x axis (a drawer): the
    handle at ``h0 + q x0``, ``J = x0``, driven by the pull along its axis."""

    def _path(self, T_world_handle0: Array) -> tuple[float, float, float, float, float, float]:
        (ax, _, _, hx), (ay, _, _, hy), (az, _, _, hz), _ = T_world_handle0.tolist()  # axis, handle
        o = self.position
        return hx + o * ax, hy + o * ay, hz + o * az, ax, ay, az


class RevoluteHandle(Handle):
    """A handle on a revolute joint (a hinged door), turned about the hinge line by the
    angle ``q``: with ``r0 = p_handle0 - p_hinge`` split into ``r_par`` along the unit
    axis ``a`` and ``r_perp`` across it, the handle is at ``p_hinge + r_par + cos q
    r_perp + sin q (a x r_perp)`` and ``J = a x (p_handle - p_hinge)``, of length the
    lever; driven by the torque about the hinge, of inertia ``mass lever^2``."""

    def __init__(self, joint: Joint):
        super().__init__(joint)
        self._key = b""  # the pose at 0 (bytes) that _arm was worked out for
        self._arm: tuple[float, ...] = ()

    def _path(self, T_world_handle0: Array) -> tuple[float, float, float, float, float, float]:
        key = T_world_handle0.tobytes()
        if key != self._key:
            self._arm, self._key = self._arm_of(T_world_handle0), key
        ox, oy, oz, ux, uy, uz, bx, by, bz = self._arm
        c, s = math.cos(self.position), math.sin(self.position)
        rx, ry, rz = c * ux + s * bx, c * uy + s * by, c * uz + s * bz  # r now, less r_par
        return ox + rx, oy + ry, oz + rz, c * bx - s * ux, c * by - s * uy, c * bz - s * uz

    def _arm_of(self, T_world_handle0: Array) -> tuple[float, ...]:
        """``p_hinge + r_par``, ``r_perp`` and ``a x r_perp`` (world), as floats."""
        hinge = self.joint.hinge
        assert hinge is not None  # (a revolute joint has one)
        R0, p0 = T_world_handle0[:3, :3], T_world_handle0[:3, 3]
        a = R0 @ hinge.axis
        centre = R0 @ hinge.point + p0
        r0 = p0 - centre
        across = r0 - float(r0 @ a) * a
        return (*(p0 - across).tolist(), *across.tolist(), *np.cross(a, across).tolist())


HANDLES: dict[str, type[Handle]] = {"prismatic": PrismaticHandle, "revolute": RevoluteHandle}
"""The handle physics of each kind of joint (:data:`JOINT_KINDS`)."""
