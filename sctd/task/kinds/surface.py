"""A body's solid surface the hand touches, and a push button in it: the ``surface``
and ``button`` facets of a body.

A **surface** is the plane through the body's origin normal to its x axis, solid behind
it (towards -x). A point of the hand (its ``touch`` frames: ``hand`` and the held
object's frames; all of them when the file does not say) that is ``d`` behind the plane
is pushed out along the normal by ``max(0, stiffness d + damping v_in)`` (``v_in`` its
speed into the surface) and held back along it by Coulomb friction, ``friction`` times
that, built up over ``friction_speed`` (tanh). It reports, by its body's name, the
normal force the hand presses it with (``force`` now, ``max_force``, N) and whether a
point of the hand is pressed into it (``touching``).

A **button** sits in its body's surface (a light switch, an elevator's call button): its
face, a disc of ``radius`` centred on the body's origin, flush with the surface at rest,
travels in (along -x) against a spring up to ``travel``, where it rests on the wall;
pushed in past ``click`` it switches (its flag ``on`` toggles), and switches again only
once it came back out to half that. The button is light beside the hand: at every
instant its face is where the contact and its spring balance, ``stiffness (d - s) =
preload + spring s`` for the hand's point ``d`` past the face's rest plane and the face
pushed in by ``s`` in [0, travel]. It reports how far it is in (``position``, m), ``on``
and how often it switched (``presses``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from sctd import se3
from sctd.skill.reader import kind_of

from ..model import Scene
from .base import Array, Facet, FacetPhysics, Shape, World

HAND = "hand"  # (the reader's name for the hand: the reader imports the registry)
MAX_STIFFNESS = 50000.0
"""N/m: the stiffest contact the simulator's 1 kHz step integrates stably against the
arm's effective mass at the hand."""
FRICTION_SPEED = 0.01
"""m/s: ``friction_speed`` when the file leaves it out."""
WALL = 0.6  # m: the side of a surface's slab as the view draws it
WALL_DEPTH = 0.02  # m: its thickness behind the plane


def _moving(scene: Scene) -> tuple[str, ...]:
    """The frames that move with the hand: ``hand`` and the held frames."""
    return (HAND, *(scene.held.frames if scene.held is not None else ()))


