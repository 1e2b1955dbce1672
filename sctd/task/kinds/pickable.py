"""Things the hand picks up and the places they rest on: the ``support`` and ``item``
facets of a body.

A **support** is a flat top things rest on (a shelf, a table, a fridge door's shelf):
the body's origin is the top's centre, its z up, the top ``size`` along the body's x and
y, optionally a ``rim`` of that height around it that what it holds must be lifted over.
It reports ``<body>.items``, how many items rest on it.

An **item** is an upright cylinder the hand can pick up (a cup, a bottle): the body's
origin is the middle of its base, its z along its axis. It starts resting on a
support (the body's pose is its pose on the support's default pose, and it moves with
the support where a trial puts it). The hand's two fingers close along the hand's y
axis, their tips' middle at the hand's origin: they take the item when they close with
its axis between them (the fingers across the axis, within ``aim`` of it along the hand's
x, on its side between 10 % of its height and 1 cm under its top), and hold it as long as
their squeeze ``force`` gives friction enough, ``2 friction force >= mass (g + a)``,
once it is off its support; past that it slips out and falls. Fingers that close on it
off its axis slide it to their middle (it is light beside the hand). A dropped item lies
where it fell, out of the hand's reach. Opened, they let go of it: it lands standing on a
support when its base is over the support's top (inside the rim), at most ``max_drop``
above it, and tilted less than ``topple``; otherwise it is dropped. While the hand carries
it, a support's top and rim push it back (a contact spring), and the push reaches the
hand. It reports whether it is ``held``, how often it was grasped (``grasps``) and slipped
(``slips``), whether it was ``dropped`` or ``resting`` on a support, how far its base is
above where it rested at the start (``lifted``, m), its ``tilt`` from upright (rad) and the
push of a support on it (``force`` now, ``max_force``, N).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from sctd import se3

from ..model import Scene
from .base import Array, Facet, FacetPhysics, Shape, World

F = TypeVar("F", bound=Facet)
GRAVITY = 9.81
CONTACT_STIFFNESS = 3000.0  # N/m: a support's top and rim against an item carried into them
CONTACT_DAMPING = 60.0  # N s/m
DEEP = 0.05  # m: a contact deeper than this is an item under the support, not in its top
FREE = 0.002  # m: fingers this much wider than an item have let go of it
SUPPORTED = 0.001  # m: a base within this of a top rests on it (the top bears the item's weight)
LOW, TOP_GAP = 0.10, 0.01  # fingers on an item's side: above 10 % of its height, 1 cm under its top


def _f(x: float) -> float:
    return float(x)


def facet_of(scene: Scene, body: str, kind: type[F]) -> F:
    """The body's facet of ``kind`` (the reader checked it has one)."""
    f = scene.bodies[body].facets[kind.key]
    assert isinstance(f, kind)
    return f


def across_fingers(T_world_ee: Array, T_world_cyl: Array, f: Any, radius: float, span: tuple[float, float],
                   aim: float) -> bool:
    """Whether a cylinder (axis its frame's z from its origin, ``radius``) runs between
    the open fingers ``f`` where they can take it: the fingers' middle at a height along
    the axis within ``span``, their line (the hand's y) within 25 deg of square to the
    axis, the axis within ``aim`` of their middle along the hand's x and within what the
    open fingers leave along their line; and the cylinder no wider than they open."""
    R_ee, o_ee = T_world_ee[:3, :3], T_world_ee[:3, 3]
    axis, base = T_world_cyl[:3, 2], T_world_cyl[:3, 3]
    h = float((o_ee - base) @ axis)
    if not span[0] <= h <= span[1]:
        return False
    d = R_ee.T @ (base + h * axis - o_ee)  # the axis from the fingertips' middle (hand frame)
    across = abs(float(R_ee[:, 1] @ axis))  # the fingers' line against the axis
    return 2 * radius <= f.max_width and across < math.sin(math.radians(25.0)) and \
        abs(float(d[0])) <= aim and abs(float(d[1])) <= f.max_width / 2 - radius + FREE


