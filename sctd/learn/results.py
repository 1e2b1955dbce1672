"""What a learning run returns: the fitted learner, the preprocessed demonstrations,
labels per raw displacement, timings, and the options of the skill it becomes.

:class:`SkillOptions` and :class:`VectorFieldOptions` are the hyperparameters that do
not change what is learned, only the skill written from it (Listings 4.1/4.2).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..skill import SkillError, SpeedNear
from ..skill.frames import builtin_frames
from ..skill.reader import Reader
from .frames import FoundFrame
from .gripper import GripperOptions, GripperPlan
from .linear import Hyperplane, LinearIMLearner
from .objects import ObjectChoice
from .params import Interval, OneOf, Text, Valid, get_params, hyperparameter
from .preprocess import Prepared, Preprocessing
from .traps import TrapFinding
from .vf import VectorFieldLearner
from .vfstates import StatePlan
from .vfturns import TurnInPlace

Array = NDArray[np.float64]

VF_COMBINE = ("intent", "weighted", "most_probable")
VF_STATES = ("auto", "blend")
VF_MOTION = ("rigid", "translate")
VF_DIRECTION = ("forward", "both")


SPEED_NEAR = "WITHIN:V:W[:X,Y,Z]"
"""How ``--speed-near`` is written: m, m/s, rad/s and optionally the point of the hand
(an offset from the ee, m)."""


def speed_near_from_text(text: str) -> SpeedNear:
    """The ``speed_near`` constraint (on the ee) that ``--speed-near`` text describes:
    ``WITHIN:V:W`` (the hand's origin within WITHIN m of the object moves at most V m/s
    and turns at most W rad/s) or ``WITHIN:V:W:X,Y,Z`` (that point of the hand instead),
    checked as a skill file's is.

    Raises
    ------
    ValueError
        Not so written, or a value a skill file may not hold (the message says which).
    """
    parts = text.split(":")
    if len(parts) not in (3, 4):
        raise ValueError(f"expected {SPEED_NEAR}, got {text!r}")
    try:
        within, v, w = (float(x) for x in parts[:3])
        point = [float(x) for x in parts[3].split(",")] if len(parts) == 4 else None
    except ValueError:
        raise ValueError(f"expected numbers as in {SPEED_NEAR}, got {text!r}") from None
    doc: dict[str, Any] = {"within": within, "max_linear_speed": v, "max_angular_speed": w}
    if point is not None:
        doc["point"] = point
    r = Reader("--speed-near", {})
    r.frames = builtin_frames()
    try:
        c = SpeedNear.from_yaml(r, {"type": SpeedNear.type, "frame": "ee", **doc}, "speed_near")
    except SkillError as e:
        raise ValueError(f"{e.path.removeprefix('speed_near.')}: {e.problem}") from None
    return c


@dataclass(frozen=True)
class SpeedNearText(Valid):
    """Empty (no cap), or what :func:`speed_near_from_text` reads."""

    def problem(self, value: Any) -> str:
        if value == "":
            return ""
        if not isinstance(value, str):
            return f"expected {SPEED_NEAR} or nothing, got {value!r}"
        try:
            speed_near_from_text(value)
        except ValueError as e:
            return str(e)
        return ""


@dataclass(frozen=True)
class SkillOptions:
    """Options of every learned skill.

    Parameters
    ----------
    object : str
        The task object whose frame the demonstrations are in (the skill's frame).
    max_linear_speed : float
        m/s at full input.
    max_angular_speed : float
        rad/s at full input.
    speed_near : str
        ``WITHIN:V:W[:X,Y,Z]`` (:func:`speed_near_from_text`): every state of the skill
        gets a ``speed_near`` constraint so written; empty for none.
    """

    object: str = hyperparameter("object", "task object whose frame the demonstrations are in (the "
                                 "skill's frame; sctd learn's default: the one the folder's demos.yaml "
                                 "names)", valid=Text())
    max_linear_speed: float = hyperparameter(0.10, "m/s at full input (default %(default)s)",
                                             valid=Interval(0, 1, open="low"))
    max_angular_speed: float = hyperparameter(0.50, "rad/s at full input (default %(default)s)",
                                              valid=Interval(0, 3, open="low"))
    speed_near: str = hyperparameter(
        "", "cap the speed near the object in every state: within WITHIN m of its origin the "
        "hand's origin (or the point X,Y,Z of the hand, m from the ee) moves at most V m/s "
        "and the hand turns at most W rad/s (a speed_near constraint; default none)",
        valid=SpeedNearText(), metavar=SPEED_NEAR)


@dataclass(frozen=True)
class VectorFieldOptions:
    """Run-time parameters of a vector-field skill (Listing 4.2).

    Parameters
    ----------
    min_v : float
        Floor of the scaling (eq. 4.34).
    max_d : float
        Neighbour distance (m) of the IM and the orientation constraint.
    k_s : float
        Sigmoid k (eq. 4.33).
    vf_max_n : int
        Demonstration neighbours consulted at run time.
    vf_combine : {"intent", "weighted", "most_probable"}
        How the fields' agreements combine (eqs. 4.31, 4.32, or by the membership given
        the position and the command).
    vf_rotation_weight : float
        m/rad: neighbours by pose rather than by position alone (0, the thesis).
    vf_motion : {"rigid", "translate"}
        Rotational fields turn the hand about their centre (rigid) or only move it
        (translate, the thesis).
    vf_direction : {"forward", "both"}
        A push back along a field goes against it (forward, the thesis: scaled down to
        ``min_v``) or follows it (both).
    vf_states : {"auto", "blend"}
        Sequential fields become states (:func:`~sctd.learn.vfstates.plan_states`) or
        all blend in one state (the thesis).
    vf_pivot_within : float
        m: a field the hand turned about a point of (its ``pivot``) turns it fully only
        with that point within this of the field's centre or axis, not at all from twice
        it; nearer the hand is moved, not turned (0: the runtime's 3.5 and 7 cm).
    vf_arrive : float
        m: the part of a push that carries such a point towards the field's centre or
        axis moves the hand, not turns it, in full from this far off, fading to none at
        the centre (the mapping's ``arrive``; 0: off, every part along the field turns).
    """

    min_v: float = hyperparameter(0.1, "eq. 4.34 floor", valid=Interval(0, 1))
    max_d: float = hyperparameter(0.15, "neighbour distance (m)", valid=Interval(0, 1, open="low"))
    k_s: float = hyperparameter(0.5, "sigmoid k (eq. 4.33)", valid=Interval(-1, 1, open="both"))
    vf_max_n: int = hyperparameter(5, "neighbours at run time", valid=Interval(1, 100, integer=True))
    vf_motion: str = hyperparameter(
        "rigid", "rigid: motion along a sphere or cylinder field turns the hand about its "
        "centre or axis; translate: only moves it, as in the thesis (default %(default)s)",
        choices=VF_MOTION, valid=OneOf(VF_MOTION))
    vf_rotation_weight: float = hyperparameter(
        0.1, "m per rad: the neighbour-orientation constraint takes the demonstration points "
        "nearest in pose (position and orientation) rather than in position alone (0, the "
        "thesis) (default %(default)s)", valid=Interval(0, 10))
    vf_combine: str = hyperparameter(
        "intent", "how fields' agreements combine: intent weighs them by the membership given "
        "the position and the command; weighted (eq. 4.32) and most_probable (eq. 4.31) by the "
        "position's alone (default %(default)s)", choices=VF_COMBINE, valid=OneOf(VF_COMBINE))
    vf_direction: str = hyperparameter(
        "forward", "forward: a push back along a field goes against it and is scaled down to "
        "min-v, as in the thesis; both: it follows the field as fast as a push along it (out "
        "of a drawer, off the lips) (default %(default)s)", choices=VF_DIRECTION,
        valid=OneOf(VF_DIRECTION))
    vf_states: str = hyperparameter(
        "blend", "auto: fields the demonstrations use one after the other, in separate places, "
        "become states with hyperplane transitions between them; blend: one state blends all "
        "fields, as in the thesis (default %(default)s)", choices=VF_STATES, valid=OneOf(VF_STATES))
    vf_pivot_within: float = hyperparameter(
        0.0, "m: a sphere or cylinder the hand turned about a point of (a cup's rim) turns it "
        "fully only with that point within this of its centre or axis, not at all from twice "
        "it; further out a push moves the hand (0: 3.5 and 7 cm) (default %(default)s)",
        valid=Interval(0, 0.5))
    vf_arrive: float = hyperparameter(
        0.0, "m: the part of a push that carries the point a sphere or cylinder turns the hand "
        "about (a cup's rim) towards the field's centre or axis moves the hand instead of "
        "turning it, in full from this far off, none at the centre: the cup comes to the lips "
        "upright and turns about its rim there (0: off) (default %(default)s)",
        valid=Interval(0, 0.5))


@dataclass
class LinearResult:
    """Linear IMs learned from demonstrations (:func:`~sctd.learn.learn_linear`)."""

    preprocessing: Preprocessing
    options: SkillOptions
    frames: dict[str, Array]  # name -> pose [7] (T_ee_frame)
    prepared: list[Prepared]
    learner: LinearIMLearner
    labels: dict[str, list[int]]  # demo -> state index per raw displacement
    timings: dict[str, float] = field(default_factory=dict)
    traps: list[TrapFinding] = field(default_factory=list)  # per transition (sctd.learn.traps)
    found_frames: list[FoundFrame] = field(default_factory=list)  # found, not given (frames.py)
    gripper: GripperPlan | None = None  # the demonstrations' gripper events (gripper.py), if any
    gripper_options: GripperOptions = field(default_factory=GripperOptions)
    objects: list[ObjectChoice] = field(default_factory=list)  # each state's frame (objects.py)
    back: dict[int, Hyperplane] = field(default_factory=dict)  # k+1 -> k in another frame, by k
    frame: str = ""  # the frame it was learned in (objects.py); "": the task object's

    def hyperparameters(self) -> dict[str, Any]:
        """Every hyperparameter of the run, by name (the gripper's where the
        demonstrations have gripper events)."""
        return {**get_params(self.preprocessing), **get_params(self.learner),
                **get_params(self.options), **_gripper_params(self)}


@dataclass
class VectorFieldResult:
    """Vector fields learned from demonstrations (:func:`~sctd.learn.learn_vector_fields`)."""

    preprocessing: Preprocessing
    options: SkillOptions
    field_options: VectorFieldOptions
    prepared: list[Prepared]
    learner: VectorFieldLearner
    labels: dict[str, list[int]]  # demo -> state index (0: one state) per raw displacement
    field_labels: dict[str, list[int]]  # demo -> field index (-1 outlier) per raw displacement
    timings: dict[str, float] = field(default_factory=dict)
    plan: StatePlan = field(default_factory=StatePlan)  # the fields as states, or why not
    gripper: GripperPlan | None = None  # the demonstrations' gripper events (gripper.py), if any
    gripper_options: GripperOptions = field(default_factory=GripperOptions)
    frame: str = ""  # the frame it was learned in (objects.py); "": the task object's
    turns: dict[int, TurnInPlace] = field(default_factory=dict)  # gripper phase -> its turn in place

    def hyperparameters(self) -> dict[str, Any]:
        """Every hyperparameter of the run, by name (the gripper's where the
        demonstrations have gripper events)."""
        return {**get_params(self.preprocessing), **get_params(self.learner),
                **get_params(self.options), **get_params(self.field_options), **_gripper_params(self)}


def _gripper_params(result: LinearResult | VectorFieldResult) -> dict[str, Any]:
    """The gripper's hyperparameters where they were used (else none: a run on
    demonstrations without gripper events reports what it always did)."""
    return {} if result.gripper is None else get_params(result.gripper_options)