@dataclass(frozen=True)
class Surface(Facet):
    """A body's solid surface: the plane through the body's origin normal to its x axis,
    solid behind it (see the module doc).

    Attributes
    ----------
    stiffness : float
        N/m of the contact (a fingertip's or a tool's against the wall).
    damping : float
        N s/m.
    friction : float
        The coefficient of friction (tangential over normal force).
    friction_speed : float
        m/s over which the friction builds up.
    touch : tuple of str
        The frames that touch it: ``hand`` (the end-effector's origin) and held frames
        (empty as read: :meth:`completed` fills in every frame that moves with the hand).
    """

    key = "surface"
    order = 1
    quantities = ("force", "max_force", "touching")
    flags = ("touching",)

    stiffness: float
    damping: float
    friction: float
    friction_speed: float
    touch: tuple[str, ...]

    @classmethod
    def read(cls, r: Any, v: Any, path: str) -> Surface:
        d = r.fields(v, path, {"stiffness"}, {"damping", "friction", "friction_speed", "touch"})
        stiffness = r.number(d["stiffness"], f"{path}.stiffness", lo=0.0, hi=MAX_STIFFNESS, lo_open=True)
        damping, friction = (r.nonneg(d.get(k, 0.0), f"{path}.{k}") for k in ("damping", "friction"))
        touch: tuple[str, ...] = ()
        if "touch" in d:
            names = d["touch"]
            if not isinstance(names, list) or not names:
                raise r.fail(f"{path}.touch", f"expected a non-empty list of frames, got {kind_of(names)}")
            touch = tuple(r.string(n, f"{path}.touch[{i}]") for i, n in enumerate(names))
            if len(set(touch)) < len(touch):
                raise r.fail(f"{path}.touch", f"a frame is listed twice: {', '.join(touch)}")
        return cls(stiffness, damping, friction,
                   r.positive(d.get("friction_speed", FRICTION_SPEED), f"{path}.friction_speed"), touch)

    def completed(self, r: Any, body: str, scene: Scene, path: str) -> Surface:
        """Its ``touch`` checked against the frames that move with the hand, or set to all
        of them when the file does not say; the held object may not share its body's name
        (it reports its readings by it)."""
        moving = _moving(scene)
        for i, f in enumerate(self.touch):
            if f not in moving:
                raise r.fail(f"{path}.touch[{i}]", f"expected a frame that moves with the hand, got {f!r} "
                                                   f"(frames: {', '.join(moving)})")
        if scene.held is not None and body == scene.held.name:
            raise r.fail(path, f"the held object is called {body!r} too: a surface reports its readings "
                               "by its body's name")
        return replace(self, touch=self.touch or moving)

    def check(self, r: Any, body: str, scene: Scene, path: str) -> None:
        """Every frame that touches it starts in front of it (it is solid behind its plane)."""
        T_start = scene.start.T_world
        frames = scene.held.frames if scene.held is not None else {}
        T_body_world = se3.invert_transform(scene.bodies[body].T_world)
        for f in self.touch:
            T = T_start @ frames[f] if f != HAND else T_start
            x = float((T_body_world @ T)[0, 3])
            if not x > 0.0:
                raise r.fail(f"{path.rsplit('.bodies.', 1)[0]}.start",
                             f"{f} starts {-x:.3g} m behind the surface of {body!r}: a surface is solid "
                             "behind its plane (the body's -x side)")

    def to_yaml(self) -> dict[str, Any]:
        out: dict[str, Any] = {"stiffness": float(self.stiffness)}
        for key, default in (("damping", 0.0), ("friction", 0.0), ("friction_speed", FRICTION_SPEED)):
            if getattr(self, key) != default:
                out[key] = float(getattr(self, key))
        out["touch"] = list(self.touch)  # (its default depends on the held object: written)
        return out

    def physics(self, body: str, scene: Scene) -> FacetPhysics:
        frames = {HAND: np.eye(4), **(scene.held.frames if scene.held is not None else {})}
        points = [frames[f] for f in self.touch]
        button = scene.bodies[body].facets.get("button")
        if isinstance(button, Button):  # (a surface with a button gives way there)
            return PushButton(body, self, button, points)
        return Contact(body, self, points)

    def shapes(self) -> list[Shape]:
        slab = se3.transform_from_rt(np.eye(3), [-WALL_DEPTH / 2 - 1e-3, 0.0, 0.0])
        grey = (170 / 255, 170 / 255, 160 / 255)
        return [Shape("box", (WALL_DEPTH, WALL, WALL), slab, grey, name="surface", label="{body}'s surface")]


