"""A task file's document to a :class:`~.model.Task`, checked field by field.

Every problem is a :class:`TaskError` naming the file, the field's path and what is
wrong (``tasks/pour.yaml: scene.bodies.mug.position: expected a list of 3 numbers, got
str``); an unknown field is one, so that a misspelt key never passes silently.
"""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Collection
from typing import Any

import numpy as np

from sctd import se3
from sctd.skill.reader import Reader, kind_of

from . import kinds
from .model import (
    DONE,
    VERSION,
    AllOf,
    AnyOf,
    Body,
    Compare,
    FailRule,
    Held,
    Near,
    Not,
    Outcome,
    Predicate,
    Reading,
    Scene,
    Start,
    Step,
    Task,
    Teach,
    TeachStep,
    Vary,
)

NAME = re.compile(r"^[a-z][a-z0-9_]{0,39}$")
"""Task, body, frame and joint names: they go into Zenoh keys and file names."""
DEGREES = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*deg\s*$")
"""An angle written in degrees: ``"15 deg"``."""
HAND = "hand"
"""The frame name predicates use for the hand (the end-effector)."""


class TaskError(ValueError):
    """A task failed to validate: ``file: path.to.field: what is wrong``."""

    def __init__(self, file: str, path: str, problem: str):
        self.file, self.path, self.problem = file, path, problem
        super().__init__(f"{file}: {path}: {problem}" if path else f"{file}: {problem}")

    def __reduce__(self):
        return (type(self), (self.file, self.path, self.problem))


class _Reader(Reader):
    def __init__(self, file: str):
        super().__init__(file, {})

    def fail(self, path: str, problem: str) -> TaskError:  # type: ignore[override]
        return TaskError(self.file, path, problem)

    def known_keys(self, d: dict, path: str, allowed: set[str]) -> None:
        extra = sorted(set(map(str, d)) - allowed)
        if extra:
            raise self.fail(f"{path}.{extra[0]}" if path else extra[0],
                            f"unknown field (allowed: {', '.join(sorted(allowed))})")

    def fields(self, v: Any, path: str, required: set[str], optional: Collection[str] = ()) -> dict:
        """A mapping with exactly the ``required`` keys and some of the ``optional`` ones."""
        d = self.mapping(v, path)
        self.known_keys(d, path, required | set(optional))
        missing = sorted(required - set(d))
        if missing:
            raise self.fail(f"{path}.{missing[0]}" if path else missing[0], "missing")
        return d

    def name(self, v: Any, path: str) -> str:
        s = self.string(v, path)
        if not NAME.match(s):
            raise self.fail(path, f"expected a name of lower-case letters, digits and _ (at most 40, "
                                  f"a letter first), got {s!r}")
        return s

    def positive(self, v: Any, path: str) -> float:
        return self.number(v, path, lo=0.0, lo_open=True)

    def nonneg(self, v: Any, path: str) -> float:
        return self.number(v, path, lo=0.0)

    def angle(self, v: Any, path: str, lo: float | None = None, hi: float | None = None,
              lo_open: bool = False) -> float:
        """Radians: a number, or a string ``"<number> deg"``."""
        if isinstance(v, str):
            m = DEGREES.match(v)
            if m is None:
                raise self.fail(path, f"expected an angle in rad, or \"<number> deg\", got {v!r}")
            v = math.radians(float(m.group(1)))
        return self.number(v, path, lo, hi, lo_open)

    def tilt(self, v: Any, path: str) -> float:
        """A tilt from the vertical: an angle in (0, pi]."""
        return self.angle(v, path, lo=0.0, hi=math.pi, lo_open=True)

    def pair(self, v: Any, path: str) -> tuple[float, float]:
        """``[lo, hi]``, two numbers with lo < hi."""
        lo, hi = self.vector(v, path, 2).tolist()
        if not lo < hi:
            raise self.fail(path, f"expected [low, high] with low < high, got [{lo}, {hi}]")
        return lo, hi

    def transform(self, d: dict, path: str) -> np.ndarray:
        """``position`` [3] and ``rpy`` [3] (roll, pitch, yaw about fixed x, y, z; angles
        as :meth:`angle` reads them; default 0)."""
        p = self.vector(d["position"], f"{path}.position", 3)
        rpy = np.zeros(3)
        if "rpy" in d:
            if not isinstance(d["rpy"], list) or len(d["rpy"]) != 3:
                raise self.fail(f"{path}.rpy", f"expected a list of 3 angles, got {kind_of(d['rpy'])}")
            rpy = np.array([self.angle(a, f"{path}.rpy[{i}]") for i, a in enumerate(d["rpy"])])
        return se3.transform_from_rt(rpy_matrix(rpy), p)

    def vary(self, v: Any, path: str) -> Vary:
        d = self.fields(v, path, set(), {"position", "yaw"})
        pos = np.zeros(3)
        if "position" in d:
            x = d["position"]
            pos = (np.full(3, self.nonneg(x, f"{path}.position")) if not isinstance(x, list)
                   else self.vector(x, f"{path}.position", 3))
            if np.any(pos < 0):
                raise self.fail(f"{path}.position", "must be >= 0 on every axis")
        yaw = self.angle(d.get("yaw", 0.0), f"{path}.yaw", lo=0.0, hi=math.pi)
        return Vary(pos, yaw)


