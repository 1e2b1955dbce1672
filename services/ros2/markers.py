"""The active skill as ``visualization_msgs/MarkerArray`` for RViz (the thesis' display):
the active state drawn at the hand, in the world frame, with the shapes and colours of
sctd's own view (:mod:`sctd_services.view.skill_scene`, ``docs/view.md``).

Each array starts with a DELETEALL, so RViz shows one state at a time: what each input
axis does there (an arrow per axis: how far full deflection moves the mapping's frame in
1 s, a thin one for what it turns about, numbered), the state's constraints (amber),
its transition regions (purple), its vector fields' fitted shapes (teal), and a label
over the object naming the skill and the state. Namespaces: ``axes``, ``constraint``,
``transition``, ``field``, ``mapping``, ``labels``.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from typing import Any

import numpy as np

from sctd import se3
from sctd.skill import Skill
from sctd.skill.sketch import Arrow, Cone, Cuboid, Dots, Line, Plane, Shape, Sphere, plane_basis
from sctd_services.view.draw import ARROW_SCALE, AXIS_RGB, CONE_RING, OPACITY, ROLE_RGB, TURN_SCALE
from sctd_services.view.skill_scene import state_scene, workspace

LIFETIME = 2.0  # s a marker stays when no new array comes (the node stopped)


class SkillMarkers:
    """Builds the MarkerArray of ``skill`` (``messages``: the message classes,
    :func:`marker_messages`)."""

    def __init__(self, skill: Skill, messages: Any, frame: str = "world"):
        self.skill, self.m, self.frame = skill, messages, frame
        self.ws = workspace(skill)

    def array(self, state: str, T_world_obj: np.ndarray, T_world_ee: np.ndarray,
              stamp: tuple[int, int]) -> Any:
        """The markers of ``state`` with the hand at ``T_world_ee`` and the object at
        ``T_world_obj`` (4x4 each); ``stamp`` is ``(sec, nanosec)``."""
        i = self.skill.state_index(state)
        st = state_scene(self.skill, i, se3.invert_transform(T_world_obj) @ T_world_ee, self.ws)
        self._T, self._stamp = T_world_obj, stamp
        out = self.m.MarkerArray()
        clear = self.m.Marker()
        clear.action = self.m.Marker.DELETEALL
        markers = [clear]
        ids: dict[str, int] = {}

        def add(ns: str, marker: Any) -> None:
            marker.ns, marker.id = ns, ids.get(ns, 0)
            ids[ns] = marker.id + 1
            markers.append(marker)
        for e in st.effects:
            rgb = AXIS_RGB[e.axis % len(AXIS_RGB)]
            tip = e.origin + e.velocity * ARROW_SCALE
            if np.linalg.norm(e.velocity) > 1e-9:
                add("axes", self._arrow(e.origin, tip, rgb, 0.006))
                add("labels", self._text(tip, str(e.axis + 1), rgb))
            if np.linalg.norm(e.turn) > 1e-9:
                end = e.origin + e.turn * TURN_SCALE
                add("axes", self._arrow(e.origin, end, rgb, 0.003))
                add("labels", self._text(end, f"{e.axis + 1} (turn)", rgb))
        for role, shape in st.shapes:
            for marker in self._shape(shape, ROLE_RGB[role]):
                add(role, marker)
        add("labels", self._text(np.array([0.0, 0.0, 0.25]), f"{self.skill.name}: {state}", (20, 20, 20)))
        out.markers = markers
        return out

    # -- one marker ----------------------------------------------------------------------
    def _marker(self, kind: int, rgb, alpha: float = 1.0) -> Any:
        mk = self.m.Marker()
        mk.header.frame_id = self.frame
        mk.header.stamp.sec, mk.header.stamp.nanosec = self._stamp
        mk.type, mk.action = kind, self.m.Marker.ADD
        mk.pose.orientation.w = 1.0
        mk.color.r, mk.color.g, mk.color.b = (c / 255.0 for c in rgb)
        mk.color.a = float(alpha)
        mk.lifetime.sec = int(LIFETIME)
        return mk

    def _world(self, p) -> np.ndarray:
        return self._T[:3, :3] @ np.asarray(p, dtype=float) + self._T[:3, 3]

    def _point(self, p) -> Any:
        pt = self.m.Point()
        pt.x, pt.y, pt.z = (float(v) for v in self._world(p))
        return pt

    def _arrow(self, a, b, rgb, shaft: float) -> Any:
        mk = self._marker(self.m.Marker.ARROW, rgb)
        mk.points = [self._point(a), self._point(b)]
        mk.scale.x, mk.scale.y, mk.scale.z = shaft, 2.0 * shaft, 3.0 * shaft
        return mk

    def _text(self, p, text: str, rgb) -> Any:
        mk = self._marker(self.m.Marker.TEXT_VIEW_FACING, rgb)
        self._place(mk, p, np.eye(3))
        mk.text, mk.scale.z = text, 0.025
        return mk

    def _place(self, mk: Any, p, R_obj: np.ndarray) -> None:
        """``mk.pose``: at ``p`` turned by ``R_obj``, both in the object frame."""
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = self._T[:3, :3] @ R_obj, self._world(p)
        x, y, z, qx, qy, qz, qw = se3.pose_from_transform(T)
        mk.pose.position.x, mk.pose.position.y, mk.pose.position.z = x, y, z
        o = mk.pose.orientation
        o.x, o.y, o.z, o.w = qx, qy, qz, qw

    def _lines(self, pairs: Iterator[tuple[Any, Any]], rgb, width: float = 0.002) -> Any:
        mk = self._marker(self.m.Marker.LINE_LIST, rgb)
        mk.points = [self._point(p) for pair in pairs for p in pair]
        mk.scale.x = width
        return mk

    def _shape(self, s: Shape, rgb) -> list[Any]:
        """One sketch shape as markers (object frame -> world)."""
        if isinstance(s, Arrow):
            return [self._arrow(s.origin, s.origin + s.vector, rgb, 0.004)]
        if isinstance(s, Sphere):
            mk = self._marker(self.m.Marker.SPHERE, rgb, OPACITY)
            self._place(mk, s.centre, np.eye(3))
            mk.scale.x = mk.scale.y = mk.scale.z = 2.0 * float(s.radius)
            return [mk]
        if isinstance(s, Cuboid):
            mk = self._marker(self.m.Marker.CUBE, rgb, OPACITY)
            self._place(mk, (np.asarray(s.lower) + np.asarray(s.upper)) / 2, np.eye(3))
            mk.scale.x, mk.scale.y, mk.scale.z = (float(v) for v in np.asarray(s.upper) - np.asarray(s.lower))
            return [mk]
        if isinstance(s, Plane):
            a, b = plane_basis(s.normal)
            mk = self._marker(self.m.Marker.CUBE, rgb, OPACITY)
            self._place(mk, s.point, np.column_stack([a, b, np.asarray(s.normal, dtype=float)]))
            mk.scale.x = mk.scale.y = float(s.size)
            mk.scale.z = 0.001
            return [mk]
        if isinstance(s, Cone):
            return [self._lines(_cone_lines(s), rgb)]
        if isinstance(s, Line):
            return [self._lines(iter([(s.a, s.b)]), rgb)]
        if isinstance(s, Dots):
            mk = self._marker(self.m.Marker.SPHERE_LIST, rgb, 0.8)
            mk.points = [self._point(p) for p in np.asarray(s.points)[:2000]]
            mk.scale.x = mk.scale.y = mk.scale.z = 0.005
            return [mk]
        return []


def _cone_lines(c: Cone) -> Iterator[tuple[Any, Any]]:
    """A cone's rim and a few generators, as line segments (object frame)."""
    axis = np.asarray(c.axis, dtype=float)
    apex = np.asarray(c.apex, dtype=float)
    a, b = plane_basis(axis)
    centre = apex + axis * c.length
    r = c.length * math.tan(min(c.angle, 1.5))
    rim = [centre + r * (math.cos(t) * a + math.sin(t) * b)
           for t in np.linspace(0.0, 2 * math.pi, CONE_RING // 2 + 1)]
    yield from itertools.pairwise(rim)
    for p in rim[:-1:4]:
        yield apex, p


def marker_messages() -> Any:
    """The message classes the markers are built of (the ``ros2`` extra)."""
    from types import SimpleNamespace

    from geometry_msgs.msg import Point
    from visualization_msgs.msg import Marker, MarkerArray

    return SimpleNamespace(Marker=Marker, MarkerArray=MarkerArray, Point=Point)