@dataclass(frozen=True)
class Button(Facet):
    """A push button in its body's surface (see the module doc).

    Attributes
    ----------
    radius : float
        m of the face.
    travel : float
        m from rest to where it rests on the wall.
    click : float
        m pushed in past which it switches; at most ``travel``.
    spring : float
        N/m of its return spring.
    preload : float
        N its spring holds it out with: the push it takes to start moving.
    """

    key = "button"
    order = 2
    quantities = ("position", "on", "presses")
    flags = ("on",)

    radius: float
    travel: float
    click: float
    spring: float
    preload: float

    @classmethod
    def read(cls, r: Any, v: Any, path: str) -> Button:
        d = r.fields(v, path, {"radius", "travel", "click"}, {"spring", "preload"})
        radius, travel, click = (r.positive(d[k], f"{path}.{k}") for k in ("radius", "travel", "click"))
        if click > travel:
            raise r.fail(f"{path}.click", f"must be at most the travel {travel}, got {click}")
        spring, preload = (r.nonneg(d.get(k, 0.0), f"{path}.{k}") for k in ("spring", "preload"))
        return cls(radius, travel, click, spring, preload)

    def completed(self, r: Any, body: str, scene: Scene, path: str) -> Button:
        """Refused without its body's surface (the wall it is pushed into)."""
        if "surface" not in scene.bodies[body].facets:
            raise r.fail(path, "a button sits in its body's surface: the body needs a surface "
                               "(the wall it is pushed into)")
        return self

    @property
    def click_force(self) -> float:
        """The push that takes the face to its click depth, N."""
        return self.preload + self.spring * self.click

    def to_yaml(self) -> dict[str, Any]:
        out: dict[str, Any] = {"radius": float(self.radius), "travel": float(self.travel),
                               "click": float(self.click)}
        for key in ("spring", "preload"):
            if getattr(self, key) != 0.0:
                out[key] = float(getattr(self, key))
        return out

    def shapes(self) -> list[Shape]:
        q = math.sin(math.pi / 4), math.cos(math.pi / 4)  # (a disc about z turned onto x)
        z_to_x = se3.transform_from_pose([0.0, 0.0, 0.0, 0.0, q[0], 0.0, q[1]])
        return [Shape("cylinder", (self.radius, self.radius, 0.01), z_to_x, (200 / 255, 60 / 255, 60 / 255),
                      name="button", label="{body}")]


class Contact(FacetPhysics):
    """A body's solid surface (:class:`Surface`): the plane through the
    body's origin normal to its x axis, solid behind it, against the points of the hand
    that touch it (its ``touch`` frames, fixed in the hand).

    A point ``d`` m behind the plane, moving into it at ``v_in`` and along it at ``v_t``,
    is pushed out along the normal by ``F_n = max(0, k (d - s) + c v_in)`` (``s``: how
    far the surface gave way there, 0 but in a button) and held back along the plane by
    ``mu F_n tanh(|v_t| / v_s)`` against its slip. The force acts at the point: on the
    hand it is that force and its moment about the hand's origin. A point first seen
    behind the plane (a start drawn into the wall) is not pushed until it has come out
    in front: only what comes through the plane meets it.

    Attributes
    ----------
    force, max_force : float
        The normal force the hand presses the surface with (its points summed), now and
        the highest so far, N.
    touching : bool
        Whether a point of the hand is pressed into it.
    """

    def __init__(self, body: str, surface: Surface, T_ee_points: list[Array]):
        self.name = body
        self.surface = surface
        self._points = [tuple(T[:3, 3].tolist()) for T in T_ee_points]
        self._clear()

    def reset(self, world: World) -> None:
        self._clear()

    def _clear(self) -> None:
        """Nothing touching, no force so far."""
        self.force = self.max_force = 0.0
        self.touching = False
        self._front = [False] * len(self._points)  # per point: it has been in front of the plane

    def _give(self, y: float, z: float, depth: float) -> float:
        """How far the surface gives way where a point presses it at ``(y, z)`` (body
        frame), ``depth`` m past the plane: not at all."""
        return 0.0

    def _begin(self) -> None:
        """Before the points of a step."""

    def _end(self) -> None:
        """After the points of a step."""

    def step(self, world: World, dt: float) -> Array:
        """The points against the surface now; return the wrench on the ee, shape (6,)."""
        # (on floats, as a joint's handle's step: numpy's per-call cost would dominate)
        T_world_ee, twist, T_world_body = world.T_world_ee, world.twist, world.poses[self.name]
        S = self.surface
        (r00, r01, r02, ex), (r10, r11, r12, ey), (r20, r21, r22, ez), _ = T_world_ee.tolist()
        (b00, b01, b02, bx), (b10, b11, b12, by), (b20, b21, b22, bz), _ = T_world_body.tolist()
        vx, vy, vz, wx, wy, wz = twist.tolist()
        wrench = [0.0] * 6
        total, touching = 0.0, False
        self._begin()
        for i, (px, py, pz) in enumerate(self._points):
            ox, oy, oz = r00 * px + r01 * py + r02 * pz, r10 * px + r11 * py + r12 * pz, \
                r20 * px + r21 * py + r22 * pz  # the point from the ee's origin (world)
            qx, qy, qz = ex + ox - bx, ey + oy - by, ez + oz - bz
            x = b00 * qx + b10 * qy + b20 * qz  # in the body's frame
            if x > 0.0 or not self._front[i]:
                self._front[i] = self._front[i] or x > 0.0
                continue
            y, z = b01 * qx + b11 * qy + b21 * qz, b02 * qx + b12 * qy + b22 * qz
            press = -x - self._give(y, z, -x)
            if press <= 0.0:
                continue
            touching = True
            ux, uy, uz = vx + wy * oz - wz * oy, vy + wz * ox - wx * oz, vz + wx * oy - wy * ox
            fn = S.stiffness * press - S.damping * (b00 * ux + b10 * uy + b20 * uz)
            if fn <= 0.0:
                continue
            ty, tz = b01 * ux + b11 * uy + b21 * uz, b02 * ux + b12 * uy + b22 * uz  # slip
            slip = math.sqrt(ty * ty + tz * tz)
            held = S.friction * fn * math.tanh(slip / S.friction_speed) / slip if slip > 1e-12 else 0.0
            fy, fz = -held * ty, -held * tz
            Fx, Fy, Fz = b00 * fn + b01 * fy + b02 * fz, b10 * fn + b11 * fy + b12 * fz, \
                b20 * fn + b21 * fy + b22 * fz
            for k, f in enumerate((Fx, Fy, Fz, oy * Fz - oz * Fy, oz * Fx - ox * Fz, ox * Fy - oy * Fx)):
                wrench[k] += f
            total += fn
        self._end()
        self.force, self.touching = total, touching
        self.max_force = max(self.max_force, total)
        return np.array(wrench)

    def readings(self, world: World) -> dict[str, float | bool]:
        n = self.name
        return {f"{n}.force": self.force, f"{n}.max_force": self.max_force, f"{n}.touching": self.touching}


