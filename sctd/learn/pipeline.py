"""Demonstrations -> learned results -> skill (Algorithms 1 and 4 end to end).

:func:`learn_linear` and :func:`learn_vector_fields` take the estimator and option
objects; :func:`learn` and :func:`learn_skill` take every hyperparameter as a keyword
argument by its field name (``smoothness=``, ``random_state=``, ``vf_max_n=``, ...),
which is what a notebook wants. Hyperparameter defaults are the thesis' (Ch. 5.2).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from .. import se3
from ..skill import Skill, skill_from_bundle
from .bundle import skill_bundle
from .demos import Demo
from .frames import automatic_frames, frames_to_use
from .gripper import GripperOptions, GripperPlan, plan_gripper
from .linear import Hyperplane, LinearIMLearner, Progress
from .objects import ObjectChoice, choose_objects, learning_frame, rebased, reframe_linear
from .params import HyperparameterError, check_params, param_problem
from .preprocess import Prepared, Preprocessing, preprocess, raw_labels
from .results import LinearResult, SkillOptions, VectorFieldOptions, VectorFieldResult
from .traps import TrapFinding, fix_traps
from .vf import VectorFieldLearner
from .vfstates import StatePlan, plan_states
from .vfturns import turns_in_place

METHODS = ("linear", "vf")
STAGES: dict[str, tuple[str, ...]] = {
    "linear": ("preprocess", "costs", "segmentation", "states", "transitions"),
    "vf": ("preprocess", "ransac", "em"),
}
"""The stage names a ``progress`` callback is called with, per method, in order."""

_PARTS: dict[str, tuple[type, ...]] = {
    "linear": (Preprocessing, LinearIMLearner, SkillOptions, GripperOptions),
    "vf": (Preprocessing, VectorFieldLearner, SkillOptions, VectorFieldOptions, GripperOptions),
}


def learn_linear(demos: list[Demo], frames: Mapping[str, ArrayLike] | None = None, *,
                 learner: LinearIMLearner | None = None,
                 preprocessing: Preprocessing | None = None, options: SkillOptions | None = None,
                 progress: Progress | None = None, gripper: GripperOptions | None = None) -> LinearResult:
    """Linear IMs (Ch. 4.1, Algorithm 1) from demonstrations.

    Parameters
    ----------
    demos : list of Demo
    frames : mapping of name -> pose [x, y, z, qx, qy, qz, qw] (T_ee_frame), optional
        Candidate feature frames besides ``ee``. Without them (and with the learner's
        ``auto_frames``), the frames the demonstrations turned about are found
        (:func:`~sctd.learn.frames.automatic_frames`) and used instead.
    learner : LinearIMLearner, optional
        The (unfitted) estimator with its hyperparameters; it is fitted in place.
    preprocessing : Preprocessing, optional
    options : SkillOptions, optional
    progress : callable(str), optional
        Called with each stage of ``STAGES["linear"]`` as it ends.
    gripper : GripperOptions, optional
        How the demonstrations' gripper events (if they have any) become states
        (:mod:`sctd.learn.gripper`).

    Raises
    ------
    sctd.learn.gripper.GripperError
        Demonstrations whose gripper events differ, or some with the gripper's columns and
        some without.
    sctd.learn.traps.TrapError
        A learned state traps the user (Ch. 6.2) and has no free input axis; one with a
        free axis gets the missing DoF (``result.traps`` says which).
    """
    learner = LinearIMLearner() if learner is None else learner
    preprocessing = Preprocessing() if preprocessing is None else preprocessing
    options = SkillOptions() if options is None else options
    gripper = GripperOptions() if gripper is None else gripper
    for part in (preprocessing, learner, options, gripper):
        check_params(part)  # before any work: a value out of range is named, not trained
    events = plan_gripper(demos, gripper)  # before any work too: mixed columns are refused
    demos, frame, events = _in_learning_frame(demos, options.object, gripper, events)
    t0 = time.perf_counter()
    found = []
    if not frames and learner.auto_frames:
        found = automatic_frames(demos, preprocessing, VectorFieldLearner(random_state=learner.random_state))
    pose_of = frames_to_use(frames, found)
    prepared = preprocess(demos, preprocessing, preprocessing.spacing, learner.alpha,
                          translation_only=False)
    if progress:
        progress("preprocess")
    t1 = time.perf_counter()
    T_obj_ee: list[ArrayLike] = [se3.transform_from_pose(p.poses) for p in prepared]
    learner.fit(T_obj_ee, {k: se3.transform_from_pose(v) for k, v in pose_of.items()},
                progress=progress)
    labels = {p.name: raw_labels(p, s) for p, s in zip(prepared, learner.state_labels_, strict=True)}
    choices, back, traps = _frames_and_traps(learner, demos, prepared, labels, T_obj_ee, frame,
                                             None if events is None else events.phases)
    timings = {"preprocess": t1 - t0, **learner.timings_, "total": time.perf_counter() - t0}
    return LinearResult(preprocessing, options, pose_of, prepared, learner, labels, timings, traps,
                        found_frames=found, gripper=events, gripper_options=gripper,
                        objects=choices, back=back, frame=frame)


def _in_learning_frame(demos: list[Demo], task_object: str, gripper: GripperOptions,
                       events: GripperPlan | None) -> tuple[list[Demo], str, GripperPlan | None]:
    """The demonstrations in the frame they are learned in (sctd.learn.objects: the task
    object's unless it moves with the hand in a gripper phase and another body never
    does), that frame's name and the gripper's events in it."""
    frame = learning_frame(demos, task_object, None if events is None else events.phases)
    if frame == task_object:
        return demos, frame, events
    demos = rebased(demos, frame, task_object)
    return demos, frame, plan_gripper(demos, gripper)


def _frames_and_traps(learner: LinearIMLearner, demos: list[Demo], prepared: list[Prepared],
                      labels: dict[str, list[int]], T_obj_ee: list[ArrayLike], task_object: str,
                      phases: dict[str, list[int]] | None
                      ) -> tuple[list[ObjectChoice], dict[int, Hyperplane], list[TrapFinding]]:
    """Each state's frame among the demonstrations' bodies and, where one is not the task
    object's, the states and transitions re-derived in their frames (sctd.learn.objects;
    without bodies nothing changes); then the traps (Ch. 6.2: a state that traps gets the
    missing DoF), each judged in its state's frame."""
    choices = choose_objects(demos, labels, len(learner.states_), task_object, phases=phases)
    objects = [c.object for c in choices]
    back: dict[int, Hyperplane] = {}
    in_frame_of = None
    if any(o != task_object for o in objects):
        back, per_state = reframe_linear(learner, prepared, demos, objects, task_object)
        in_frame_of = per_state.__getitem__
    return choices, back, fix_traps(learner, T_obj_ee, in_frame_of)


