"""Learned results -> skills -> skill bundles: the YAML text and model files, in memory.

The skill format is ``docs/skill-format.md``. :func:`linear_skill` and :func:`vf_skill`
build the learned :class:`sctd.skill.Skill` of a result from the skill's element
classes, with the learned numbers rounded as skill files store them;
:func:`skill_bundle` writes it (each element writes itself,
:func:`sctd.skill.bundle_from_skill`) under a comment header saying what was learned.
:func:`sctd.skill.skill_from_bundle` validates the bundle, and ``sctd learn`` writes
its files next to each other.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..skill import (
    Bundle,
    Distance,
    Field,
    Frame,
    Hyperplane,
    InputMapping,
    Limits,
    LinearMapping,
    NeighbourOrientation,
    Skill,
    State,
    Transition,
    VectorFieldMapping,
    VectorFieldModel,
    bundle_from_skill,
)
from ..skill.frames import builtin_frames
from ..skill.mappings import PIVOT_OFF
from ..skill.reader import Reader
from ..skill.region import Region
from ..skill.summary import field_summary
from .gripper import gripper_lines, with_gripper
from .linear import AXIS_NAMES
from .results import LinearResult, VectorFieldResult, speed_near_from_text
from .vfstates import entry_direction


def rounded(x: Any, nd: int = 6) -> Any:
    """Floats (also inside lists, tuples and arrays) rounded to ``nd`` digits, as the
    skill files store them; other values unchanged."""
    if isinstance(x, np.ndarray):
        return [rounded(v, nd) for v in x.tolist()]
    if isinstance(x, list | tuple):
        return [rounded(v, nd) for v in x]
    if isinstance(x, float | np.floating):
        return round(float(x), nd)
    return x


def state_name(k: int) -> str:
    """Name of the k-th learned state."""
    return f"s{k}"


def _limits(result: LinearResult | VectorFieldResult) -> Limits:
    o = result.options
    return Limits(max_linear_speed=o.max_linear_speed, max_angular_speed=o.max_angular_speed)


def _capped(states: tuple[State, ...], result: LinearResult | VectorFieldResult) -> tuple[State, ...]:
    """The states with the options' ``speed_near`` cap added last to each, if any."""
    text = result.options.speed_near
    if not text:
        return states
    cap = speed_near_from_text(text)
    return tuple(dataclasses.replace(s, active_constraints=(*s.active_constraints, cap)) for s in states)


def linear_skill(result: LinearResult, name: str) -> Skill:
    """The skill of a linear-IM result: a state per learned IM, a hyperplane transition
    each way per learned boundary; matrices, normals, offsets and frame poses rounded to
    6 digits.

    Raises
    ------
    sctd.skill.SkillError
        A frame's pose is not 7 finite numbers with a unit quaternion (checked as the
        loader checks it).
    """
    L = result.learner
    r = Reader(f"{name}.yaml", {})
    frames = builtin_frames() | {k: Frame(k, "ee", r.pose(rounded(v), f"frames.{k}.pose"))
                                 for k, v in result.frames.items()}
    task_object = result.options.object
    own = [c.object if c.object != task_object else None for c in result.objects] or [None] * len(L.states_)
    states = tuple(State(name=state_name(k), active_constraints=(), input_mappings=(
        LinearMapping(frame=st.label.frame, matrix=np.array(rounded(st.label.matrix))),), object=obj)
        for k, (st, obj) in enumerate(zip(L.states_, own, strict=True)))
    transitions: list[Transition] = []
    for h in L.transitions_:
        a, b = state_name(h.source), state_name(h.target)
        n, o = np.array(rounded(h.normal, 6)), round(float(h.offset), 6)
        transitions.append(Hyperplane(source=a, target=b, frame=h.frame, normal=n, offset=o,
                                      margin=h.margin))
        back = result.back.get(h.source)
        if back is not None:  # the way back is in the other state's frame: a plane of its own
            transitions.append(Hyperplane(source=b, target=a, frame=back.frame,
                                          normal=np.array(rounded(back.normal, 6)),
                                          offset=round(float(back.offset), 6), margin=back.margin))
            continue
        # The way back on the same plane: the margins leave a dead band between them.
        transitions.append(Hyperplane(source=b, target=a, frame=h.frame, normal=-n, offset=-o,
                                      margin=h.margin))
    return _gripped(result, Skill(
        name=name, object=result.options.object, frames=frames, states=_capped(states, result),
        transitions=tuple(transitions), start=state_name(0), end=state_name(len(L.states_) - 1),
        limits=_limits(result), min_dwell=0.1,
        description=(f"Learned by sctd learn --method linear from {len(result.prepared)} "
                     "demonstrations (linear IMs, alpha-beta swap, linear-SVM transitions).")))


