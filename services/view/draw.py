"""A skill's scene (:mod:`.skill_scene`) on a Viser scene, with a state picker.

Everything of the skill hangs under one node, ``/skill``, placed at the task object's
pose in the world (the identity before it runs, where the world is the object's frame):

- ``/skill/object``: the object's frame and name;
- ``/skill/demos/<n>``: each demonstration, its segments in the colour of the state the
  skill's FSM is in there (:data:`STATE_RGB`, the state's place in the skill);
- ``/skill/states/<state>/...``: the hand where the state is shown (``hand``), what
  each input axis does there (``axis<k>``: an arrow of the frame's motion in
  :data:`AXIS_RGB`, a dashed arrow along the axis it turns about), the constraints'
  shapes (amber), the transitions' (purple), the fields' shapes and arrows.

The GUI has a **state** picker (every state, or one), a check box for the
demonstrations, and the picked state's description (what each axis does, what holds the
hand, where it goes next). :class:`SkillView` keeps the node names it drew, so a test
can find where each element is.
"""

from __future__ import annotations

import itertools
import math
from typing import Any

import numpy as np

from sctd import se3
from sctd.skill.sketch import Arrow, Cone, Cuboid, Dots, Line, Plane, Shape, Sphere, plane_basis
from sctd.task import Task

from .skill_scene import AxisEffect, FieldArrows, SkillScene, StateScene
from .task_scene import Part, default_poses, part_pose, task_parts

