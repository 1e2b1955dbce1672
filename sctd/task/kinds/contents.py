"""What the hand pours and what it pours into: the ``container`` facet of a body and the
``contents`` facet of the held object.

A **container** is a body that holds what is poured into it: its opening is the body's
origin (z up, the opening's plane its xy plane), ``radius`` and ``depth`` (m); a stream
lands inside when it falls within ``radius - rim_margin`` of the axis, at most
``max_drop`` above the opening.

The **contents** of the held object (``held.contents``: ``mass`` kg when full, the
``outlet`` frame they flow out of along its z, the container body they are meant to go
``into``, the ``flow_angle`` past which they flow and the ``flow_rate``, the fraction of
the full contents per second at 90 deg past it, growing as the sine of the tilt past
it) flow out while the outlet is tilted past the flow angle: into the container when the
outlet is over its opening, spilled otherwise. They report, by the held object's name,
the fractions ``poured``, ``spilled`` and ``remaining``, and whether they are
``flowing``; the arm carries what is left of them with the held object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from sctd import se3

from ..model import Scene
from .base import Array, Facet, FacetPhysics, Shape, World


@dataclass(frozen=True)
class Container(Facet):
    """A body that holds what is poured into it (see the module doc).

    Attributes
    ----------
    radius : float
        Inner radius of the opening, m.
    depth : float
        How deep it is below the opening, m.
    rim_margin : float
        A stream lands inside when it falls within ``radius - rim_margin`` of the axis.
    max_drop : float
        The highest above the opening a stream still lands inside from, m.
    """

    key = "container"
    order = 0

    radius: float
    depth: float
    rim_margin: float = 0.005
    max_drop: float = 0.15

    @classmethod
    def read(cls, r: Any, v: Any, path: str) -> Container:
        c = r.fields(v, path, {"radius", "depth"}, {"rim_margin", "max_drop"})
        radius = r.positive(c["radius"], f"{path}.radius")
        margin = r.nonneg(c.get("rim_margin", 0.005), f"{path}.rim_margin")
        if margin >= radius:
            raise r.fail(f"{path}.rim_margin", f"must be below the radius {radius}, got {margin}")
        return cls(radius, r.positive(c["depth"], f"{path}.depth"), margin,
                   r.positive(c.get("max_drop", 0.15), f"{path}.max_drop"))

    def to_yaml(self) -> dict[str, Any]:
        out: dict[str, Any] = {"radius": float(self.radius), "depth": float(self.depth)}
        for key, default in (("rim_margin", 0.005), ("max_drop", 0.15)):
            if getattr(self, key) != default:
                out[key] = float(getattr(self, key))
        return out

    def extent(self) -> float:
        return self.radius

    def shapes(self) -> list[Shape]:
        T = se3.transform_from_rt(np.eye(3), [0.0, 0.0, -self.depth / 2])
        grey = (110 / 255, 110 / 255, 130 / 255)
        return [Shape("cylinder", (self.radius, self.radius, self.depth), T, grey, 0.7, "container",
                      f"{{body}} ({self.radius * 200:.0f} cm wide)")]


@dataclass(frozen=True)
class Contents(Facet):
    """What flows out of the held object when it is tilted (see the module doc).

    Attributes
    ----------
    mass : float
        kg when full.
    outlet : str
        The held object's frame it flows out of (its z axis: out of the opening).
    into : str
        The container body it is meant to go into; what misses it is spilled.
    flow_angle : float
        Tilt of the outlet's axis from the vertical past which it flows, rad.
    flow_rate : float
        Fraction of the full contents per second at 90 deg past ``flow_angle``; the flow
        grows as the sine of the tilt past it.
    """

    key = "contents"
    holder = "held"
    quantities = ("poured", "spilled", "remaining", "flowing")
    flags = ("flowing",)

    mass: float
    outlet: str
    into: str
    flow_angle: float
    flow_rate: float

    @classmethod
    def read(cls, r: Any, v: Any, path: str) -> Contents:
        c = r.fields(v, path, {"mass", "outlet", "into", "flow_angle", "flow_rate"})
        outlet = r.string(c["outlet"], f"{path}.outlet")
        into = r.string(c["into"], f"{path}.into")
        return cls(r.positive(c["mass"], f"{path}.mass"), outlet, into,
                   r.angle(c["flow_angle"], f"{path}.flow_angle", lo=0.0, hi=math.pi),
                   r.positive(c["flow_rate"], f"{path}.flow_rate"))

    def completed(self, r: Any, body: str, scene: Scene, path: str) -> Contents:
        """Refused unless its outlet is a frame of the held object and it goes into a
        body with a container."""
        frames = scene.held.frames if scene.held is not None else {}
        if self.outlet not in frames:
            raise r.fail(f"{path}.outlet", f"unknown frame {self.outlet!r} of the held object "
                                           f"(frames: {', '.join(frames) or 'none'})")
        bodies = scene.bodies
        if self.into not in bodies or bodies[self.into].container is None:
            raise r.fail(f"{path}.into", f"expected a body with a container, got {self.into!r} (containers: "
                                         f"{', '.join(b for b in bodies if bodies[b].container) or 'none'})")
        return self

    def to_yaml(self) -> dict[str, Any]:
        from ..writer import _angle  # (the writer imports the reader, the registry)

        return {"mass": float(self.mass), "outlet": self.outlet, "into": self.into,
                "flow_angle": _angle(self.flow_angle), "flow_rate": float(self.flow_rate)}

    def physics(self, body: str, scene: Scene) -> FacetPhysics:
        assert scene.held is not None  # (contents are the held object's)
        container = scene.bodies[self.into].container
        assert container is not None  # (checked: contents go into a container)
        return Flow(body, scene.held.frames[self.outlet], self, container)


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

    outlet_in_container: Array
    above_rim: float
    radial: float
    tilt: float
    over_opening: bool


def outlet_geometry(T_world_outlet: Array, container: Container, T_container_world: Array
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


class Flow(FacetPhysics):
    """The held object's contents, poured into a container body or spilled.

    Attributes
    ----------
    remaining, poured, spilled : float
        Fractions of the full contents: still held, in the container, spilled.
    """

    def __init__(self, name: str, T_ee_outlet: Array, contents: Contents, container: Container):
        self.name = name
        self.contents = contents
        self.container = container
        self.T_ee_outlet = T_ee_outlet
        # the outlet's axis in the ee frame: the outlet's tilt from the hand's rotation
        self._outlet_axis = tuple(self.T_ee_outlet[:3, 2].tolist())
        self._key = b""  # the container pose (bytes) _T_container_world inverts
        self._T_container_world = np.eye(4)
        self._clear()

    def reset(self, world: World) -> None:
        self._clear()

    def _clear(self) -> None:
        """Full, nothing poured."""
        self.remaining = 1.0
        self.poured = 0.0
        self.spilled = 0.0
        self._tilt: float | None = None
        self._at: tuple[Array, Array] | None = None  # (T_world_ee, T_container_world)
        self._geometry: OutletGeometry | None = None

    def step(self, world: World, dt: float) -> Array:
        """Pour for ``dt`` s from the hand at ``world.T_world_ee`` (which must not change
        afterwards: :attr:`geometry` is worked out from it when asked); no force."""
        self._flow_for(world.T_world_ee, world.poses[self.contents.into], dt)
        return np.zeros(6)

    def _flow_for(self, T_world_ee: Array, T_world_container: Array, dt: float) -> None:
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

    def _inverse(self, T: Array) -> Array:
        """``T_container_world``, computed again only when the container moved."""
        key = T.tobytes()
        if key != self._key:
            self._T_container_world, self._key = se3.invert_transform(T), key
        return self._T_container_world

    @property
    def flowing(self) -> bool:
        tilt = self._tilt
        return tilt is not None and outlet_stream(tilt, self.contents) > 0.0 and self.remaining > 0.0

    def readings(self, world: World) -> dict[str, float | bool]:
        n = self.name
        return {f"{n}.poured": self.poured, f"{n}.spilled": self.spilled, f"{n}.remaining": self.remaining,
                f"{n}.flowing": self.flowing}

    def held_mass(self) -> float:
        """What is left of the contents, kg."""
        return self.contents.mass * self.remaining

    def outcome(self, world: World, thresholds: dict[str, float]) -> dict[str, Any]:
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
