"""The skill model: plain, validated, immutable data (no I/O, no per-tick state).

A skill is a Shared Control Template (Ch. 3): a finite state machine whose states hold
input mappings (user input -> end-effector motion relative to a feature frame) and
active constraints (geometric limits on the end-effector pose), expressed in the frame
of one task object. The kinds of elements are classes of their own, one per kind, each
in the module of its element kind: :mod:`sctd.skill.mappings`,
:mod:`sctd.skill.constraints`, :mod:`sctd.skill.transitions` and
:mod:`sctd.skill.fields`. :mod:`sctd.skill.loader` builds a skill from YAML;
:mod:`sctd.skill.engine` runs it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

from .fields import Field

if TYPE_CHECKING:
    from .constraints import ActiveConstraint
    from .mappings import InputMapping
    from .transitions import Transition

Array = NDArray[np.float64]

AXIS_NAMES = ("tx", "ty", "tz", "rx", "ry", "rz")
BUILTIN_FRAMES = ("ee", "object")
WORLD_OBJECT = "world"  # a skill's ``object``: the world frame itself (no object pose needed)


@dataclass(frozen=True)
class Frame:
    """A feature frame: a fixed offset ``T_parent_frame`` (4, 4) from the ee or the object."""

    name: str
    parent: Literal["ee", "object"]
    T_parent_frame: Array


@dataclass(frozen=True)
class VectorFieldModel:
    """Fields plus the demonstration points they were fitted on (model file data).

    ``points`` (n, 3) positions of the mapping's frame in the object frame,
    ``quaternions`` (n, 4) orientations (x, y, z, w) of that frame, and
    ``responsibilities`` (n, K) the EM membership of each point in each field.
    """

    fields: tuple[Field, ...]
    points: Array
    quaternions: Array
    responsibilities: Array


@dataclass(frozen=True)
class State:
    name: str
    input_mappings: tuple[InputMapping, ...]
    active_constraints: tuple[ActiveConstraint, ...]


@dataclass(frozen=True)
class Limits:
    """Speeds at full input (SI). The daemon's own limits cap these further."""

    max_linear_speed: float = 0.10
    max_angular_speed: float = 0.5


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

    def state_index(self, name: str) -> int:
        for i, s in enumerate(self.states):
            if s.name == name:
                return i
        raise KeyError(name)