def _gripped(result: LinearResult | VectorFieldResult, skill: Skill) -> Skill:
    """``skill`` with the region its demonstrations went through (:mod:`sctd.skill.region`)
    and split at the demonstrations' gripper events, each a state that commands the
    gripper (:mod:`sctd.learn.gripper`); a vector-field phase that turns in place
    (:mod:`sctd.learn.vfturns`) moves by its turn."""
    points = np.concatenate([p.poses[:, :3] for p in result.prepared])
    skill = dataclasses.replace(skill, region=Region.around(result.frame or result.options.object, points,
                                                            demonstrations=len(result.prepared)))
    if result.gripper is None:
        return skill
    moves = None
    if isinstance(result, VectorFieldResult) and result.turns:
        frames, moves = _turns(result, skill.name)
        skill = dataclasses.replace(skill, frames={**skill.frames, **frames})
    return with_gripper(skill, result.labels, result.gripper, result.gripper_options,
                        frame=result.frame or None, moves=moves)


def _turns(result: VectorFieldResult, name: str
           ) -> tuple[dict[str, Frame], dict[int, tuple[InputMapping, ...]]]:
    """Per phase that turns in place: its lever frame (``lever<phase>``, an ee offset)
    and the vector-field mapping that turns the hand about its origin by the lever point's
    cylinder field (model file ``name-turn<phase>.npz``), rigid and scaled part by part as
    a state of one field is."""
    p = result.field_options
    frames: dict[str, Frame] = {}
    moves: dict[int, tuple[InputMapping, ...]] = {}
    for phase, turn in sorted(result.turns.items()):
        frame = f"lever{phase}"
        frames[frame] = Frame(frame, "ee", np.array([*turn.lever, 0.0, 0.0, 0.0, 1.0]))
        model = turn.model()
        model = dataclasses.replace(model, fields=tuple(_stored(f) for f in model.fields))
        moves[phase] = (VectorFieldMapping(model_file=f"{name}-turn{phase}.npz", model=model, frame=frame,
                                           mode="scale", combine=p.vf_combine,  # type: ignore[arg-type]
                                           min_v=p.min_v, k_s=p.k_s, max_n=p.vf_max_n, max_d=p.max_d,
                                           motion="rigid", direction=p.vf_direction,  # type: ignore[arg-type]
                                           scale_by="parts"),)
    return frames, moves


def _gripper_header(result: LinearResult | VectorFieldResult, skill: Skill) -> str:
    if result.gripper is None:
        return ""
    return "\n".join(["", "Gripper (the demonstrations' events, states renamed in order):",
                      *(f"  {line}" for line in gripper_lines(result.gripper, skill))])


def _objects_header(result: LinearResult | VectorFieldResult) -> str:
    """Where the demonstrations carry other bodies: the frame learned in where it is not
    the task object's, and each linear state's frame and why (nothing without them)."""
    lines = []
    if result.frame and result.frame != result.options.object:
        lines += ["", f"Learned in the frame of {result.frame}: {result.options.object} moves with the "
                      "hand in a gripper phase (docs/learning.md, \"Other bodies\")."]
    if isinstance(result, LinearResult) and any(c.spread for c in result.objects):
        lines += ["", "Frames (each state's, among the demonstrations' bodies):",
                  *(f"  {c.line(state_name(c.state))}" for c in result.objects)]
    return "\n".join(lines)


def _linear_header(result: LinearResult) -> str:
    lines = ["Learned skill (sctd learn --method linear). States:"]
    for f in result.found_frames:
        lines.insert(0, f"Frame {f.name} found in the demonstrations: {f.kind}, ee offset "
                        f"{rounded(f.pose[:3], 4)}, spread {f.spread:.4f} m")
    for k, st in enumerate(result.learner.states_):
        axes = ", ".join(AXIS_NAMES[a] for a in st.label.axes)
        lines.append(f"  {state_name(k)}: {axes} in frame {st.label.frame}")
    for h in result.learner.transitions_:
        lines.append(f"  {state_name(h.source)} -> {state_name(h.target)}: hyperplane on "
                     f"{h.frame}, training accuracy {h.accuracy:.3f}, "
                     f"{'reachable' if h.reachable else 'NOT reachable by the IM'}")
    lines += [f"  {line}" for line in trap_lines(result)]
    return "\n".join(lines)


