"""The skill model: plain, validated, immutable data (no I/O, no per-tick state).

A skill is a Shared Control Template (Ch. 3): a finite state machine whose states hold
input mappings (user input -> end-effector motion relative to a feature frame) and
active constraints (geometric limits on the end-effector pose), expressed in the frame
of one task object. :mod:`sctd.skill.loader` builds these from YAML and validates every
field; :mod:`sctd.skill.engine` runs them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

AXIS_NAMES = ("tx", "ty", "tz", "rx", "ry", "rz")
BUILTIN_FRAMES = ("ee", "object")
WORLD_OBJECT = "world"  # a skill's ``object``: the world frame itself (no object pose needed)


@dataclass(frozen=True)
class Frame:
    """A feature frame: a fixed offset ``T_parent_frame`` from the ee or the object."""

    name: str
    parent: Literal["ee", "object"]
    T_parent_frame: Array  # (4, 4)


# --- input mappings -------------------------------------------------------------------


@dataclass(frozen=True)
class LinearMapping:
    """Linear input mapping (eq. 4.1, Algorithm 2).

    ``matrix`` (6, k) maps input axes to a displacement [tx, ty, tz, rx, ry, rz] at full
    speed: rotation about ``frame``'s origin and its own axes (``rotation == "frame"``,
    Algorithm 2) or the object's axes; translation in the object's axes
    (``translation == "object"``, Algorithm 2) or in ``frame``'s axes.
    """

    frame: str
    matrix: Array  # (6, k)
    translation: Literal["object", "frame"] = "object"
    rotation: Literal["frame", "object"] = "frame"
    type: str = "linear"


@dataclass(frozen=True)
class Field:
    """One basic vector field (Ch. 4.2.2) in the object frame.

    ``translation``: unit ``direction``. ``cylinder``: rotation about the line through
    ``point`` along unit ``axis`` (circulation by the right-hand rule about ``axis``).
    ``sphere``: motion tangent to spheres about ``centre``.
    """

    type: Literal["translation", "cylinder", "sphere"]
    weight: float = 1.0  # mixing proportion pi (eq. 4.29)
    sigma: float = 0.3  # angular spread (rad) of its vectors (eq. 4.30)
    inliers: int = 0
    direction: Array | None = None
    point: Array | None = None
    axis: Array | None = None
    centre: Array | None = None
    radius: float | None = None
    pivot: Array | None = None  # the centre (sphere) or an axis point (cylinder) as a fixed
    # point of the mapping's frame (its offset in that frame), when the demonstrations
    # turned about a point of the hand (a bottle's opening): rigid motion turns about it


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
class VectorFieldMapping:
    """Vector-field input mapping (Ch. 4.2.5, Algorithm 7).

    The first three input axes are a translation command in the object's axes. In
    ``scale`` mode the command is scaled by the sigmoid-normalised agreement with the
    fields (eqs. 4.31-4.34); in ``blend`` mode its direction is bent towards them
    (eq. 4.35) without changing its magnitude, so zero input never moves.

    ``motion``: ``translate`` moves the frame by the (scaled or bent) command, as in the
    thesis; ``rigid`` turns the part of it that follows a rotational field (tangent to
    a sphere, around a cylinder's axis), weighted by the field's membership, into a
    rotation of the whole hand about the field's centre or axis, so that the hand turns
    as it moves along the field (a bottle tilts about its opening, a crank's handle
    keeps its grip) instead of waiting for an orientation constraint to catch up.

    ``combine``: how the fields' agreements make one scaling (``scale``) and one bend
    (``blend``): ``most_probable`` (eq. 4.31) and ``weighted`` (eq. 4.32) weigh them by
    the position's membership ``P(F | p)``; ``intent`` by the membership given the
    command as well, ``P(F | p, u) ~ P'(F | p) exp(intent_kappa * s_F(u))`` with ``P'``
    the membership mixed with 10 % of the fields' weights: where fields overlap in
    space (the start of a reach and the end of a pull), the one the user's push
    follows is the one the user means.
    """

    model_file: str
    model: VectorFieldModel
    frame: str = "ee"
    mode: Literal["scale", "blend"] = "scale"
    combine: Literal["most_probable", "weighted", "intent"] = "weighted"
    intent_kappa: float = 4.0
    min_v: float = 0.1
    k_s: float = 0.5
    max_n: int = 5
    max_d: float = 0.15
    blend: float = 0.5
    motion: Literal["translate", "rigid"] = "translate"
    type: str = "vector_field"


InputMapping = LinearMapping | VectorFieldMapping


# --- active constraints ---------------------------------------------------------------


@dataclass(frozen=True)
class TiltCone:
    """``axis`` (in ``frame``) stays within ``max_angle`` of ``reference`` (object frame)."""

    frame: str
    axis: Array
    reference: Array
    max_angle: float
    type: str = "tilt_cone"


@dataclass(frozen=True)
class Band:
    """``frame``'s origin keeps a signed distance in [lower, upper] along ``normal``
    from the plane through ``point`` (object frame): a height band when normal is z."""

    frame: str
    normal: Array
    point: Array
    lower: float
    upper: float
    type: str = "band"


@dataclass(frozen=True)
class Box:
    """``frame``'s origin stays inside the axis-aligned box [lower, upper] (object frame)."""

    frame: str
    lower: Array
    upper: Array
    type: str = "box"


@dataclass(frozen=True)
class NeighbourOrientation:
    """Orientation of ``frame`` pulled to the distance-weighted mean orientation of the
    demonstration points near it (Ch. 4.2.5, Algorithm 7 lines 2-5)."""

    model_file: str
    model: VectorFieldModel
    frame: str = "ee"
    max_n: int = 5
    max_d: float = 0.15
    pivot: Array | None = None  # turn about this point of the frame (its offset), not its origin
    rotation_weight: float = 0.0  # m per rad: > 0 picks the neighbours nearest in pose, not
    # in position alone (the demonstrations near where the hand is *and* as it is turned)
    type: str = "neighbour_orientation"


ActiveConstraint = TiltCone | Band | Box | NeighbourOrientation


# --- transitions ----------------------------------------------------------------------


@dataclass(frozen=True)
class Transition:
    """A guarded FSM edge; guards carry a hysteresis ``margin`` in their own unit.

    ``hyperplane``: fires when ``(normal . p + offset) / |normal| > margin`` for the
    position p of ``frame`` in the object frame (the linear-SVM decision function of
    Algorithm 3, positive side = ``target``). ``distance``: the distance from ``frame``
    to ``point`` goes below ``threshold - margin`` (``direction == "below"``) or above
    ``threshold + margin``. ``timeout``: the state has been active ``threshold``
    seconds. ``force``: the measured force (along ``axis`` in the object frame, or its
    norm) exceeds ``threshold + margin`` newtons.
    """

    source: str
    target: str
    type: Literal["hyperplane", "distance", "timeout", "force", "button"]
    frame: str = "ee"
    normal: Array | None = None
    offset: float = 0.0
    point: Array | None = None
    threshold: float = 0.0
    direction: Literal["below", "above"] = "below"
    axis: Array | None = None
    margin: float = 0.0
    button: int = 0


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
