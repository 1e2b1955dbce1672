"""Several tasks in one room: task files composed into one scene (pure).

:func:`compose` makes one :class:`~.model.Task` out of several, as if a room held all
their objects at once: the first task is the one whose outcome, intent and hand start
the composed task keeps (the one a person goes for, in an evaluation); the others bring
their bodies, joints, heads and zones. Each task keeps its objects' layout; a task whose objects would
overlap those already placed is turned as a whole about the vertical through the arm's
base (by 10 deg steps, alternately either way, up to 90 deg), which keeps every object
at its distance from the arm, until its footprint (the ball around its bodies, joint
paths and containers, plus :data:`CLEARANCE`) is clear of the others', and every
footprint and the hand's start are in front of every task's walls (a body's solid
surface is a plane, solid behind it: a task behind another's wall could not be
reached).

The composed task's ``parts`` are the tasks as placed, each judged on the composed
scene's readings (an element's readings carry its own name, so they do not mix).
Names must not clash: two bodies, joints, heads, zones or held objects of one name are
an error, as is a second held object (the hand holds one thing).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from numpy.typing import NDArray

from sctd import se3

from . import kinds
from .kinds import Section
from .model import Body, Scene, Task
from .reader import TaskError

Array = NDArray[np.float64]
CLEARANCE = 0.10
"""m between two tasks' footprints."""
STEP = math.radians(10.0)
"""The turn about the base's vertical tried at a time."""
MAX_TURN = math.radians(90.0)


def footprint(task: Task, T: Array | None = None) -> tuple[Array, float]:
    """The ball (centre, radius) around ``task``'s bodies, the paths of its joints'
    handles, its containers' openings and its heads, in the world (moved by ``T``,
    default none)."""
    sc = task.scene
    T = np.eye(4) if T is None else T
    points = [b.T_world[:3, 3] for b in sc.bodies.values()]
    pad = [max((f.extent() for f in b.facets.values()), default=0.0)  # (a container's radius)
           for b in sc.bodies.values()]
    for entries in sc.sections.values():  # (a joint's handle's path, a person's head's sphere)
        for e in entries.values():
            for centre, r in e.footprint(sc):
                points.append(centre)
                pad.append(r)
    P = (T[:3, :3] @ np.array(points).T).T + T[:3, 3]
    centre = P.mean(axis=0)
    radius = max(float(np.linalg.norm(p - centre)) + r for p, r in zip(P, pad, strict=True))
    return centre, radius


def _turned(task: Task, T: Array) -> Task:
    """``task`` with its bodies (and so its joints' handles) and its start moved by ``T``."""
    sc = task.scene
    bodies = {n: replace(b, T_world=T @ b.T_world) for n, b in sc.bodies.items()}
    start = replace(sc.start, T_world=T @ sc.start.T_world)
    return replace(task, scene=replace(sc, bodies=bodies, start=start))


def walls(task: Task, T: Array | None = None) -> list[tuple[Array, Array]]:
    """The planes of ``task``'s solid surfaces (a wall with a switch in it), moved by
    ``T``: a point on each and its normal out of the solid (the body's x axis)."""
    T = np.eye(4) if T is None else T
    out = []
    for b in task.scene.bodies.values():
        if b.surface is not None:
            W = T @ b.T_world
            out.append((W[:3, 3].copy(), W[:3, 0].copy()))
    return out


def _in_front(centre: Array, radius: float, planes: list[tuple[Array, Array]]) -> bool:
    """Whether the ball is wholly on the open side of every plane."""
    return all(float(n @ (centre - p)) >= radius for p, n in planes)


def _clear(centre: Array, radius: float, placed: list[tuple[Array, float]]) -> bool:
    return all(float(np.linalg.norm(centre - c)) >= radius + r + CLEARANCE for c, r in placed)