def trap_lines(result: LinearResult) -> list[str]:
    """One line per trap the check fixed and per transition without a way back by
    motion (sctd.learn.traps), for the skill's header and ``sctd learn``'s output."""
    out = []
    for f in result.traps:
        a, b = state_name(f.state), state_name(f.target)
        if f.added is not None:
            out.append(f"{a} trapped the user (reach {f.reach:.2f} of the plane to {b}): "
                       f"added {f.added}")
        if not f.way_back:
            out.append(f"{b} -> {a}: no way back by motion from where {b} is entered "
                       "(escape, button 2, returns)")
    return out


def vf_model(result: VectorFieldResult, fields: tuple[int, ...] | None = None) -> VectorFieldModel:
    """The model file's content: the fields (all, or those indexed by ``fields``; their
    arrays rounded to 12 decimals, as model files store them) and the demonstration
    points (those the chosen fields explain)."""
    L = result.learner
    if not L.fields_:
        raise ValueError("no vector field was found in the demonstrations")
    within = result.field_options.vf_pivot_within or None
    chosen = [_stored(f, within) for f in (L.fields_ if fields is None else [L.fields_[m] for m in fields])]
    if fields is None:
        return VectorFieldModel(fields=tuple(chosen), points=L.points_,
                                quaternions=L.quaternions_, responsibilities=L.responsibilities_)
    sel = np.isin(L.assignment_, fields)
    R = L.responsibilities_[sel][:, list(fields)]
    s = R.sum(axis=1, keepdims=True)
    R = np.where(s > 1e-12, R / np.maximum(s, 1e-12), 1.0 / len(fields))
    return VectorFieldModel(fields=tuple(chosen), points=L.points_[sel],
                            quaternions=L.quaternions_[sel], responsibilities=R)


def _stored(f: Field, pivot_within: float | None = None) -> Field:
    """The field with its arrays rounded to 12 decimals (a general field renormalises its
    directions) and, if it has a ``pivot``, ``pivot_within`` (None: not written, the
    runtime's default)."""
    arrays: dict[str, Any] = {d.name: np.round(v, 12) for d in dataclasses.fields(f)
                              if isinstance(v := getattr(f, d.name), np.ndarray)}
    if f.pivot is not None and pivot_within is not None:
        arrays["pivot_within"] = pivot_within
    return dataclasses.replace(f, **arrays)


def _vf_state(result: VectorFieldResult, name: str, rel: str, model: VectorFieldModel,
              fields: list[Field], m: int | None = None) -> State:
    """One state of a vector-field skill: a vector-field IM and a neighbour-orientation AC
    on ``model``, the model file ``rel`` (fitted as ``fields``). A state of one field
    scales each part of a push by its own agreement (``scale_by: parts``): the part across
    its field is off every field the state has; a state that blends fields scales the
    whole push (the thesis), since a part across one field may be along another. A state
    of one field ``m`` of a sequence that turns the hand about a pivot of its own turns
    the stick's axes with the hand (``command_turns_from``: the pivot's direction where
    the demonstrations entered the state)."""
    p = result.field_options
    pivot = None
    pivots = [f for f in fields if f.pivot is not None]
    if pivots and p.vf_motion == "rigid":  # orientation pulled about the point the hand turned about
        pivot = np.array(rounded(max(pivots, key=lambda f: f.weight).pivot))
    turns = None
    if m is not None and len(fields) == 1 and pivot is not None and np.linalg.norm(pivot) >= PIVOT_OFF:
        d = entry_direction(result.learner, result.plan.order, m, pivot / np.linalg.norm(pivot))
        turns = None if d is None else tuple(rounded(d, 6))
    mapping = VectorFieldMapping(model_file=rel, model=model, frame="ee", mode="scale",
                                 combine=p.vf_combine, min_v=p.min_v, k_s=p.k_s,  # type: ignore[arg-type]
                                 max_n=p.vf_max_n, max_d=p.max_d, motion=p.vf_motion,  # type: ignore[arg-type]
                                 direction=p.vf_direction,  # type: ignore[arg-type]
                                 scale_by="parts" if len(fields) == 1 else "whole",
                                 command_turns_from=turns,
                                 arrive=p.vf_arrive if pivot is not None and p.vf_motion == "rigid" else 0.0)
    constraint = NeighbourOrientation(model_file=rel, model=model, frame="ee", max_n=p.vf_max_n,
                                      max_d=p.max_d, rotation_weight=p.vf_rotation_weight, pivot=pivot,
                                      yields_to_turn=pivot is not None)
    return State(name=name, input_mappings=(mapping,), active_constraints=(constraint,))


