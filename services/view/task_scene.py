"""A task's scene as solid parts: what the view draws of the mug, the bottle, the drawer.

A task file (:mod:`sctd.task`) describes the physics of its scene, not its looks: a
container's radius and depth, a wall's plane, a button's radius, a head's sphere, a
joint's handle and hinge, what the hand holds and its frames. Each becomes a part
(:class:`Part`): a triangle mesh in the frame of what it moves with, so that a view
places it once and only moves that frame:

- the shapes of the elements of registered kinds (:mod:`sctd.task.kinds`): a body's
  facets' (a container's cylinder below its opening, a surface's slab behind its plane,
  a button's disc on its face) and a section's entries' (a joint's moving part, a
  drawer's box behind a prismatic handle or a door's panel from a revolute handle's
  hinge to past the handle, moving with the handle where the joint's position puts it;
  a head's sphere, behind the body it is behind);
- what the hand holds: a cylinder from the hand to its furthest frame (the bottle's
  opening), moving with the hand.

The sizes a file does not give (a drawer front's width, a wall's extent) are drawn at
constants of their kinds: they show where things are, not what collides.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
import trimesh
from numpy.typing import NDArray

from sctd.task import Task
from sctd.task.kinds import Facet, Section, Shape

Array = NDArray[np.float64]

HELD_RADIUS = 0.03  # m: the held object's cylinder
RGB = {"held": (70, 150, 70)}


@dataclass(frozen=True)
class Part:
    """One solid part of the scene.

    ``anchor`` says what it moves with: ``("body", name)`` the body's pose,
    ``("entry", "<section>/<name>")`` where a section's entry draws itself (a joint's
    handle at the joint's position), ``("hand", "")`` the end-effector. ``vertices`` (n,
    3; in the anchor's frame) and ``faces`` (m, 3) make its mesh; ``kind`` picks its
    colour (:data:`RGB`) where it gives none of its own.
    """

    name: str
    label: str
    kind: str
    anchor: tuple[Literal["body", "entry", "hand"], str]
    vertices: Array
    faces: NDArray[np.int64]
    opacity: float = 1.0
    colour: tuple[int, int, int] | None = None  # (a registered kind's shape says its own)

    @property
    def rgb(self) -> tuple[int, int, int]:
        return self.colour if self.colour is not None else RGB[self.kind]


def task_parts(task: Task) -> list[Part]:
    """Every part of ``task``'s scene."""
    parts: list[Part] = []
    sc = task.scene
    for name, b in sc.bodies.items():
        parts += _facet_parts(name, b.facets)
    for key, entries in sc.sections.items():
        for name, e in entries.items():
            parts += _section_parts(key, name, e)
    if sc.held is not None and sc.held.frames:
        far = max(sc.held.frames.values(), key=lambda T: float(np.linalg.norm(T[:3, 3])))[:3, 3]
        length = float(np.linalg.norm(far))
        if length > 1e-3:
            m = trimesh.creation.cylinder(radius=HELD_RADIUS, segment=np.array([np.zeros(3), far]))
            parts.append(_part(f"{sc.held.name}/held", sc.held.name, "held", ("hand", ""), m, 0.6))
    return parts


def part_pose(part: Part, task: Task, T_world: dict[str, Array], T_world_ee: Array | None,
              readings: dict[str, float] | None = None) -> Array | None:
    """Where ``part``'s anchor is: the body's pose in ``T_world`` (name -> (4, 4)), where
    a section's entry draws itself with the bodies there and the scene's ``readings`` (a
    joint's handle at the joint's position, :meth:`~sctd.task.kinds.Section.drawn_at`),
    or the hand ``T_world_ee``; None when that is not known."""
    kind, name = part.anchor
    if kind == "hand":
        return T_world_ee
    if kind == "body":
        return T_world.get(name)
    key, _, entry = name.partition("/")
    return task.scene.sections[key][entry].drawn_at(T_world, dict(readings or {}))


def default_poses(task: Task) -> dict[str, Array]:
    """Every body's default pose (world)."""
    return {name: b.T_world for name, b in task.scene.bodies.items()}


def _part(name: str, label: str, kind: str, anchor, m: trimesh.Trimesh, opacity: float = 1.0) -> Part:
    return Part(name, label, kind, anchor, np.asarray(m.vertices, dtype=float),
                np.asarray(m.faces, dtype=np.int64), opacity)


def _facet_parts(body: str, facets: dict[str, Facet]) -> list[Part]:
    """The shapes a body's facets of registered kinds draw (:meth:`Facet.shapes`), moving
    with the body (an item carried moves with it)."""
    return [_shape_part(f"{body}/{shape.name or key + str(k)}",
                        shape.label.format(body=body) if shape.label else f"{body} ({key})", "facet",
                        ("body", body), shape)
            for key, facet in facets.items() for k, shape in enumerate(facet.shapes())]


def _section_parts(key: str, name: str, entry: Section) -> list[Part]:
    """The shapes a section's entry draws (:meth:`Section.shapes`: a joint's drawer box or
    door panel, moving with its handle; a head's sphere), where it says."""
    return [_shape_part(f"{name}/{shape.name or entry.noun + str(k or '')}", entry.label(), entry.noun,
                        ("entry", f"{key}/{name}"), shape)
            for k, shape in enumerate(entry.shapes())]


def _shape_part(name: str, label: str, kind: str, anchor: tuple[Literal["body", "entry", "hand"], str],
                shape: Shape) -> Part:
    """A kind's :class:`Shape` as a part moving with its ``anchor``."""
    if shape.kind == "box":
        m = trimesh.creation.box(extents=shape.size)
    elif shape.kind == "sphere":
        m = trimesh.creation.icosphere(subdivisions=2, radius=shape.size[0])
    else:
        m = trimesh.creation.cylinder(radius=shape.size[0], height=shape.size[2])
    m.apply_transform(shape.T_body_shape)
    rgb = tuple(round(255 * c) for c in shape.colour)
    return Part(name, label, kind, anchor, np.asarray(m.vertices, dtype=float),
                np.asarray(m.faces, dtype=np.int64), shape.opacity, (rgb[0], rgb[1], rgb[2]))