@dataclass(frozen=True)
class Support(Facet):
    """A flat top things rest on (see the module doc).

    Attributes
    ----------
    size : tuple of 2 floats
        Its top's length along the body's x and y, m.
    rim : float
        Height of a rim around it, m (0: none).
    """

    key = "support"
    order = 10
    quantities = ("items",)

    size: tuple[float, float]
    rim: float = 0.0

    @classmethod
    def read(cls, r: Any, v: Any, path: str) -> Support:
        d = r.fields(v, path, {"size"}, {"rim"})
        sx, sy = r.vector(d["size"], f"{path}.size", 2).tolist()
        if sx <= 0 or sy <= 0:
            raise r.fail(f"{path}.size", f"expected two lengths > 0, got [{sx}, {sy}]")
        return cls((sx, sy), r.nonneg(d.get("rim", 0.0), f"{path}.rim"))

    def to_yaml(self) -> dict[str, Any]:
        out: dict[str, Any] = {"size": [_f(self.size[0]), _f(self.size[1])]}
        if self.rim:
            out["rim"] = _f(self.rim)
        return out

    def inside(self, p_top: Array, margin: float = 0.0) -> bool:
        """Whether the point ``p_top`` (the support's frame) is over its top, at least
        ``margin`` in from its edges."""
        return abs(float(p_top[0])) <= self.size[0] / 2 - margin and \
            abs(float(p_top[1])) <= self.size[1] / 2 - margin

    def physics(self, body: str, scene: Scene) -> FacetPhysics:
        return _SupportPhysics(body)

    def shapes(self) -> list[Shape]:
        board = Shape("box", (*self.size, 0.02), se3.transform_from_rt(np.eye(3), [0.0, 0.0, -0.01]),
                      (0.72, 0.6, 0.45))
        if not self.rim:
            return [board]
        sx, sy, h, t = self.size[0], self.size[1], self.rim, 0.005
        walls = [((sx, t, h), (0.0, (sy - t) / 2, h / 2)), ((sx, t, h), (0.0, -(sy - t) / 2, h / 2)),
                 ((t, sy, h), ((sx - t) / 2, 0.0, h / 2)), ((t, sy, h), (-(sx - t) / 2, 0.0, h / 2))]
        glass = (0.85, 0.85, 0.9)
        return [board, *(Shape("box", size, se3.transform_from_rt(np.eye(3), list(at)), glass, 0.6)
                         for size, at in walls)]


class _SupportPhysics(FacetPhysics):
    """Counts the items resting on it (they say where they rest)."""

    def __init__(self, body: str):
        self.body = body

    def reset(self, world: World) -> None:
        pass

    def step(self, world: World, dt: float) -> Array:
        return np.zeros(6)

    def readings(self, world: World) -> dict[str, float | bool]:
        n = sum(1 for facets in world.physics.values() for p in facets.values()
                if isinstance(p, _ItemPhysics) and p.on == self.body)
        return {f"{self.body}.items": float(n)}


