"""Kinds of task element as a registry: what a task file may say, one class a kind.

A **facet** is a kind of scene element that a body has (``bodies.<name>.<key>``): a
container things are poured into, a solid surface the hand touches and a push button in
it, a support things rest on, an item the hand can pick up, a knob it turns; or that the
object the hand holds from the start has (``held.<key>``): its contents, which flow out
when it is tilted. A **section** is a kind of scene element with a section of the scene
of its own (``scene.<key>.<name>``): a joint moving a handle
the hand grasps, a person's head, a zone a frame of the hand is timed in. A **step
kind** is a kind of intent step (``intent[i].<key>``): reach a goal with a frame, tilt it,
bring it upright, move a joint's handle, press a button, grasp an item, place it, turn a
knob in the hand. Each kind is one class that holds everything sctd knows of it:

- its data (the instance's fields) and its reader (:meth:`Facet.read`, :meth:`StepKind.read`);
- its writer (``to_yaml``: a task file's fields, read back to the same element);
- its readings (``<body>.<quantity>``, :attr:`Facet.quantities`; a section's entry's
  by its name);
- its physics in the simulator (:meth:`Facet.physics`, :meth:`Section.physics`: pure
  numpy on a :class:`World`);
- the simulated user's behaviour for a step (:meth:`StepKind.mind`: the minds of one
  run share a :class:`Run`, and may see each other's, a tilt its reach's);
- the demonstrator's plan for a step (:meth:`StepKind.plan`, by default its
  :meth:`StepKind.legs`; :mod:`.teaching`);
- its part of a task's floor (:meth:`StepKind.floor_path`, a :class:`Floor`);
- its drawing in the view (:meth:`Facet.shapes`, :meth:`Section.shapes`: boxes,
  cylinders and spheres, as data).

The kinds shipped with sctd are listed in :data:`BUILTIN`; a package adds its own under
the entry-point group ``sctd.task_kinds`` (a name for the kind's key, the class as its
value)::

    [project.entry-points."sctd.task_kinds"]
    hook = "mypackage.hook:Hook"

A built-in key wins over an entry point of the same key. Nothing here does I/O: a kind's
physics and its user's behaviour are pure functions of what they are given.
"""

from __future__ import annotations

import importlib
from functools import cache
from importlib.metadata import entry_points

from .base import (
    Facet,
    FacetPhysics,
    Fingers,
    Floor,
    Leg,
    Person,
    Run,
    Section,
    Shape,
    Sight,
    StepKind,
    StepMind,
    Want,
    World,
)

GROUP = "sctd.task_kinds"
BUILTIN = {
    "container": "sctd.task.kinds.contents:Container",
    "contents": "sctd.task.kinds.contents:Contents",
    "surface": "sctd.task.kinds.surface:Surface",
    "button": "sctd.task.kinds.surface:Button",
    "support": "sctd.task.kinds.pickable:Support",
    "item": "sctd.task.kinds.pickable:Item",
    "reach": "sctd.task.kinds.reach:Reach",
    "tilt": "sctd.task.kinds.tilt:Tilt",
    "upright": "sctd.task.kinds.tilt:Upright",
    "move_joint": "sctd.task.kinds.move_joint:MoveJoint",
    "press": "sctd.task.kinds.press:Press",
    "grasp": "sctd.task.kinds.handling:GraspStep",
    "place": "sctd.task.kinds.handling:PlaceStep",
    "knob": "sctd.task.kinds.knob:Knob",
    "turn": "sctd.task.kinds.knob:TurnStep",
    "joints": "sctd.task.kinds.joint:Joint",
    "heads": "sctd.task.kinds.head:Head",
    "zones": "sctd.task.kinds.zone:Zone",
}
"""The shipped kinds, by their key in a task file."""


class KindError(ValueError):
    """A registered kind that does not load or is not a kind."""


Kind = type[Facet] | type[Section] | type[StepKind]


def _load(key: str, target: str) -> Kind:
    module, _, attr = target.partition(":")
    try:
        cls = getattr(importlib.import_module(module), attr)
    except (ImportError, AttributeError) as e:
        raise KindError(f"task element kind {key!r} ({target}) does not load: {e}") from e
    if not (isinstance(cls, type) and issubclass(cls, Facet | Section | StepKind)):
        raise KindError(f"task element kind {key!r} ({target}): not a Facet or StepKind subclass, "
                        "nor a Section")
    if cls.key != key:
        raise KindError(f"task element kind {key!r} ({target}): its class says key {cls.key!r}")
    return cls


@cache
def registry() -> dict[str, Kind]:
    """Every kind by its key: the built-in ones, then the registered ones (loaded once)."""
    out = {key: _load(key, target) for key, target in BUILTIN.items()}
    for ep in sorted(entry_points(group=GROUP), key=lambda e: e.name):
        if ep.name not in out:
            out[ep.name] = _load(ep.name, ep.value)
    return out


def facets() -> dict[str, type[Facet]]:
    """The facet kinds of bodies, by key (in their order: a facet that another one refers
    to comes first: supports before items)."""
    kinds = [c for c in registry().values() if issubclass(c, Facet) and c.holder == "body"]
    return {c.key: c for c in sorted(kinds, key=lambda c: c.order)}


def held_facets() -> dict[str, type[Facet]]:
    """The facet kinds of the object the hand holds from the start (its contents), by key."""
    kinds = [c for c in registry().values() if issubclass(c, Facet) and c.holder == "held"]
    return {c.key: c for c in sorted(kinds, key=lambda c: c.order)}


def sections() -> dict[str, type[Section]]:
    """The section kinds, by key (the scene's field), in their order."""
    kinds = [c for c in registry().values() if issubclass(c, Section)]
    return {c.key: c for c in sorted(kinds, key=lambda c: c.order)}


def step_kinds() -> dict[str, type[StepKind]]:
    """The step kinds, by key."""
    return {k: c for k, c in registry().items() if issubclass(c, StepKind)}


__all__ = ["BUILTIN", "GROUP", "Facet", "FacetPhysics", "Fingers", "Floor", "KindError", "Leg", "Person",
           "Run", "Section", "Shape", "Sight", "StepKind", "StepMind", "Want", "World", "facets",
           "held_facets", "registry", "sections", "step_kinds"]