def learn_vector_fields(demos: list[Demo], *, learner: VectorFieldLearner | None = None,
                        preprocessing: Preprocessing | None = None,
                        options: SkillOptions | None = None,
                        field_options: VectorFieldOptions | None = None,
                        progress: Progress | None = None,
                        gripper: GripperOptions | None = None) -> VectorFieldResult:
    """Vector fields (Ch. 4.2, Algorithm 4) from demonstrations (ee positions).

    Parameters as :func:`learn_linear`; ``field_options`` are the vector-field skill's
    run-time parameters, and ``progress`` is called with ``STAGES["vf"]``.
    """
    learner = VectorFieldLearner() if learner is None else learner
    preprocessing = Preprocessing() if preprocessing is None else preprocessing
    options = SkillOptions() if options is None else options
    field_options = VectorFieldOptions() if field_options is None else field_options
    gripper = GripperOptions() if gripper is None else gripper
    for part in (preprocessing, learner, options, field_options, gripper):
        check_params(part)  # before any work: a value out of range is named, not trained
    events = plan_gripper(demos, gripper)
    demos, frame, events = _in_learning_frame(demos, options.object, gripper, events)
    t0 = time.perf_counter()
    prepared = preprocess(demos, preprocessing, preprocessing.vf_spacing, 0.0,
                          translation_only=True)
    if progress:
        progress("preprocess")
    t1 = time.perf_counter()
    learner.fit([p.poses[:, :3] for p in prepared], [p.poses[:, 3:] for p in prepared],
                progress=progress)
    plan = StatePlan(reason="--vf-states blend")
    if field_options.vf_states == "auto":
        plan = plan_states(learner)
    state_of = {m: k for k, m in enumerate(plan.order)}
    labels, field_labels = {}, {}
    for k, p in enumerate(prepared):
        sel = learner.demo_index_ == k
        per = np.full(max(1, len(p.keep) - 1), -1, dtype=np.int64)
        per[learner.sample_index_[sel]] = learner.assignment_[sel]
        field_labels[p.name] = raw_labels(p, per)
        labels[p.name] = _states_of(field_labels[p.name], state_of)
    turns = {} if events is None else turns_in_place(
        demos, events, options.max_linear_speed / options.max_angular_speed, preprocessing.vf_spacing)
    timings = {"preprocess": t1 - t0, **learner.timings_, "total": time.perf_counter() - t0}
    return VectorFieldResult(preprocessing, options, field_options, prepared, learner, labels, field_labels,
                             timings, plan, gripper=events, gripper_options=gripper, frame=frame, turns=turns)