class PushButton(Contact):
    """A surface with a push button in it (:class:`Button`): within the
    button's radius of the body's origin the surface is the button's face, light beside
    the hand, where the contact and the button's spring balance, ``k (d - s) = preload +
    spring s`` with ``s`` in [0, travel] (beyond its travel it rests on the wall, which
    then holds the push with the contact's stiffness). Pushed in past its click depth it
    switches (``on`` toggles, ``presses`` counts), and again only once it has come back
    out to half that depth.

    Attributes
    ----------
    position : float
        How far the face is pushed in, m (the deepest point's).
    on : bool
    presses : int
    """

    def __init__(self, body: str, surface: Surface, button: Button, T_ee_points: list[Array]):
        self.button = button
        super().__init__(body, surface, T_ee_points)

    def _clear(self) -> None:
        """Out and off, never pressed."""
        super()._clear()
        self.position = 0.0
        self.on = False
        self.presses = 0
        self._armed = True  # it switches when next pushed past its click depth
        self._pushed = 0.0

    def _begin(self) -> None:
        self._pushed = 0.0

    def _give(self, y: float, z: float, depth: float) -> float:
        B = self.button
        if y * y + z * z > B.radius * B.radius:  # the wall around it
            return 0.0
        k = self.surface.stiffness
        s = min(B.travel, max(0.0, (k * depth - B.preload) / (k + B.spring)))
        self._pushed = max(self._pushed, s)
        return s

    def _end(self) -> None:
        B = self.button
        self.position = self._pushed
        if self._armed and self.position >= B.click:
            self.on, self.presses, self._armed = not self.on, self.presses + 1, False
        elif not self._armed and self.position <= 0.5 * B.click:
            self._armed = True

    def readings(self, world: World) -> dict[str, float | bool]:
        n = self.name
        return {**super().readings(world), f"{n}.position": self.position, f"{n}.on": self.on,
                f"{n}.presses": float(self.presses)}