@dataclass(frozen=True)
class Item(Facet):
    """Something the hand picks up: an upright cylinder (see the module doc).

    Attributes
    ----------
    on : str
        The support it rests on at the start (``rests_on`` in a task file: YAML reads a
        bare ``on`` as true).
    mass : float
        kg.
    radius, height : float
        m; the fingers take it at ``2 radius``.
    grip : float
        Height above its base a person takes it at, m.
    friction : float
        Between the fingers and it.
    topple : float
        rad: let go tilted further from upright, it falls over.
    max_drop : float
        m: let go higher than this over a support, it falls over.
    aim : float
        m: the fingers take it with its axis within this of their tips' middle, along the
        hand's x.
    frames : dict of str to (position, rpy)
        Named frames fixed in it, published as objects (position m, roll-pitch-yaw rad).
    """

    key = "item"
    order = 20
    quantities = ("held", "grasps", "slips", "dropped", "resting", "lifted", "tilt", "force", "max_force")
    flags = ("held", "dropped", "resting")

    on: str
    mass: float
    radius: float
    height: float
    grip: float
    friction: float = 0.8
    topple: float = math.radians(20.0)
    max_drop: float = 0.03
    aim: float = 0.015
    frames: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = \
        field(default_factory=dict)

    @classmethod
    def read(cls, r: Any, v: Any, path: str) -> Item:
        d = r.fields(v, path, {"rests_on", "mass", "radius", "height", "grip"},
                     {"friction", "topple", "max_drop", "aim", "frames"})
        height = r.positive(d["height"], f"{path}.height")
        grip = r.number(d["grip"], f"{path}.grip")
        if not LOW * height <= grip <= height - TOP_GAP:
            raise r.fail(f"{path}.grip", f"expected a height on its side, {LOW * height:.3f}-"
                                         f"{height - TOP_GAP:.3f} m above its base, got {grip}")
        frames = {}
        for key, f in r.mapping(d.get("frames", {}), f"{path}.frames").items():
            where = f"{path}.frames.{key}"
            fd = r.fields(f, where, {"position"}, {"rpy"})
            rpy = fd.get("rpy", [0.0, 0.0, 0.0])
            if not isinstance(rpy, list) or len(rpy) != 3:
                raise r.fail(f"{where}.rpy", "expected a list of 3 angles")
            frames[r.name(key, where)] = (tuple(r.vector(fd["position"], f"{where}.position", 3).tolist()),
                                          tuple(r.angle(a, f"{where}.rpy[{i}]") for i, a in enumerate(rpy)))
        return cls(r.name(d["rests_on"], f"{path}.rests_on"), r.positive(d["mass"], f"{path}.mass"),
                   r.positive(d["radius"], f"{path}.radius"), height, grip,
                   r.positive(d.get("friction", 0.8), f"{path}.friction"),
                   r.angle(d.get("topple", math.radians(20.0)), f"{path}.topple", lo=0.0, hi=math.pi / 2,
                           lo_open=True),
                   r.nonneg(d.get("max_drop", 0.03), f"{path}.max_drop"),
                   r.positive(d.get("aim", 0.015), f"{path}.aim"), frames)

    def check(self, r: Any, body: str, scene: Scene, path: str) -> None:
        where = scene.bodies.get(self.on)
        sup = where.facets.get("support") if where is not None else None
        if not isinstance(sup, Support):
            names = [n for n, b in scene.bodies.items() if "support" in b.facets]
            raise r.fail(f"{path}.rests_on",
                         f"{self.on!r} is no support (supports: {', '.join(names) or 'none'})")
        p = (se3.invert_transform(where.T_world) @ scene.bodies[body].T_world)[:3, 3]  # type: ignore[union-attr]
        if abs(float(p[2])) > 0.005 or not sup.inside(p, self.radius):
            raise r.fail(f"{path}.rests_on", f"{body!r} does not stand on {self.on!r}: its base is at "
                                       f"[{p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}] in the support's frame, "
                                       f"which must be on its top ({sup.size[0]:g} x {sup.size[1]:g} m, "
                                       f"z 0) with the item's radius to spare")

    def to_yaml(self) -> dict[str, Any]:
        out: dict[str, Any] = {"rests_on": self.on, "mass": _f(self.mass), "radius": _f(self.radius),
                               "height": _f(self.height), "grip": _f(self.grip)}
        defaults = Item("", 1.0, 1.0, 1.0, 0.5)
        for name in ("friction", "topple", "max_drop", "aim"):
            if getattr(self, name) != getattr(defaults, name):
                out[name] = _f(getattr(self, name))
        if self.frames:
            out["frames"] = {n: {"position": [_f(x) for x in p], "rpy": [_f(a) for a in rpy]}
                             for n, (p, rpy) in self.frames.items()}
        return out

    def frame_names(self) -> list[str]:
        return list(self.frames)

    def frame_transforms(self) -> dict[str, Array]:
        """Its named frames in its own frame (4x4)."""
        from ..reader import rpy_matrix  # (the reader imports the registry)

        return {n: se3.transform_from_rt(rpy_matrix(np.array(rpy)), list(p))
                for n, (p, rpy) in self.frames.items()}

    def physics(self, body: str, scene: Scene) -> FacetPhysics:
        return _ItemPhysics(body, self, scene)

    def shapes(self) -> list[Shape]:
        return [Shape("cylinder", (self.radius, self.radius, self.height),
                      se3.transform_from_rt(np.eye(3), [0.0, 0.0, self.height / 2]), (0.3, 0.55, 0.85))]


