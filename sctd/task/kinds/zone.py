"""A goal pose of a frame of the hand, timed while the frame stays there: the ``zones``
section of a scene.

A **zone** (``frame``, ``around``, ``position``, ``within``, optionally ``axis`` with
``tilt``): the frame ``frame`` (``hand`` or a frame of what the hand holds) is inside
while its origin is within ``within`` (half-widths, m, along the axes of the body
``around``) of ``position`` (in that body's frame) and, with ``tilt``, its z axis within
``tilt`` rad of ``axis`` (a unit vector in the body's frame; its spin about it is free).
It reports whether the frame is ``inside``, how long it has been inside without a break
(``dwell``, s) and the longest so far (``max_dwell``): "the cup held at the lips for
2 s" is ``{reading: <zone>.dwell, at_least: 2}``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..model import Scene
from .base import Array, FacetPhysics, Section, World

HAND = "hand"  # (the reader's name for the hand: the reader imports the registry)


@dataclass(frozen=True)
class Zone(Section):
    """A goal pose of a frame of the hand, within tolerances (see the module doc).

    Attributes
    ----------
    name, frame, around : str
    position, within, axis : ndarray (3,)
    tilt : float or None
        rad; None: any orientation.
    """

    key = "zones"
    noun = "zone"
    order = 20
    quantities = ("inside", "dwell", "max_dwell")
    flags = ("inside",)

    name: str
    frame: str
    around: str
    position: Array
    within: Array
    axis: Array
    tilt: float | None = None

    @classmethod
    def read(cls, r: Any, name: str, v: Any, path: str, scene: Scene) -> Zone:
        d = r.fields(v, path, {"frame", "around", "position", "within"}, {"axis", "tilt"})
        frame = r.string(d["frame"], f"{path}.frame")
        frames = [HAND, *(scene.held.frames if scene.held is not None else ())]
        if frame not in frames:
            raise r.fail(f"{path}.frame", f"expected {HAND!r} or a frame of what the hand holds "
                                          f"({', '.join(frames)}), got {frame!r}")
        around = r.string(d["around"], f"{path}.around")
        if around not in scene.bodies:
            raise r.fail(f"{path}.around", f"unknown body {around!r} (bodies: {', '.join(scene.bodies)})")
        w = d["within"]
        within = (np.full(3, r.positive(w, f"{path}.within")) if not isinstance(w, list)
                  else r.vector(w, f"{path}.within", 3))
        if not np.all(within > 0.0):
            raise r.fail(f"{path}.within", "must be > 0 on every axis")
        if ("axis" in d) != ("tilt" in d):
            raise r.fail(path, "axis and tilt go together: the frame's z within tilt of axis")
        axis = r.vector(d["axis"], f"{path}.axis", 3, unit=True) if "axis" in d else np.eye(3)[2]
        tilt = r.tilt(d["tilt"], f"{path}.tilt") if "tilt" in d else None
        return cls(name, frame, around, r.vector(d["position"], f"{path}.position", 3), within, axis, tilt)

    def to_yaml(self) -> dict[str, Any]:
        from ..writer import _angle, _floats, _per_axis  # (the writer imports the reader, the registry)

        out: dict[str, Any] = {"frame": self.frame, "around": self.around, "position": _floats(self.position),
                               "within": _per_axis(self.within)}
        if self.tilt is not None:  # (without a tilt the reader's axis is z, and unused)
            out["axis"] = _floats(self.axis)
            out["tilt"] = _angle(self.tilt)
        return out

    def inside(self, T_world_around: Array, T_world_frame: Array) -> bool:
        """Whether the frame at ``T_world_frame`` is inside, the body at ``T_world_around``."""
        R, o = T_world_around[:3, :3], T_world_around[:3, 3]
        d = R.T @ (T_world_frame[:3, 3] - o) - self.position
        if bool(np.any(np.abs(d) > self.within)):
            return False
        if self.tilt is None:
            return True
        c = float((R.T @ T_world_frame[:3, 2]) @ self.axis)
        return math.acos(max(-1.0, min(1.0, c))) <= self.tilt

    def physics(self, scene: Scene) -> FacetPhysics:
        frames = scene.held.frames if scene.held is not None else {}
        return ZoneWatch(self, frames.get(self.frame, np.eye(4)))


class ZoneWatch(FacetPhysics):
    """Times a :class:`Zone`: ``dwell`` grows by each step's ``dt`` while the frame is
    inside and falls to 0 when it leaves; ``max_dwell`` is the longest so far. No force."""

    def __init__(self, zone: Zone, T_ee_frame: Array):
        self.zone = zone
        self.name = zone.name
        self.T_ee_frame = T_ee_frame
        self.inside = False
        self.dwell = self.max_dwell = 0.0

    def reset(self, world: World) -> None:
        self.inside = False
        self.dwell = 0.0
        self.max_dwell = 0.0

    def step(self, world: World, dt: float) -> Array:
        self.inside = self.zone.inside(world.poses[self.zone.around], world.T_world_ee @ self.T_ee_frame)
        self.dwell = self.dwell + dt if self.inside else 0.0
        self.max_dwell = max(self.max_dwell, self.dwell)
        return np.zeros(6)

    def readings(self, world: World) -> dict[str, float | bool]:
        n = self.name
        return {f"{n}.inside": self.inside, f"{n}.dwell": self.dwell, f"{n}.max_dwell": self.max_dwell}