def _states_of(fields: list[int], state_of: dict[int, int]) -> list[int]:
    """The state of each displacement from its field's (an outlier's: the state before it,
    or the first)."""
    out, last = [], 0
    for m in fields:
        last = state_of.get(m, last)
        out.append(last)
    return out


def hyperparameter_fields(method: str) -> list[dataclasses.Field]:
    """The dataclass fields that define ``method``'s hyperparameters (their metadata has
    the command line's help and flag), each name once."""
    out: list[dataclasses.Field] = []
    for part in _PARTS[_check_method(method)]:
        out += [f for f in dataclasses.fields(part) if f.init and f.name not in {g.name for g in out}]
    return out


def hyperparameter_names(method: str) -> list[str]:
    """The keyword arguments :func:`learn` accepts as hyperparameters for ``method``."""
    return [f.name for f in hyperparameter_fields(method)]


def _check_method(method: str) -> str:
    if method not in METHODS:
        raise ValueError(f"method must be linear or vf, got {method!r}")
    return method


def check_hyperparameters(method: str, hyperparameters: Mapping[str, Any]) -> None:
    """Each value one its field allows (:mod:`sctd.learn.params`).

    Raises
    ------
    TypeError
        A hyperparameter the method does not have.
    HyperparameterError
        A value out of its field's range or of the wrong type, naming the field.
    """
    fields = {f.name: f for f in hyperparameter_fields(method)}
    unknown = set(hyperparameters) - set(fields)
    if unknown:
        raise TypeError(f"unknown hyperparameter(s) for method {method!r}: "
                        f"{', '.join(sorted(map(str, unknown)))} (see sctd.learn.hyperparameter_names)")
    for name, value in hyperparameters.items():
        problem = param_problem(fields[name], value)
        if problem:
            raise HyperparameterError(name, problem)


def _parts(method: str, hyperparameters: dict[str, Any]) -> list[Any]:
    """One object per part of ``method``, each given the hyperparameters it has."""
    check_hyperparameters(method, hyperparameters)
    return [part(**{f.name: hyperparameters[f.name] for f in dataclasses.fields(part)
                    if f.init and f.name in hyperparameters})
            for part in _PARTS[method]]


def learn(demos: list[Demo], method: str = "linear", *,
          frames: Mapping[str, ArrayLike] | None = None, progress: Progress | None = None,
          **hyperparameters: Any) -> LinearResult | VectorFieldResult:
    """Learn from demonstrations by either method, every hyperparameter a keyword.

    Parameters
    ----------
    demos : list of Demo
        As :func:`read_demos` returns them.
    method : {"linear", "vf"}
        Linear input mappings (Ch. 4.1) or vector fields (Ch. 4.2).
    frames : mapping of name -> pose [7], optional
        Candidate feature frames (T_ee_frame) for linear IMs.
    progress : callable(str), optional
        Called with each stage of ``STAGES[method]`` as it ends.
    **hyperparameters
        By field name: :class:`Preprocessing`, the method's learner
        (:class:`LinearIMLearner` or :class:`VectorFieldLearner`), :class:`SkillOptions`
        and, for vector fields, :class:`VectorFieldOptions` (``hyperparameter_names``
        lists them). ``random_state`` seeds the learner.

    Raises
    ------
    TypeError
        A hyperparameter the method does not have, or frames for vector fields.
    """
    parts = _parts(_check_method(method), hyperparameters)
    if method == "linear":
        prep, lin, options, gripper = parts
        return learn_linear(demos, frames, learner=lin, preprocessing=prep, options=options,
                            progress=progress, gripper=gripper)
    if frames:
        raise TypeError("frames are candidate frames of linear IMs; vector fields find their own")
    prep, vf, options, field_options, gripper = parts
    return learn_vector_fields(demos, learner=vf, preprocessing=prep, options=options,
                               field_options=field_options, progress=progress, gripper=gripper)


def learn_skill(demos: list[Demo], method: str = "linear", *, name: str = "skill",
                frames: Mapping[str, ArrayLike] | None = None, progress: Progress | None = None,
                **hyperparameters: Any) -> Skill:
    """:func:`learn`, then the validated :class:`sctd.skill.Skill` (as the runtime would
    load it) named ``name``; nothing is written. Same parameters as :func:`learn`."""
    result = learn(demos, method, frames=frames, progress=progress, **hyperparameters)
    return skill_from_bundle(skill_bundle(result, name))