def vf_skill(result: VectorFieldResult, name: str) -> Skill:
    """The skill of a vector-field result. Blended (the thesis): one state ``default``
    with a vector-field IM and a neighbour-orientation AC on the model file
    ``name.npz``. Sequential (``result.plan``): one state per field, in the order the
    demonstrations use them, each on its own model file (:func:`state_model_files`),
    with a distance transition from each to the next where the demonstrations switched.

    Raises
    ------
    ValueError
        A result without any field.
    """
    L, plan = result.learner, result.plan
    rel = f"{name}.npz"
    description = (f"Learned by sctd learn --method vf from {len(result.prepared)} "
                   "demonstrations (RANSAC + EM vector fields, neighbour orientation"
                   + (", one state per field in the order they are used)." if plan.sequential
                      else ")."))
    if not plan.sequential:
        names = ["default"]
        states: tuple[State, ...] = (_vf_state(result, "default", rel, vf_model(result), list(L.fields_)),)
        transitions: tuple[Transition, ...] = ()
        min_dwell = Skill.min_dwell  # what a file without it gives
    else:
        names = [state_name(k) for k in range(len(plan.order))]
        states = tuple(_vf_state(result, nm, f, vf_model(result, (m,)), [L.fields_[m]], m) for nm, f, m
                       in zip(names, state_model_files(result, rel), plan.order, strict=True))
        transitions = tuple(  # on when the hand is where the demonstrations switched
            Distance(source=names[plan.order.index(h.source)], target=names[plan.order.index(h.target)],
                     frame="ee", point=np.array(rounded(h.point)), threshold=round(h.radius, 6),
                     direction="below", margin=0.0)
            for h in plan.transitions)
        min_dwell = 0.1
    if result.frame and result.frame != result.options.object:  # learned in another body's frame
        states = tuple(dataclasses.replace(s, object=result.frame) for s in states)
    return _gripped(result, Skill(name=name, object=result.options.object, frames=builtin_frames(),
                                  states=_capped(states, result),
                                  transitions=transitions, start=names[0], end=names[-1],
                                  limits=_limits(result), min_dwell=min_dwell, description=description,
                                  candidate_frames=tuple(L.candidate_frames_)))


def state_model_files(result: VectorFieldResult, model: str) -> list[str]:
    """The model file of each state of a sequential vector-field skill: ``model`` with
    the state's name before its suffix (``pour-vf.npz`` -> ``pour-vf-s0.npz``)."""
    stem, dot, ext = model.rpartition(".")
    return [f"{stem}-{state_name(k)}{dot}{ext}" for k in range(len(result.plan.order))]


def _vf_header(result: VectorFieldResult) -> str:
    lines = ["Learned skill (sctd learn --method vf). Fields:"]
    plan = result.plan
    for m, f in enumerate(result.learner.fields_):
        s = field_summary(f)
        state = f"{state_name(plan.order.index(m))}: " if m in plan.order else ""
        lines.append("  " + state + ", ".join(f"{k}={rounded(v, 4)}" for k, v in s.items()))
    if plan.sequential:
        for h in plan.transitions:
            lines.append(f"  {state_name(plan.order.index(h.source))} -> "
                         f"{state_name(plan.order.index(h.target))}: the hand within "
                         f"{h.radius * 100:.1f} cm of {rounded(h.point, 3)}, where the "
                         f"demonstrations switched ({h.spread * 100:.1f} cm RMS apart); escape "
                         "(button 2) goes back")
    else:
        lines.append(f"  one state blends the fields ({plan.reason})")
    for phase, t in sorted(result.turns.items()):
        degrees = np.degrees(t.angles)
        lines.append(f"  turn in place (gripper phase {phase}): about {rounded(t.axis, 3)} through "
                     f"{rounded(t.centre, 3)}, {degrees.min():.0f}-{degrees.max():.0f} deg in the "
                     f"demonstrations, the origin within {t.spread * 100:.1f} cm; pushed at the lever "
                     f"point {rounded(t.lever, 3)} of the hand (frame lever{phase})")
    return "\n".join(lines)


def skill_bundle(result: LinearResult | VectorFieldResult, name: str) -> Bundle:
    """The learned skill as a bundle: ``name.yaml`` (a comment header summarising what
    was learned, then the document) and, for vector fields, the model ``name.npz`` (one
    per state, ``name-s0.npz``, ..., for sequential fields).

    Raises
    ------
    ValueError
        A vector-field result without any field.
    """
    if isinstance(result, LinearResult):
        skill = linear_skill(result, name)
        return bundle_from_skill(skill, _linear_header(result) + _objects_header(result)
                                 + _gripper_header(result, skill))
    skill = vf_skill(result, name)
    return bundle_from_skill(skill, _vf_header(result) + _objects_header(result)
                             + _gripper_header(result, skill))
