"""The skill model: plain, validated, immutable data (no I/O, no per-tick state).

A skill is a Shared Control Template (Ch. 3): a finite state machine whose states hold
input mappings (user input -> end-effector motion relative to a feature frame) and
active constraints (geometric limits on the end-effector pose), expressed in the frame
of one task object. The kinds of elements are classes of their own, one per kind, each
in the module of its element kind: :mod:`sctd.skill.mappings`,
:mod:`sctd.skill.constraints`, :mod:`sctd.skill.transitions` and
:mod:`sctd.skill.fields`; frames are in :mod:`sctd.skill.frames`, vector-field models
in :mod:`sctd.skill.modelfile`, a state's gripper action in :mod:`sctd.skill.gripper`.
The model sits above all of them (they never import it). :mod:`sctd.skill.loader`
builds a skill from YAML; :mod:`sctd.skill.engine` runs it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .constraints import ActiveConstraint
from .frames import Frame
from .gripper import GripperAction
from .mappings import InputMapping
from .modelfile import VectorFieldModel
from .region import Region
from .transitions import Transition


@dataclass(frozen=True)
class State:
    """One FSM state: its input mappings, its active constraints and, optionally, what
    the gripper does when a transition enters it (:mod:`sctd.skill.gripper`) and the
    body whose frame the state is expressed in (``object``; None: the skill's object).

    Two frames for one task: a pick-and-place reaches and grasps relative to the item
    and carries and puts down relative to where it goes (the thesis' Shared Control
    Templates give each state its own feature frame).
    """

    name: str
    input_mappings: tuple[InputMapping, ...]
    active_constraints: tuple[ActiveConstraint, ...]
    gripper: GripperAction | None = None
    object: str | None = None


@dataclass(frozen=True)
class Limits:
    """Speeds at full input (SI). The daemon's own limits cap these further."""

    max_linear_speed: float = 0.10
    max_angular_speed: float = 0.5

    @property
    def speeds(self) -> tuple[float, float, float, float, float, float]:
        """The speed at full input per displacement axis: tx, ty, tz (m/s), rx, ry, rz
        (rad/s)."""
        v, w = self.max_linear_speed, self.max_angular_speed
        return v, v, v, w, w, w


@dataclass(frozen=True)
class Skill:
    """A validated skill. ``id`` is the content hash of its bundle."""

    name: str
    object: str
    frames: dict[str, Frame]
    states: tuple[State, ...]
    transitions: tuple[Transition, ...]
    start: str
    end: str
    limits: Limits = field(default_factory=Limits)
    min_dwell: float = 0.05
    description: str = ""
    id: str = ""
    source: str = ""
    candidate_frames: tuple[dict, ...] = ()
    region: Region | None = None  # where its demonstrations went (:mod:`.region`); None: not said

    def models(self) -> dict[str, VectorFieldModel]:
        """The model files the states' elements read, by relative path, in the order
        they are first named.

        Raises
        ------
        ValueError
            Two elements name one file but hold different models (a loaded skill reads
            each file once, so only a skill built in code can).
        """
        out: dict[str, VectorFieldModel] = {}
        for s in self.states:
            elements: list[InputMapping | ActiveConstraint] = [*s.input_mappings, *s.active_constraints]
            for element in elements:
                for rel, model in element.models():
                    if out.setdefault(rel, model) is not model:
                        raise ValueError(f"two models for the model file {rel!r}")
        return out

    def state_object(self, index: int) -> str:
        """The body whose frame state number ``index`` is expressed in: its own
        ``object``, else the skill's."""
        own = self.states[index].object
        return self.object if own is None else own

    def objects(self) -> tuple[str, ...]:
        """Every body the skill names, the skill's ``object`` first, then the states'
        own in state order, each once (``world`` among them where named: it needs no
        pose)."""
        out = [self.object]
        for s in self.states:
            if s.object is not None and s.object not in out:
                out.append(s.object)
        return tuple(out)

    def state_index(self, name: str) -> int:
        for i, s in enumerate(self.states):
            if s.name == name:
                return i
        raise KeyError(name)