ALL = "every state"
ACTIVE = "active state"  # the live view's picker: follow the state the daemon is in
STATE_RGB = ((31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
             (140, 86, 75), (227, 119, 194), (127, 127, 127))
AXIS_RGB = ((230, 30, 30), (20, 170, 20), (30, 70, 235), (200, 160, 0), (160, 0, 200), (0, 170, 170))
ROLE_RGB = {"constraint": (245, 170, 0), "transition": (150, 40, 210), "field": (0, 150, 150),
            "mapping": (90, 90, 90)}
FIELD_RGB = ((0, 150, 150), (200, 80, 0), (120, 120, 0), (0, 100, 200), (200, 0, 120))
ARROW_SCALE = 1.0  # s: an axis's arrow is how far full deflection moves the frame in this time
TURN_SCALE = 0.15  # m per rad/s: how long an axis's turn is drawn
OPACITY = 0.3  # of regions (spheres, boxes, cones, planes)
CONE_RING = 32  # vertices of a cone's rim


def state_rgb(i: int) -> tuple[int, int, int]:
    return STATE_RGB[i % len(STATE_RGB)]


class SkillView:
    """Draws a :class:`~.skill_scene.SkillScene` on ``server`` (a ``viser.ViserServer``).

    Attributes
    ----------
    nodes : dict
        Node name -> what was drawn there: ``("arrow", origin, tip)``, ``("sphere",
        centre, radius)`` ... in the object frame, for every node (tests project them).
    handles : dict
        Node name -> the Viser handle.
    picker : viser GUI dropdown
        The state picker (:data:`ALL` or a state's name).
    """

    def __init__(self, server: Any, scene: SkillScene, T_world_obj: np.ndarray | None = None,
                 task: Task | None = None, live: bool = False):
        self.server = server
        self.scene = scene
        self.live = live
        self.nodes: dict[str, tuple] = {}
        self.handles: dict[str, Any] = {}
        self._gui_handles: list[Any] = []
        T = np.eye(4) if T_world_obj is None else T_world_obj
        pose = se3.pose_from_transform(T)
        self.root = server.scene.add_frame("/skill", show_axes=False, position=pose[:3],
                                           wxyz=(pose[6], pose[3], pose[4], pose[5]))
        lights(server)
        self._draw_object()
        parts = task_parts(task) if task is not None else []
        if task is not None:
            self._draw_task(task, [p for p in parts if p.anchor[0] != "hand"])
        for k, d in enumerate(scene.demos):
            self._draw_demo(k, d)
        self._held = [p for p in parts if p.anchor[0] == "hand"]
        self.active = scene.skill.start
        for i, st in enumerate(scene.states):
            self._draw_state(i, st, self._held)
        self._gui()
        self.look_at, self.camera = self._framing(T)
        if not live:
            server.initial_camera.look_at = tuple(self.look_at)
            server.initial_camera.position = tuple(self.camera)

    def place(self, T_world_obj: np.ndarray) -> None:
        """Put the skill where its object is now (world)."""
        pose = se3.pose_from_transform(T_world_obj)
        self.root.position = pose[:3]
        self.root.wxyz = (pose[6], pose[3], pose[4], pose[5])

    def follow(self, state: str) -> None:
        """The daemon is in ``state``: shown when the picker follows the active state."""
        self.active = state
        if self.picker.value == ACTIVE:
            self.show(state)

    def redraw_state(self, st: StateScene) -> None:
        """Draw a state again (its hand at another pose: the measured one, live)."""
        i = next(k for k, s in enumerate(self.scene.states) if s.name == st.name)
        base = f"/skill/states/{st.name}"
        visible = self.handles[base].visible
        self.handles[base].remove()
        for name in [n for n in self.handles if n == base or n.startswith(base + "/")]:
            del self.handles[name]
            self.nodes.pop(name, None)
        self.scene.states[i] = st
        self._draw_state(i, st, self._held)
        self.handles[base].visible = visible
        if self.picker.value in (ACTIVE, st.name, ALL):
            self._text.content = self._describe(self.picker.value if self.picker.value != ACTIVE
                                                else self.active)

    def close(self) -> None:
        """Remove everything it drew and its controls."""
        self.root.remove()
        for h in self._gui_handles:
            h.remove()

    def _framing(self, T_world_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Where the camera looks (the middle of what was drawn, world) and stands (in
        front of it, to the object's -y and above, far enough to see it all)."""
        points = [np.atleast_2d(v) for kind, *vals in self.nodes.values() for v in vals[:2]
                  if kind in ("frame", "arrow", "path", "box", "line") and np.shape(v)[-1:] == (3,)]
        pts = np.vstack(points) if points else np.zeros((1, 3))
        lo, hi = np.percentile(pts, 2, axis=0), np.percentile(pts, 98, axis=0)
        centre = (lo + hi) / 2
        size = max(float(np.linalg.norm(hi - lo)), 0.2)
        eye = centre + size * 1.4 * np.array([0.45, -0.8, 0.45])
        R, t = T_world_obj[:3, :3], T_world_obj[:3, 3]
        return R @ centre + t, R @ eye + t

    # -- what is shown -----------------------------------------------------------------
    def show(self, state: str) -> None:
        """Show one state's elements (or every state's: :data:`ALL`; the active one:
        :data:`ACTIVE`)."""
        state = self.active if state == ACTIVE else state
        for st in self.scene.states:
            self.handles[f"/skill/states/{st.name}"].visible = state in (ALL, st.name)
        self._text.content = self._describe(state)

    def _gui(self) -> None:
        gui = self.server.gui
        names = [st.name for st in self.scene.states]
        skill = self.scene.skill
        first = ACTIVE if self.live else skill.start
        self._gui_handles = [
            gui.add_markdown(f"**{skill.name}** on `{skill.object}`: {skill.description}"),
            picker := gui.add_dropdown("state", [*([ACTIVE] if self.live else []), *names, ALL],
                                       initial_value=first),
            demos := gui.add_checkbox("demonstrations", True, visible=bool(self.scene.demos)),
            text := gui.add_markdown("")]
        self.picker, self.demos_box, self._text = picker, demos, text
        self.show(first)

        @self.picker.on_update
        def _(_event: Any) -> None:
            self.show(self.picker.value)

        @self.demos_box.on_update
        def _(_event: Any) -> None:
            self.handles["/skill/demos"].visible = self.demos_box.value

    def _describe(self, state: str) -> str:
        lines = []
        for i, st in enumerate(self.scene.states):
            if state not in (ALL, st.name):
                continue
            r, g, b = state_rgb(i)
            start = " (start)" if st.name == self.scene.skill.start else ""
            lines.append(f"<b style='color:rgb({r},{g},{b})'>{st.name}</b>{start}\n")
            lines += [f"- {t}" for t in st.text]
            lines.append("")
        return "\n".join(lines)

    # -- drawing -----------------------------------------------------------------------
    def _draw_object(self) -> None:
        sc = self.server.scene
        name = "/skill/object"
        self.handles[name] = sc.add_frame(name, axes_length=0.1, axes_radius=0.003)
        sc.add_label(f"{name}/label", self.scene.skill.object, position=(0.0, 0.0, -0.02))
        self.nodes[name] = ("frame", np.zeros(3))

    def _draw_task(self, task: Task, parts: list[Part]) -> None:
        """The task's scene at its default poses, seen from the task object."""
        T_world = default_poses(task)
        T_obj_world = se3.invert_transform(T_world[task.object]) if task.object in T_world else np.eye(4)
        for part in parts:
            T = part_pose(part, task, T_world, None)
            if T is not None:
                self._draw_part(f"/skill/task/{part.name}", part, T_obj_world @ T)

    def _draw_part(self, name: str, part: Part, T_parent_part: np.ndarray) -> None:
        pose = se3.pose_from_transform(T_parent_part)
        self.handles[name] = self.server.scene.add_mesh_simple(
            name, part.vertices.astype(np.float32), part.faces.astype(np.uint32), color=part.rgb,
            opacity=part.opacity if part.opacity < 1.0 else None, position=pose[:3],
            wxyz=(pose[6], pose[3], pose[4], pose[5]), cast_shadow=False, receive_shadow=False)
        self.nodes[name] = ("mesh", (T_parent_part[:3, :3] @ part.vertices.T).T + T_parent_part[:3, 3])

    def _draw_demo(self, k: int, d) -> None:
        """One demonstration: a polyline per stretch in one state, in that state's colour
        (one colour a node: three.js lightens per-vertex colours)."""
        if len(d.points) < 2:
            return
        if "/skill/demos" not in self.handles:
            self.handles["/skill/demos"] = self.server.scene.add_frame("/skill/demos", show_axes=False)
        name = f"/skill/demos/{k}"
        self.handles[name] = self.server.scene.add_frame(name, show_axes=False)
        cuts = [0, *(np.flatnonzero(np.diff(d.states)) + 1).tolist(), len(d.points)]
        for j, (a, b) in enumerate(itertools.pairwise(cuts)):
            stretch = d.points[a:min(b + 1, len(d.points))]  # on to the next stretch's first point
            if len(stretch) < 2:
                continue
            segments = np.stack([stretch[:-1], stretch[1:]], axis=1)
            self.server.scene.add_line_segments(f"{name}/{j}", segments, state_rgb(int(d.states[a])),
                                                thickness=3.0, thickness_units="screen")
        self.nodes[name] = ("path", d.points, d.states)
        if len(d.spikes):  # the outliers the learner drops: small grey dots, not the path
            self.handles[f"{name}/spikes"] = self.server.scene.add_point_cloud(
                f"{name}/spikes", d.spikes.astype(np.float32), colors=(150, 150, 150), point_size=0.004,
                point_shape="circle")
            self.nodes[f"{name}/spikes"] = ("dots", d.spikes)

    def _draw_state(self, i: int, st: StateScene, held: list[Part]) -> None:
        sc = self.server.scene
        base = f"/skill/states/{st.name}"
        self.handles[base] = sc.add_frame(base, show_axes=False)
        pose = se3.pose_from_transform(st.T_obj_ee)
        hand = f"{base}/hand"
        self.handles[hand] = sc.add_frame(hand, axes_length=0.04, axes_radius=0.002, origin_radius=0.006,
                                          origin_color=state_rgb(i), position=pose[:3],
                                          wxyz=(pose[6], pose[3], pose[4], pose[5]))
        self.nodes[hand] = ("frame", pose[:3])
        for part in held:  # what the hand holds, with it
            self._draw_part(f"{base}/held/{part.name}", part, st.T_obj_ee)
        for e in st.effects:
            self._draw_effect(base, e)
        for k, (role, shape) in enumerate(st.shapes):
            self._draw_shape(f"{base}/{role}{k}", shape, ROLE_RGB[role])
        for fa in st.arrows:
            self._draw_field(f"{base}/field_arrows{fa.index}", fa)

    def _draw_effect(self, base: str, e: AxisEffect) -> None:
        rgb = AXIS_RGB[e.axis % len(AXIS_RGB)]
        v = e.velocity * ARROW_SCALE
        if np.linalg.norm(v) > 1e-4:
            self._arrow(f"{base}/axis{e.axis + 1}", e.origin, e.origin + v, rgb, 0.004)
            self.server.scene.add_label(f"{base}/axis{e.axis + 1}/label", str(e.axis + 1),
                                        position=tuple(e.origin + 1.1 * v))
        w = e.turn * TURN_SCALE
        if np.linalg.norm(w) > 1e-3:
            self._arrow(f"{base}/turn{e.axis + 1}", e.origin, e.origin + w, rgb, 0.002)
            self.server.scene.add_label(f"{base}/turn{e.axis + 1}/label", f"{e.axis + 1} (turn)",
                                        position=tuple(e.origin + 1.1 * w))

    def _arrow(self, name: str, a: np.ndarray, b: np.ndarray, rgb, shaft: float) -> None:
        length = float(np.linalg.norm(b - a))
        self.handles[name] = self.server.scene.add_arrows(
            name, np.array([[a, b]]), np.array([rgb], dtype=np.uint8), shaft_radius=shaft,
            head_radius=2.5 * shaft, head_length=min(0.3 * length, 0.02))
        self.nodes[name] = ("arrow", np.asarray(a), np.asarray(b))

    def _draw_field(self, name: str, fa: FieldArrows) -> None:
        if not len(fa.points):
            return
        rgb = FIELD_RGB[fa.index % len(FIELD_RGB)]
        ends = np.stack([fa.points, fa.points + 0.015 * fa.vectors], axis=1)
        self.handles[name] = self.server.scene.add_arrows(
            name, ends, np.full((len(ends), 3), rgb, dtype=np.uint8), shaft_radius=0.0008,
            head_radius=0.002, head_length=0.004)
        self.nodes[name] = ("arrows", fa.points, fa.vectors)

    def _draw_shape(self, name: str, s: Shape, rgb) -> None:
        sc = self.server.scene
        if isinstance(s, Arrow):
            self._arrow(name, s.origin, s.origin + s.vector, rgb, 0.003)
        elif isinstance(s, Sphere):
            self.handles[name] = sc.add_icosphere(name, radius=max(s.radius, 1e-3), color=rgb,
                                                  opacity=OPACITY, position=tuple(s.centre),
                                                  cast_shadow=False, receive_shadow=False)
            self.nodes[name] = ("sphere", s.centre, s.radius)
        elif isinstance(s, Cuboid):
            size = tuple(np.maximum(s.upper - s.lower, 1e-3))
            self.handles[name] = sc.add_box(name, color=rgb, dimensions=size, opacity=OPACITY,
                                            position=tuple((s.upper + s.lower) / 2), cast_shadow=False,
                                            receive_shadow=False)
            self.nodes[name] = ("box", s.lower, s.upper)
        elif isinstance(s, Cone | Plane):
            vertices, faces = cone_mesh(s) if isinstance(s, Cone) else plane_mesh(s)
            self.handles[name] = sc.add_mesh_simple(name, vertices, faces, color=rgb, opacity=OPACITY,
                                                    side="double", cast_shadow=False, receive_shadow=False)
            self.nodes[name] = ("mesh", vertices)
        elif isinstance(s, Line):
            self.handles[name] = sc.add_line_segments(name, np.array([[s.a, s.b]]), rgb, thickness=3.0,
                                                      thickness_units="screen")
            self.nodes[name] = ("line", s.a, s.b)
        elif isinstance(s, Dots):
            self.handles[name] = sc.add_point_cloud(name, s.points, rgb, point_size=0.008 if len(s.points) < 5
                                                    else 0.003, point_shape="circle")
            self.nodes[name] = ("dots", s.points)


def lights(server: Any) -> None:
    """Plain lighting: an even ambient light and one from above, no environment map
    (its image costs a software renderer seconds before the first frame, and a
    wheelchair's computer may have no GPU)."""
    server.scene.configure_environment_map(hdri=None)
    server.scene.configure_default_lights(enabled=False)
    server.scene.add_light_ambient("/lights/ambient", intensity=1.2)
    server.scene.add_light_directional("/lights/above", intensity=1.0, wxyz=(1.0, 0.0, 0.0, 0.0),
                                       position=(0.0, 0.0, 2.0))


def cone_mesh(c: Cone) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n, 3) and faces (m, 3) of a cone's surface: its rim at slant length
    ``c.length`` from the apex (so that a cone wider than a half-turn still closes)."""
    a, b = plane_basis(c.axis)
    th = np.linspace(0.0, 2.0 * math.pi, CONE_RING, endpoint=False)
    ring = (c.apex + c.length * math.cos(c.angle) * c.axis
            + c.length * math.sin(c.angle) * (np.cos(th)[:, None] * a + np.sin(th)[:, None] * b))
    vertices = np.vstack([c.apex[None, :], ring])
    faces = np.array([[0, 1 + k, 1 + (k + 1) % CONE_RING] for k in range(CONE_RING)])
    return vertices.astype(np.float32), faces.astype(np.uint32)


def plane_mesh(p: Plane) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (4, 3) and faces (2, 3) of a plane's square."""
    a, b = plane_basis(p.normal)
    h = p.size / 2
    vertices = np.array([p.point + h * (sa * a + sb * b) for sa, sb in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    return vertices.astype(np.float32), np.array([[0, 1, 2], [0, 2, 3]], dtype=np.uint32)