def _place(task: Task, placed: list[tuple[Array, float]], placed_walls: list[tuple[Array, Array]],
           start: Array) -> Task:
    """``task`` turned about the base's vertical until clear of ``placed``, in front of
    their walls (``placed_walls``), and with ``placed`` and the hand's ``start`` in
    front of its own (a surface is a plane solid behind it: a task behind another's
    wall could not be reached)."""
    turns = [0.0]
    k = 1
    while k * STEP <= MAX_TURN + 1e-9:
        turns += [k * STEP, -k * STEP]
        k += 1
    for a in turns:
        T = se3.transform_from_rt(se3.matrix_from_rotvec([0.0, 0.0, a]), np.zeros(3))
        centre, radius = footprint(task, T)
        own = walls(task, T)
        if _clear(centre, radius, placed) and _in_front(centre, radius, placed_walls) \
                and all(_in_front(c, r, own) for c, r in [*placed, (start, 0.0)]):
            return _turned(task, T) if a else task
    raise TaskError(task.file or task.name, "", f"no place for task {task.name!r} clear of the others "
                                                 f"within {math.degrees(MAX_TURN):.0f} deg either way")


def compose(tasks: list[Task]) -> Task:
    """One task out of ``tasks`` (see the module doc); one task is itself.

    Raises
    ------
    TaskError
        Clashing names, two held objects, or no place clear of the others.
    """
    if len(tasks) == 1:
        return tasks[0]
    first = tasks[0]
    placed_tasks = [first]
    placed = [footprint(first)]
    placed_walls = walls(first)
    start = first.scene.start.T_world[:3, 3]
    for t in tasks[1:]:
        t = _place(t, placed, placed_walls, start)
        placed_tasks.append(t)
        placed.append(footprint(t))
        placed_walls += walls(t)
    bodies: dict[str, Body] = {}
    sections: dict[str, dict[str, Section]] = {}
    held = None
    for t in placed_tasks:
        sc = t.scene
        names = set(sc.bodies) | _entries(sc.sections) | \
            ({sc.held.name, *sc.held.frames} if sc.held else set())
        taken = set(bodies) | _entries(sections) | \
            ({held.name, *held.frames} if held else set())
        clash = sorted(names & taken)
        if clash:
            raise TaskError(t.file or t.name, "", f"{clash[0]!r} is also a name in an earlier task: "
                                                   "composed tasks need distinct names")
        if sc.held is not None and held is not None:
            raise TaskError(t.file or t.name, "scene.held", f"the hand already holds {held.name!r} "
                                                            "for an earlier task: it holds one thing")
        bodies.update(sc.bodies)
        for key, entries in sc.sections.items():
            sections[key] = {**sections.get(key, {}), **entries}
        held = held or sc.held
    order = list(kinds.sections())
    sections = {k: sections[k] for k in sorted(sections, key=order.index)}
    scene = Scene(first.scene.start, bodies, held, sections)
    name = "+".join(t.name for t in placed_tasks)
    return replace(first, name=name, title=" and ".join(t.title for t in placed_tasks), scene=scene,
                   parts=tuple(placed_tasks))


def _entries(sections: dict[str, dict[str, Section]]) -> set[str]:
    """The names of every section's entries."""
    return {n for entries in sections.values() for n in entries}


def room(tasks: list[Task], goal: str) -> Task:
    """The room of ``tasks`` laid out in that order (:func:`compose`), as the task a
    person going for the one named ``goal`` does (its outcome and intent first), with the
    hand's start of the room's first task whatever the goal.

    Raises
    ------
    TaskError
        As :func:`compose`; ValueError: no task named ``goal``.
    """
    placed = compose(list(tasks))
    parts = list(placed.parts) if len(tasks) > 1 else [placed]
    first = next((p for p in parts if p.name == goal), None)
    if first is None:
        raise ValueError(f"no task {goal!r} among {', '.join(p.name for p in parts)}")
    task = compose([first, *(p for p in parts if p is not first)])
    return replace(task, scene=replace(task.scene, start=placed.scene.start))
