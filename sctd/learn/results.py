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

from .frames import FoundFrame
from .linear import LinearIMLearner
from .params import Interval, OneOf, Text, get_params, hyperparameter
from .preprocess import Prepared, Preprocessing
from .traps import TrapFinding
from .vf import VectorFieldLearner
from .vfstates import StatePlan

Array = NDArray[np.float64]

VF_COMBINE = ("intent", "weighted", "most_probable")
VF_STATES = ("auto", "blend")
VF_MOTION = ("rigid", "translate")


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
    """

    object: str = hyperparameter("object", "task object name (the skill frame)", valid=Text())
    max_linear_speed: float = hyperparameter(0.10, "m/s at full input (default %(default)s)",
                                             valid=Interval(0, 1, open="low"))
    max_angular_speed: float = hyperparameter(0.50, "rad/s at full input (default %(default)s)",
                                              valid=Interval(0, 3, open="low"))


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
    vf_states : {"auto", "blend"}
        Sequential fields become states (:func:`~sctd.learn.vfstates.plan_states`) or
        all blend in one state (the thesis).
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
    vf_states: str = hyperparameter(
        "blend", "auto: fields the demonstrations use one after the other, in separate places, "
        "become states with hyperplane transitions between them; blend: one state blends all "
        "fields, as in the thesis (default %(default)s)", choices=VF_STATES, valid=OneOf(VF_STATES))


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

    def hyperparameters(self) -> dict[str, Any]:
        """Every hyperparameter of the run, by name."""
        return {**get_params(self.preprocessing), **get_params(self.learner),
                **get_params(self.options)}


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

    def hyperparameters(self) -> dict[str, Any]:
        """Every hyperparameter of the run, by name."""
        return {**get_params(self.preprocessing), **get_params(self.learner),
                **get_params(self.options), **get_params(self.field_options)}