class _ItemPhysics(FacetPhysics):
    """An item resting, held or dropped (see the module doc)."""

    def __init__(self, body: str, item: Item, scene: Scene):
        self.body, self.item = body, item
        self._T_default_support = scene.bodies[item.on].T_world
        self._supports = {n: f for n, f in scene.with_facet("support").items() if isinstance(f, Support)}
        self._frames = item.frame_transforms()
        self.on: str | None = item.on
        self.T_ee_item: Array | None = None
        self._start_z = 0.0
        self._v_prev: Array | None = None
        self.grasps = self.slips = 0
        self.dropped = False
        self.force = self.max_force = 0.0
        self._supported = True

    # -- the state ---------------------------------------------------------------------
    def reset(self, world: World) -> None:
        moved = world.poses[self.item.on] @ se3.invert_transform(self._T_default_support)
        world.poses[self.body] = moved @ world.poses[self.body]  # (on its support, where the trial puts it)
        self._start_z = float(world.poses[self.body][2, 3])
        self.on, self.T_ee_item, self._v_prev = self.item.on, None, None
        self._supported = True
        self.grasps = self.slips = 0
        self.dropped = False
        self.force = self.max_force = 0.0

    @property
    def held(self) -> bool:
        return self.T_ee_item is not None

    def step(self, world: World, dt: float) -> Array:
        f = world.fingers
        T = world.poses[self.body]
        if self.T_ee_item is not None:
            if f is None or (not f.closing and f.width > 2 * self.item.radius + FREE):
                self._let_go(world)  # (opened clear of it)
                return np.zeros(6)
            if f.closing:
                f.block(2 * self.item.radius)
            world.poses[self.body] = T = world.T_world_ee @ self.T_ee_item
            wrench = self._contact(world, T)
            if f.closing and not self._supported and self._slipping(world, f, dt):
                self.slips += 1
                self._let_go(world)
                return np.zeros(6)
            return wrench
        if not self.dropped and f is not None and f.closing and f.width <= 2 * self.item.radius + FREE \
                and self._between(world, f):
            f.block(2 * self.item.radius)
            T_ee = se3.invert_transform(world.T_world_ee) @ T
            T_ee[1, 3] = 0.0  # (the closing fingers slide it to their middle)
            self.T_ee_item = T_ee
            self.grasps += 1
            self.on, self._v_prev = None, None
        return np.zeros(6)

    def _between(self, world: World, f: Any) -> bool:
        """Whether the item's axis runs between the open fingers, where they take it."""
        it = self.item
        return across_fingers(world.T_world_ee, world.poses[self.body], f, it.radius,
                              (LOW * it.height, it.height - TOP_GAP), it.aim)

    def _slipping(self, world: World, f: Any, dt: float) -> bool:
        """Whether the squeeze no longer holds it: friction ``2 mu F`` against its weight
        and what the hand's acceleration asks of it."""
        v = world.twist[:3]
        a = np.zeros(3) if self._v_prev is None or dt <= 0 else (v - self._v_prev) / dt
        self._v_prev = v.copy()
        need = self.item.mass * float(np.linalg.norm(a + np.array([0.0, 0.0, GRAVITY])))
        return f is None or need > 2.0 * self.item.friction * f.force

    def _let_go(self, world: World) -> None:
        """Released: it lands standing on a support, or it is dropped."""
        self.T_ee_item, self._v_prev = None, None
        T = world.poses[self.body]
        tilt = math.acos(max(-1.0, min(1.0, float(T[2, 2]))))
        for name, sup in self._supports.items():
            S = world.poses[name]
            p = se3.invert_transform(S) @ T[:, 3]
            standing = tilt < self.item.topple and sup.inside(p[:3], self.item.radius)
            if standing and -DEEP < p[2] <= self.item.max_drop:
                yaw = math.atan2(float(T[1, 0]), float(T[0, 0]))
                world.poses[self.body] = se3.transform_from_rt(
                    se3.matrix_from_rotvec([0.0, 0.0, yaw]) @ S[:3, :3],
                    (S @ np.array([p[0], p[1], 0.0, 1.0]))[:3])
                self.on = name
                return
        self.on, self.dropped = None, True

    def _contact(self, world: World, T: Array) -> Array:
        """The supports' push on the carried item (its base against a top, over a rim),
        on the hand."""
        wrench = np.zeros(6)
        self.force = 0.0
        self._supported = False  # its base on a top: the top bears its weight
        base = T[:, 3]
        for name, sup in self._supports.items():
            S = world.poses[name]
            p = se3.invert_transform(S) @ base
            over = sup.inside(p[:3], -self.item.radius)  # (any of its base over the top)
            rim = sup.rim if sup.rim and not sup.inside(p[:3], self.item.radius) else 0.0
            depth = rim - float(p[2])
            if over and -SUPPORTED < float(p[2]) <= SUPPORTED and not rim:
                self._supported = True
            if not over or depth <= 0.0 or depth > DEEP + rim:
                continue
            up = S[:3, 2]
            v_in = -float(world.twist[:3] @ up)
            push = max(0.0, CONTACT_STIFFNESS * depth + CONTACT_DAMPING * v_in)
            force = push * up
            r = base[:3] - world.T_world_ee[:3, 3]
            wrench[:3] += force
            wrench[3:] += np.cross(r, force)
            self.force += push
        self.max_force = max(self.max_force, self.force)
        return wrench

    # -- what it reports -----------------------------------------------------------------
    def readings(self, world: World) -> dict[str, float | bool]:
        T = world.poses[self.body]
        b = self.body
        return {f"{b}.held": self.held, f"{b}.grasps": float(self.grasps), f"{b}.slips": float(self.slips),
                f"{b}.dropped": self.dropped, f"{b}.resting": self.on is not None,
                f"{b}.lifted": float(T[2, 3]) - self._start_z,
                f"{b}.tilt": math.acos(max(-1.0, min(1.0, float(T[2, 2])))),
                f"{b}.force": self.force, f"{b}.max_force": self.max_force}

    def load(self) -> tuple[float, Array] | None:
        if self.T_ee_item is None:
            return None
        return self.item.mass, (self.T_ee_item @ np.array([0.0, 0.0, self.item.height / 2, 1.0]))[:3]

    def frames(self, world: World) -> dict[str, Array]:
        T = world.poses[self.body]
        return {n: T @ F for n, F in self._frames.items()}
