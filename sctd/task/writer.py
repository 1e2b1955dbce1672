"""A :class:`~.model.Task` to its task file: the YAML document and its text (pure).

The inverse of :mod:`.reader`: ``task_from_document(task_to_yaml(t), t.file)`` is ``t``
again, field by field (``tests/test_task_writer.py``), and writing what was read back
gives the same text. Numbers are written as Python floats, which YAML keeps to the last
bit; an angle is written in degrees (``"180 deg"``) where a short number of degrees reads
back as exactly the same radians, else in radians. A pose is written as ``position`` and
``rpy``: angles whose rotation (:func:`~.reader.rpy_matrix`) is the pose's own to the
bit where the reader made it of angles in (-pi, pi], pitch in (-pi/2, pi/2)
(:func:`rpy_from_matrix`), else within 1e-12; the position is exact.

What equals the reader's default is left out only where the reader fills that same
value back (a container's ``rim_margin``, a step's
``orientation: free``); what it fills in from the rest of the scene (a surface's
``touch``) is always written. The scene's sections of registered kinds (``joints``,
``heads``, ``zones``) are written by their entries' ``to_yaml()`` (which may use :func:`_angle`
and :func:`_per_axis`). A composed task (:func:`~.compose.compose`) has no file: writing
one is a ValueError.

Elements of kinds registered in ``sctd.task.kinds`` write themselves with their
``to_yaml()``: every intent step (given the scene, which says how a predicate's bounds
are written; a kind may use :func:`_predicate`, :func:`_angle` and :func:`_floats`), and
a scene's or a body's field this module does not know (:func:`_extra_sections`,
:func:`_extra_facets`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np
import yaml

from .kinds import StepKind
from .model import (
    VERSION,
    AllOf,
    AnyOf,
    Body,
    Compare,
    Held,
    Near,
    Not,
    Outcome,
    Predicate,
    Scene,
    Step,
    Task,
    Teach,
    TeachStep,
    Vary,
)
from .reader import TEACH_SPEEDS, _angular, rpy_matrix

Doc = dict[str, Any]

ULPS = 3
"""How many ulps either way of the closed-form angles :func:`rpy_from_matrix` tries."""


def task_to_yaml(task: Task) -> Doc:
    """The task file's document (dicts, lists, str, float, int and bool only) that
    :func:`~.reader.task_from_document` reads back as ``task``.

    Raises
    ------
    ValueError
        ``task`` is composed of parts (it has no file of its own), or holds an element
        this module cannot write.
    """
    if task.parts:
        parts = ", ".join(p.name for p in task.parts)
        raise ValueError(f"task {task.name!r} is composed of parts ({parts}): a composed task has no "
                         "file to write; write each part's")
    doc: Doc = {"sctd_task": VERSION, "name": task.name}
    if task.title and task.title != task.name:  # (the name: the reader's title when there is none)
        doc["title"] = task.title
    for key in ("description", "source"):
        if getattr(task, key):
            doc[key] = getattr(task, key)
    doc["object"] = task.object
    doc["scene"] = _scene(task.scene)
    doc["outcome"] = _outcome(task.outcome, task.scene)
    doc["intent"] = [_step(s, task.scene) for s in task.intent]
    if task.teach != Teach():
        doc["teach"] = _teach(task.teach, task.intent, task.scene)
    return doc


def dump_task(task: Task) -> str:
    """The task file's text: :func:`task_to_yaml` in the file's order (block style, lists
    of scalars in flow style, folded near 100 characters)."""
    return yaml.safe_dump(task_to_yaml(task), sort_keys=False, default_flow_style=None, width=100,
                          allow_unicode=True)


# -- numbers, angles and poses ------------------------------------------------------------
def _floats(v: Iterable[Any]) -> list[float]:
    return [float(x) for x in v]


def _angle(a: float) -> float | str:
    """``a`` (rad) as an angle field: ``"<n> deg"`` where ``n``, at most 6 significant
    digits, reads back as exactly ``a``; else the radians."""
    if a != 0.0:
        text = f"{round(math.degrees(a), 6):g}"
        if math.radians(float(text)) == a:
            return f"{text} deg"
    return float(a) + 0.0  # (-0.0 as 0.0: the same angle)


def _angles(v: Iterable[float]) -> list[float | str]:
    return [_angle(float(a)) for a in v]


def _per_axis(v: np.ndarray) -> float | list[float]:
    """A vector the reader also takes as one number for every axis (``vary.position``,
    a zone's ``within``): that number when all three are equal."""
    return float(v[0]) if bool(np.all(v == v[0])) else _floats(v)


def _near_ulps(a: float) -> list[float]:
    """``a``, the whole number of millidegrees nearest it when within 1e-12, and the
    floats up to :data:`ULPS` ulps either way: where :func:`rpy_from_matrix` looks."""
    out = [math.radians(round(math.degrees(a), 3))]
    out = [x for x in out if abs(x - a) < 1e-12] + [a]
    up = down = a
    for _ in range(ULPS):
        up, down = math.nextafter(up, math.inf), math.nextafter(down, -math.inf)
        out += [up, down]
    return list(dict.fromkeys(out))


def rpy_from_matrix(R: np.ndarray) -> list[float]:
    """Roll, pitch and yaw (rad, about the fixed x, y, z axes) whose
    :func:`~.reader.rpy_matrix` is ``R`` (3, 3).

    The closed form (pitch in [-pi/2, pi/2]; in gimbal lock roll 0), then the nearest
    angles around it that give ``R`` to the bit (:func:`_near_ulps`, a whole number of
    millidegrees first), as the tests find for every ``R`` the reader makes of angles in
    (-pi, pi], pitch in (-pi/2, pi/2). For another ``R`` (angles out of those ranges,
    gimbal lock), angles whose matrix is within 1e-12 of ``R`` and gives them back: what
    is read back is written the same."""
    closed = _rpy_closed_form(R)
    exact = _rpy_exact(R, closed)
    if exact is None:
        R_near = rpy_matrix(np.array(closed))
        exact = _rpy_exact(R_near, _rpy_closed_form(R_near))
    return closed if exact is None else exact


def _rpy_closed_form(R: np.ndarray) -> list[float]:
    cos_pitch = math.hypot(R[0, 0], R[1, 0])
    pitch = math.atan2(-R[2, 0], cos_pitch)
    if cos_pitch > 1e-12:
        return [math.atan2(R[2, 1], R[2, 2]), pitch, math.atan2(R[1, 0], R[0, 0])]
    return [0.0, pitch, math.atan2(-R[0, 1], R[1, 1])]  # pitch +-pi/2: only yaw -+ roll counts


def _rpy_exact(R: np.ndarray, near: list[float]) -> list[float] | None:
    """The first angles around ``near`` whose matrix is ``R`` to the bit, or None."""
    for rpy in itertools.product(*(_near_ulps(a) for a in near)):
        if np.array_equal(rpy_matrix(np.array(rpy)), R):
            return list(rpy)
    return None


def _pose(T: np.ndarray) -> Doc:
    """``position`` and, unless it is the identity (the reader's default), ``rpy``."""
    out: Doc = {"position": _floats(T[:3, 3])}
    if not np.array_equal(T[:3, :3], np.eye(3)):
        out["rpy"] = _angles(rpy_from_matrix(T[:3, :3]))
    return out


def _vary(v: Vary) -> Doc:
    out: Doc = {}
    if np.any(v.position != 0.0):
        out["position"] = _per_axis(v.position)
    if v.yaw != 0.0:
        out["yaw"] = _angle(v.yaw)
    return out


def _put(d: Doc, key: str, value: float, default: float, write: Callable[[float], Any] = float) -> None:
    """``d[key]``, unless ``value`` is the ``default`` the reader fills back."""
    if value != default:
        d[key] = write(value)


# -- the scene ----------------------------------------------------------------------------
def _scene(sc: Scene) -> Doc:
    start = _pose(sc.start.T_world)
    if _vary(sc.start.vary):
        start["vary"] = _vary(sc.start.vary)
    out: Doc = {"start": start, "bodies": {n: _body(b) for n, b in sc.bodies.items()}}
    if sc.held is not None:
        out["held"] = _held(sc.held)
    for key, entries in sc.sections.items():  # (the sections of registered kinds)
        out[key] = {n: e.to_yaml() for n, e in entries.items()}
    out.update(_extra_sections(sc))
    return out


def _body(b: Body) -> Doc:
    out = _pose(b.T_world)
    if _vary(b.vary):
        out["vary"] = _vary(b.vary)
    out.update(_extra_facets(b))
    return out


def _held(h: Held) -> Doc:
    out: Doc = {"name": h.name, "mass": float(h.mass), "com": _floats(h.com)}
    if h.frames:
        out["frames"] = {n: _pose(T) for n, T in h.frames.items()}
    out.update({k: f.to_yaml() for k, f in h.facets.items()})  # (its contents)
    return out


def _elements(value: Any, where: str) -> list[tuple[str | None, Any]]:
    """(key, element) of a field's value that is an element with ``to_yaml()`` (key None),
    or a mapping of them (by its keys); nothing for an empty value; ValueError else."""
    if value is None or (isinstance(value, dict | tuple | list) and not value):
        return []
    if hasattr(value, "to_yaml"):
        return [(None, value)]
    if isinstance(value, dict) and all(hasattr(e, "to_yaml") for e in value.values()):
        return list(value.items())
    raise ValueError(f"{where}: the task writer does not know this field, and it holds no element "
                     "with to_yaml()")


def _extra_sections(scene: Scene) -> Doc:
    """The scene's sections of kinds registered in ``sctd.task.kinds``: each field of
    :class:`~.model.Scene` this module does not write itself, as ``{field: {name:
    element.to_yaml()}}`` (or ``{field: element.to_yaml()}`` for one element). Scene has
    no such field today: nothing."""
    known = {"start", "bodies", "held", "sections"}
    out: Doc = {}
    for f in dataclasses.fields(scene):
        if f.name not in known:
            items = _elements(getattr(scene, f.name), f"scene.{f.name}")
            if items:
                out[f.name] = {k: e.to_yaml() for k, e in items} if items[0][0] else items[0][1].to_yaml()
    return out


def _extra_facets(body: Body) -> Doc:
    """A body's facets of kinds registered in ``sctd.task.kinds``: each field of
    :class:`~.model.Body` this module does not write itself holds elements with
    ``to_yaml()``, written under their kind's ``key`` (or the mapping's keys) in the
    body's mapping: its ``facets`` (a container, a surface, an item)."""
    known = {"name", "T_world", "vary"}
    out: Doc = {}
    for f in dataclasses.fields(body):
        if f.name not in known:
            for k, e in _elements(getattr(body, f.name), f"body {body.name!r}: {f.name}"):
                out[k or type(e).key] = e.to_yaml()
    return out


# -- the outcome --------------------------------------------------------------------------
def _predicate(p: Predicate, sc: Scene) -> Any:
    if isinstance(p, bool):
        return p
    if isinstance(p, Compare):
        out: Doc = {"reading": str(p.reading)}
        number: Callable[[float], Any] = _angle if _angular(p.reading, sc) else float
        for key in ("at_least", "at_most", "above", "below"):
            if getattr(p, key) is not None:
                out[key] = number(getattr(p, key))
        if p.is_ is not None:
            out["is"] = p.is_
        return out
    if isinstance(p, Near):
        return {"near": {"frame": p.frame, "to": p.to, "within": float(p.within)}}
    if isinstance(p, AllOf | AnyOf):
        return {"all" if isinstance(p, AllOf) else "any": [_predicate(t, sc) for t in p.terms]}
    if isinstance(p, Not):
        return {"not": _predicate(p.term, sc)}
    raise ValueError(f"not a predicate the task writer knows: {p!r}")


def _outcome(o: Outcome, sc: Scene) -> Doc:
    out: Doc = {"done": _predicate(o.done, sc)}
    if o.success is not True:
        out["success"] = _predicate(o.success, sc)
    if o.done_reason != "done":
        out["done_reason"] = o.done_reason
    if o.fail:
        out["fail"] = [{"when": _predicate(f.when, sc), "reason": f.reason} for f in o.fail]
    out |= {"progress": str(o.progress), "clock": _predicate(o.clock, sc), "time_limit": float(o.time_limit)}
    return out


# -- the intent ---------------------------------------------------------------------------
def _step(s: Step, sc: Scene) -> Doc:
    """``{name, <its kind's key>: its fields}``: a step writes itself (``to_yaml``)."""
    return {"name": s.name, type(s.action).key: s.action.to_yaml(sc)}


def _end(start: float, span: float) -> float:
    """The ``b`` of ``between: [a, b]`` that the reader turns into exactly ``span``
    (``b - a``): ``a + span``, or a float an ulp or two from it."""
    for b in _near_ulps(start + span):
        if b - start == span:
            return b
    return start + span


# -- how demonstrations vary --------------------------------------------------------------
def _teach(t: Teach, intent: tuple[Step, ...], sc: Scene) -> Doc:
    default = Teach()
    out: Doc = {}
    _put(out, "start", t.start, default.start)
    if t.start_height is not None:
        out["start_height"] = _floats(t.start_height)
    _put(out, "via", t.via, default.via)
    if t.via_at != default.via_at:
        out["via_at"] = _floats(t.via_at)
    _put(out, "speed", t.speed, default.speed)
    speeds: Doc = {}
    for key, name in TEACH_SPEEDS.items():
        _put(speeds, key, getattr(t, name), getattr(default, name))
    if speeds:
        out["speeds"] = speeds
    if t.steps:
        actions = {s.name: s.action for s in intent}
        out["steps"] = {n: _teach_step(ts, actions[n], sc) for n, ts in t.steps.items()}
    return out


def _teach_step(ts: TeachStep, action: StepKind, sc: Scene) -> Doc:
    """What of a step varies (``{}`` when all is as by default: the step is still named);
    what its kind reads itself, its kind writes (``teach_to_yaml``)."""
    default = TeachStep()
    out: Doc = {}
    _put(out, "yaw", ts.yaw, default.yaw, _angle)
    out.update(action.teach_to_yaml(ts, sc))
    if ts.margin is not None:
        out["margin"] = _floats(ts.margin)
    _put(out, "miss", ts.miss, default.miss)
    return out