def _cos_sin(a: float) -> tuple[float, float]:
    """cos and sin of ``a``, exact at quarter turns (sin(pi) is 0, not 1.2e-16: a
    ``yaw: 3.141592653589793`` gives the same matrix as one written out)."""
    c, s = math.cos(a), math.sin(a)
    return (0.0 if abs(c) < 1e-15 else c), (0.0 if abs(s) < 1e-15 else s)


def rpy_matrix(rpy: np.ndarray) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll), shape (3, 3)."""
    (cr, sr), (cp, sp), (cy, sy) = (_cos_sin(float(a)) for a in rpy)
    Rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    return Rz @ Ry @ Rx


def task_from_document(doc: Any, file: str) -> Task:
    """The task a parsed YAML document describes."""
    r = _Reader(file)
    d = r.fields(doc, "", {"sctd_task", "name", "object", "scene", "outcome", "intent"},
                 {"title", "description", "source", "teach"})
    version = d["sctd_task"]
    if version != VERSION:
        raise r.fail("sctd_task", f"this sctd reads task files of version {VERSION}, got {version!r}")
    name = r.name(d["name"], "name")
    scene = _scene(r, d["scene"], "scene")
    obj = r.name(d["object"], "object")
    if obj not in scene.bodies:
        raise r.fail("object", f"unknown body {obj!r} (bodies: {', '.join(scene.bodies)})")
    outcome = _outcome(r, d["outcome"], "outcome", scene)
    intent = _intent(r, d["intent"], "intent", scene, outcome)
    for entries in scene.sections.values():
        for e in entries.values():
            e.check_intent(r, scene, obj, intent)
    teach = _teach(r, d["teach"], "teach", intent, scene) if "teach" in d else Teach()
    text = {k: (r.string(d[k], k) if k in d else "") for k in ("title", "description", "source")}
    return Task(name, text["title"] or name, text["description"], text["source"], obj, scene, outcome,
                intent, teach, file)


def _scene(r: _Reader, v: Any, path: str) -> Scene:
    section_kinds = kinds.sections()
    d = r.fields(v, path, {"start", "bodies"}, {"held", *section_kinds})
    s = r.fields(d["start"], f"{path}.start", {"position"}, {"rpy", "vary"})
    start = Start(r.transform(s, f"{path}.start"),
                  r.vary(s["vary"], f"{path}.start.vary") if "vary" in s else Vary())
    bodies: dict[str, Body] = {}
    for key, b in r.mapping(d["bodies"], f"{path}.bodies").items():
        where = f"{path}.bodies.{key}"
        bodies[r.name(key, where)] = _body(r, key, b, where)
    if not bodies:
        raise r.fail(f"{path}.bodies", "expected at least one body")
    held = _held(r, d["held"], f"{path}.held") if "held" in d else None
    scene = _completed(r, Scene(start, bodies, held), path)
    bodies, held = scene.bodies, scene.held
    for key, cls in section_kinds.items():
        if key in d:
            sections = {**scene.sections, key: _section(r, cls, d[key], f"{path}.{key}", scene)}
            scene = dataclasses.replace(scene, sections=sections)
    named = [n for entries in scene.sections.values() for n in entries]
    names = [*scene.frames(), *named, HAND]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        shared = ", ".join(["bodies", "held frames", *section_kinds])
        raise r.fail(path, f"the name {twice[0]!r} is used twice ({shared} and {HAND!r} share one "
                           "namespace)")
    for name, b in bodies.items():
        for key, facet in b.facets.items():
            facet.check(r, name, scene, f"{path}.bodies.{name}.{key}")
    _quantities_once(r, scene, path)
    for entries in scene.sections.values():
        for e in entries.values():
            e.check(r, scene, path)
    return scene


def _section(r: _Reader, cls: type[kinds.Section], v: Any, path: str,
             scene: Scene) -> dict[str, kinds.Section]:
    """A section of a registered kind: ``{name: entry}``, at least one (``scene``: as read
    so far)."""
    items = r.mapping(v, path).items()
    if not items:
        raise r.fail(path, f"expected at least one {cls.noun} (or no {cls.key} field)")
    out: dict[str, kinds.Section] = {}
    for key, e in items:
        name = r.name(key, f"{path}.{key}")
        out[name] = cls.read(r, name, e, f"{path}.{key}", scene)
    return out


def _body(r: _Reader, name: str, v: Any, path: str) -> Body:
    facet_kinds = kinds.facets()
    d = r.fields(v, path, {"position"}, {"rpy", "vary", *facet_kinds})
    facets = {k: cls.read(r, d[k], f"{path}.{k}") for k, cls in facet_kinds.items() if k in d}
    return Body(name, r.transform(d, path), r.vary(d["vary"], f"{path}.vary") if "vary" in d else Vary(),
                facets)


def _held(r: _Reader, v: Any, path: str) -> Held:
    facet_kinds = kinds.held_facets()
    d = r.fields(v, path, {"name", "mass", "com"}, {"frames", *facet_kinds})
    frames: dict[str, np.ndarray] = {}
    for key, f in r.mapping(d.get("frames", {}), f"{path}.frames").items():
        where = f"{path}.frames.{key}"
        frames[r.name(key, where)] = r.transform(r.fields(f, where, {"position"}, {"rpy"}), where)
    facets = {k: cls.read(r, d[k], f"{path}.{k}") for k, cls in facet_kinds.items() if k in d}
    return Held(r.name(d["name"], f"{path}.name"), r.nonneg(d["mass"], f"{path}.mass"),
                r.vector(d["com"], f"{path}.com", 3), frames, facets)


def _completed(r: _Reader, scene: Scene, path: str) -> Scene:
    """The scene with its facets completed from the rest of it (its bodies and held
    object, :meth:`~sctd.task.kinds.Facet.completed`: the contents' outlet and
    container, a surface's ``touch``): the held object's first, then the bodies'."""
    held = scene.held
    if held is not None:
        facets = {k: f.completed(r, held.name, scene, f"{path}.held.{k}") for k, f in held.facets.items()}
        held = dataclasses.replace(held, facets=facets)
    bodies = {}
    for name, b in scene.bodies.items():
        facets = {k: f.completed(r, name, scene, f"{path}.bodies.{name}.{k}") for k, f in b.facets.items()}
        bodies[name] = dataclasses.replace(b, facets=facets)
    return dataclasses.replace(scene, bodies=bodies, held=held)


def _facets_of(scene: Scene, element: str) -> dict[str, kinds.Facet]:
    """The facets of the body called ``element``, or of the held object so called; none
    for another element."""
    body = scene.bodies.get(element)
    if body is not None:
        return body.facets
    return scene.held.facets if scene.held is not None and scene.held.name == element else {}


# -- the outcome ----------------------------------------------------------------------
def _elements(scene: Scene) -> dict[str, str]:
    """Element name -> kind, of what reports readings."""
    out: dict[str, str] = {}
    if scene.held is not None:  # (the held object's facets: its contents)
        first = next((k for k, f in scene.held.facets.items() if f.quantities), None)
        if first is not None:
            out[scene.held.name] = first
    out |= {n: kinds.sections()[key].noun for key, entries in scene.sections.items() for n in entries}
    for n, b in scene.bodies.items():  # (a body's facets: the last with readings names it, a button)
        last = [k for k, f in b.facets.items() if f.quantities]
        if last:
            out[n] = last[-1]
    return out


def quantities(kind: str) -> tuple[str, ...]:
    """What an element of ``kind`` reports: a registered facet's, by its key, or a
    registered section's, by its noun."""
    facet = {**kinds.held_facets(), **kinds.facets()}.get(kind)
    if facet is not None:
        return facet.quantities
    return next(c.quantities for c in kinds.sections().values() if c.noun == kind)


def _entry(scene: Scene, element: str) -> kinds.Section | None:
    """The section entry called ``element``, if one is."""
    return next((e[element] for e in scene.sections.values() if element in e), None)


def _flag(reading: Reading, scene: Scene) -> bool:
    """Whether ``reading`` is true or false rather than a number."""
    for f in _facets_of(scene, reading.element).values():
        if reading.quantity in f.quantities:
            return reading.quantity in f.flags
    entry = _entry(scene, reading.element)
    return entry is not None and reading.quantity in entry.flags


def _quantities_once(r: _Reader, scene: Scene, path: str) -> None:
    """A body reports each quantity once: its facets with readings do not share one."""
    for n, b in scene.bodies.items():
        seen: list[str] = []
        for k, f in b.facets.items():
            twice = sorted(set(seen) & set(f.quantities))
            if twice:
                raise r.fail(f"{path}.bodies.{n}.{k}", f"reports {twice[0]!r}, as another element of "
                                                        f"{n!r} does: one reading, one element")
            seen += f.quantities


def _reading(r: _Reader, v: Any, path: str, scene: Scene) -> Reading:
    s = r.string(v, path)
    element, _, quantity = s.partition(".")
    elements = _elements(scene)
    if element not in elements:
        raise r.fail(path, f"unknown element {element!r} in {s!r} (elements with readings: "
                           f"{', '.join(elements) or 'none'})")
    known = _all_quantities(scene, element, elements[element])
    if quantity not in known:
        kind = elements[element]
        raise r.fail(path, f"{'an' if kind[0] in 'aeiou' else 'a'} {kind} reports {', '.join(known)}; "
                           f"got {quantity!r}")
    return Reading(element, quantity)


def _all_quantities(scene: Scene, element: str, kind: str) -> tuple[str, ...]:
    """Every quantity ``element`` reports: a body's (or the held object's) facets', in their
    order; else its kind's."""
    facets = _facets_of(scene, element)
    if not facets:
        return quantities(kind)
    out: list[str] = []
    for f in facets.values():
        out += [q for q in f.quantities if q not in out]
    return tuple(out)


COMPARISONS = ("at_least", "at_most", "above", "below", "is")


def _angular(reading: Reading, scene: Scene) -> bool:
    """Whether ``reading`` is an angle (a revolute joint's position): its bounds may be
    written in degrees."""
    if any(reading.quantity in f.angular for f in _facets_of(scene, reading.element).values()):
        return True
    entry = _entry(scene, reading.element)
    return entry is not None and entry.is_angular(reading.quantity)


def predicate(r: _Reader, v: Any, path: str, scene: Scene) -> Predicate:
    """``true``/``false``, ``{reading, at_least|at_most|above|below|is}``, ``{near: {frame,
    to, within}}``, ``{all: [...]}``, ``{any: [...]}`` or ``{not: ...}``."""
    if isinstance(v, bool):
        return v
    d = r.mapping(v, path)
    if "reading" in d:
        r.known_keys(d, path, {"reading", *COMPARISONS})
        reading = _reading(r, d["reading"], f"{path}.reading", scene)
        bounds = {k: d[k] for k in COMPARISONS if k in d}
        if not bounds:
            raise r.fail(path, f"expected a comparison: one or two of {', '.join(COMPARISONS)}")
        flag = _flag(reading, scene)
        if flag != ("is" in bounds) or (flag and len(bounds) > 1):
            how = ("a flag: compare it with is: true|false" if flag
                   else "a number: compare it with at_least, at_most, above or below")
            raise r.fail(path, f"{reading} is {how}")
        if flag:
            if not isinstance(bounds["is"], bool):
                raise r.fail(f"{path}.is", f"expected true or false, got {kind_of(bounds['is'])}")
            return Compare(reading, is_=bounds["is"])
        bound = r.angle if _angular(reading, scene) else r.number
        nums = {k: bound(x, f"{path}.{k}") for k, x in bounds.items()}
        return Compare(reading, nums.get("at_least"), nums.get("at_most"), nums.get("above"),
                       nums.get("below"))
    if len(d) != 1:
        got = ", ".join(map(str, d)) or "nothing"
        raise r.fail(path, f"expected one of reading, near, all, any, not; got {got}")
    (key, x), = d.items()
    if key == "near":
        n = r.fields(x, f"{path}.near", {"frame", "to", "within"})
        frame = r.string(n["frame"], f"{path}.near.frame")
        if frame != HAND and frame not in scene.frames():
            raise r.fail(f"{path}.near.frame", f"unknown frame {frame!r} (frames: {HAND}, "
                                               f"{', '.join(scene.frames())})")
        to = r.string(n["to"], f"{path}.near.to")
        if to not in scene.bodies:
            raise r.fail(f"{path}.near.to", f"unknown body {to!r} (bodies: {', '.join(scene.bodies)})")
        return Near(frame, to, r.positive(n["within"], f"{path}.near.within"))
    if key in ("all", "any"):
        if not isinstance(x, list) or not x:
            raise r.fail(f"{path}.{key}", f"expected a non-empty list of predicates, got {kind_of(x)}")
        terms = tuple(predicate(r, t, f"{path}.{key}[{i}]", scene) for i, t in enumerate(x))
        return AllOf(terms) if key == "all" else AnyOf(terms)
    if key == "not":
        return Not(predicate(r, x, f"{path}.not", scene))
    raise r.fail(f"{path}.{key}", "unknown predicate (expected reading, near, all, any or not)")


def _outcome(r: _Reader, v: Any, path: str, scene: Scene) -> Outcome:
    d = r.fields(v, path, {"done", "progress", "clock", "time_limit"}, {"success", "done_reason", "fail"})
    fails = d.get("fail", [])
    if not isinstance(fails, list):
        raise r.fail(f"{path}.fail", f"expected a list of {{when, reason}}, got {kind_of(fails)}")
    rules = []
    for i, f in enumerate(fails):
        where = f"{path}.fail[{i}]"
        g = r.fields(f, where, {"when", "reason"})
        rules.append(FailRule(predicate(r, g["when"], f"{where}.when", scene),
                              r.string(g["reason"], f"{where}.reason")))
    return Outcome(
        done=predicate(r, d["done"], f"{path}.done", scene),
        success=predicate(r, d.get("success", True), f"{path}.success", scene),
        done_reason=r.string(d.get("done_reason", "done"), f"{path}.done_reason"),
        fail=tuple(rules),
        progress=_reading(r, d["progress"], f"{path}.progress", scene),
        clock=predicate(r, d["clock"], f"{path}.clock", scene),
        time_limit=r.positive(d["time_limit"], f"{path}.time_limit"))


# -- the intent ---------------------------------------------------------------------------
def _intent(r: _Reader, v: Any, path: str, scene: Scene, outcome: Outcome) -> tuple[Step, ...]:
    """The ordered steps, each of a registered kind (:mod:`.kinds`), read with the steps
    before it (a tilt, an upright or a joint's move refuses to come before any reach)."""
    if not isinstance(v, list) or not v:
        raise r.fail(path, f"expected a non-empty list of steps, got {kind_of(v)}")
    steps: list[Step] = []
    registered = kinds.step_kinds()
    for i, item in enumerate(v):
        where = f"{path}[{i}]"
        d = r.mapping(item, where)
        r.known_keys(d, where, {"name", *registered})
        if "name" not in d:
            raise r.fail(f"{where}.name", "missing")
        name = r.name(d["name"], f"{where}.name")
        if name == DONE or name in (s.name for s in steps):
            why = "the phase after the last step" if name == DONE else "the name of an earlier step"
            raise r.fail(f"{where}.name", f"{name!r} is {why}")
        given = [k for k in registered if k in d]
        if len(given) != 1:
            raise r.fail(where, f"expected one of {', '.join(registered)}; got {', '.join(given) or 'none'}")
        kind = given[0]
        steps.append(Step(name, registered[kind].read(r, d[kind], f"{where}.{kind}", scene, outcome,
                                                      tuple(steps))))
    return tuple(steps)


TEACH_SPEEDS = {"reach": "reach_speed", "turn": "turn_rate", "tilt": "tilt_rate", "joint": "joint_speed",
                "press": "press_speed"}
"""``teach.speeds``' keys and the :class:`~.model.Teach` fields they set."""


def _teach(r: _Reader, v: Any, path: str, intent: tuple[Step, ...], scene: Scene) -> Teach:
    """How demonstrations vary: ``start``, ``start_height``, ``via``, ``via_at``,
    ``speed``, ``speeds`` (reach, turn, tilt, joint, press) and ``steps`` by the intent's
    step names."""
    d = r.fields(v, path, set(), {"start", "start_height", "via", "via_at", "speed", "speeds", "steps"})
    out: dict[str, Any] = {}
    for k in ("start", "via"):
        if k in d:
            out[k] = r.nonneg(d[k], f"{path}.{k}")
    if "speed" in d:
        out["speed"] = r.number(d["speed"], f"{path}.speed", lo=0.0, hi=0.9)
    if "start_height" in d:
        out["start_height"] = r.pair(d["start_height"], f"{path}.start_height")
    if "via_at" in d:
        lo, hi = out["via_at"] = r.pair(d["via_at"], f"{path}.via_at")
        if not (0.0 < lo and hi < 1.0):
            raise r.fail(f"{path}.via_at", f"expected fractions strictly between 0 and 1, got [{lo}, {hi}]")
    if "speeds" in d:
        sp = r.fields(d["speeds"], f"{path}.speeds", set(), set(TEACH_SPEEDS))
        for k, f in TEACH_SPEEDS.items():
            if k in sp:
                out[f] = r.positive(sp[k], f"{path}.speeds.{k}")
    if "steps" in d:
        by_name = {s.name: s.action for s in intent if type(s.action).teaches is not None}
        steps = r.fields(d["steps"], f"{path}.steps", set(), set(by_name))
        out["steps"] = {str(n): _teach_step(r, x, f"{path}.steps.{n}", by_name[str(n)], scene)
                        for n, x in steps.items()}
    return Teach(**out)


def _teach_step(r: _Reader, v: Any, path: str, action: kinds.StepKind, scene: Scene) -> TeachStep:
    """A step's variation: what a step of its kind can vary (:attr:`~.kinds.StepKind.teaches`;
    ``yaw``, ``miss`` and ``margin`` read here, the rest by its kind)."""
    d = r.fields(v, path, set(), set(type(action).teaches or ()))
    out: dict[str, Any] = {}
    if "yaw" in d:
        out["yaw"] = r.angle(d["yaw"], f"{path}.yaw", lo=0.0, hi=math.pi)
    if "miss" in d:
        out["miss"] = r.positive(d["miss"], f"{path}.miss")
    if "margin" in d:
        lo, hi = out["margin"] = r.pair(d["margin"], f"{path}.margin")
        if lo < 0.0:
            raise r.fail(f"{path}.margin", f"expected depths >= 0 past the click, got [{lo}, {hi}]")
    out.update(action.read_teach(r, d, path, scene))
    return TeachStep(**out)
