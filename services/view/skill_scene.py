"""A skill as a scene: what each state does, drawn where the hand is when it is active.

What a person debugging a skill needs to see of it, as plain data in the task object's
frame (:class:`SkillScene`), for a view to put on screen (:mod:`.draw`):

- per state, a **pose of the hand** where the state is shown: from the demonstrations
  the skill's own FSM puts in that state (the sample nearest their mean), else from the
  points a vector-field model was fitted on, else the previous state's;
- what **each input axis** does there (:func:`axis_effects`): the mapping's own
  ``apply`` pushed one axis at full deflection, so the arrows are what the daemon would
  do, for every kind of mapping;
- each element's shapes (a constraint's, a transition's, a field's ``sketch``), and a
  vector field's directions on a grid near the points it explains;
- the **demonstrations**, each sample labelled with the state the skill's FSM is in
  there (:func:`demo_states`: the runtime's engine run along the demonstration, so the
  colours are where the daemon would switch, which is where the learner's transitions
  put the switches).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sctd import se3
from sctd.learn.demos import Demo, spike_mask
from sctd.skill import Distance, InputMapping, Skill, SkillEngine, SphereField, Workspace
from sctd.skill.sketch import Shape, direction_words

Array = NDArray[np.float64]

PUSH_DT = 0.01  # s: the step an axis is pushed for to see what it does (at full deflection)
GRID_SPACING = 0.02  # m between a field's arrows (at least; fewer over a large region)
GRID_MAX = 7  # arrows per axis of a field's grid at most
GRID_NEAR = 0.04  # m: a field's arrows are drawn this near the points it explains
FALLBACK_HAND = (0.0, 0.0, 0.15)  # m: the hand over the object when nothing says where


@dataclass(frozen=True)
class AxisEffect:
    """What pushing input axis ``axis`` (0-based) fully does at a pose: the mapping
    frame's origin moves at ``velocity`` (3,; m/s) and turns at ``turn`` (3,; rad/s),
    both in the object's axes."""

    axis: int
    frame: str
    origin: Array
    velocity: Array
    turn: Array

    def words(self, obj: str) -> str:
        """``axis 1: along mug +z at 0.10 m/s, turns about mug +y at 0.50 rad/s``."""
        parts = []
        v, w = float(np.linalg.norm(self.velocity)), float(np.linalg.norm(self.turn))
        if v > 1e-4:
            parts.append(f"moves {self.frame} along {obj} {direction_words(self.velocity)} at {v:.2f} m/s")
        if w > 1e-3:
            parts.append(f"turns about {obj} {direction_words(self.turn)} at {w:.2f} rad/s")
        return f"axis {self.axis + 1}: " + (", ".join(parts) if parts else "nothing here")


@dataclass
class FieldArrows:
    """A vector field's directions (n, 3 each) at grid points (n, 3) near the points it
    explains; ``index`` its place in the model's fields."""

    label: str
    index: int
    points: Array
    vectors: Array


@dataclass
class StateScene:
    """One state as drawn: the hand's pose ``T_obj_ee`` (4, 4) where it is shown, what
    each axis does there, the elements' shapes by role (``mapping``, ``constraint``,
    ``transition``, ``field``), the fields' arrows and a description in lines."""

    name: str
    T_obj_ee: Array
    effects: list[AxisEffect] = field(default_factory=list)
    shapes: list[tuple[str, Shape]] = field(default_factory=list)
    arrows: list[FieldArrows] = field(default_factory=list)
    text: list[str] = field(default_factory=list)


@dataclass
class DemoPath:
    """A demonstration in the object frame: its frame positions (n, 3) and the index of
    the state the skill's FSM is in at each sample (n,), without the isolated gross
    outliers the learner drops (:func:`~sctd.learn.demos.spike_mask`), which are in
    ``spikes`` (m, 3)."""

    name: str
    points: Array
    states: NDArray[np.int64]
    spikes: Array = field(default_factory=lambda: np.zeros((0, 3)))


@dataclass
class SkillScene:
    skill: Skill
    states: list[StateScene]
    demos: list[DemoPath]


def skill_scene(skill: Skill, demos: list[Demo] | None = None) -> SkillScene:
    """The scene of ``skill``, with ``demos`` (object frame) when given."""
    ws = workspace(skill)
    kept = [spike_mask(d.poses) for d in demos or []]
    clean = [Demo(d.name, d.t[k], d.poses[k]) for d, k in zip(demos or [], kept, strict=True)]
    labelled = [(d, demo_states(skill, d)) for d in clean]
    paths = [DemoPath(d.name, d.poses[:, :3].copy(), s, raw.poses[~k, :3].copy())
             for (d, s), raw, k in zip(labelled, demos or [], kept, strict=True)]
    states: list[StateScene] = []
    for i in range(len(skill.states)):
        T = _hand_pose(skill, i, labelled, states[-1].T_obj_ee if states else None)
        states.append(state_scene(skill, i, T, ws))
    return SkillScene(skill, states, paths)


def workspace(skill: Skill) -> Workspace:
    """A workspace of ``skill`` for drawing it (its own: not the runtime's)."""
    return Workspace(skill.limits.speeds, skill.frames, skill.models())


def state_scene(skill: Skill, i: int, T_obj_ee: Array, ws: Workspace) -> StateScene:
    """State ``i`` of ``skill`` drawn with the hand at ``T_obj_ee`` (4, 4; object frame):
    what each axis does there, where the constraints are, the guards out of it."""
    state = skill.states[i]
    scene = StateScene(state.name, T_obj_ee)
    F = se3.flat_from_transform(T_obj_ee)
    for m in state.input_mappings:
        _add_mapping(scene, m, F, ws, skill.object)
    for c in state.active_constraints:
        shapes = c.sketch(ws.frame_pose(F, c.frame))
        scene.shapes += [("constraint", s) for s in shapes]
        scene.text += [f"{c.type}: {s.label}" for s in shapes[:1]] or [f"{c.type} on {c.frame}"]
    for t in skill.transitions:
        if t.source == state.name:
            shapes = t.sketch()
            scene.shapes += [("transition", s) for s in shapes]
            scene.text.append(f"{shapes[0].label}" if shapes else f"{t.source} -> {t.target}: {t.type} "
                              + ", ".join(f"{k} {v}" for k, v in t.summary().items()
                                          if k not in ("from", "to", "type")))
    return scene


def holding(skill: Skill, i: int, T_obj_ee: Array, ws: Workspace) -> list[str]:
    """The constraints of state ``i`` that hold the hand at ``T_obj_ee`` (object frame):
    the bounding ones (``bounds``) whose projection moves it (by more than 0.1 mm or 1
    mrad: the hand is on or past the limit), each as its sketch's label (or its kind).
    (What the view infers from where the hand is, when the runtime's status does not
    say which constraints acted: a log of an older daemon.)"""
    F = se3.flat_from_transform(T_obj_ee)
    labels = constraint_labels(skill, i, T_obj_ee, ws)
    out = []
    for c, label in zip(skill.states[i].active_constraints, labels, strict=True):
        if not c.bounds:
            continue
        P = c.project(F, ws.frame_pose(F, c.frame), ws)
        d = np.asarray(P) - np.asarray(F)
        if P is not F and (np.max(np.abs(d[9:])) > 1e-4 or np.max(np.abs(d[:9])) > 1e-3):
            out.append(label)
    return out


def constraint_labels(skill: Skill, i: int, T_obj_ee: Array, ws: Workspace) -> list[str]:
    """Each active constraint of state ``i`` in words (its sketch's label at the hand
    ``T_obj_ee``, object frame, or its kind), in the skill file's order."""
    F = se3.flat_from_transform(T_obj_ee)
    out = []
    for c in skill.states[i].active_constraints:
        shapes = c.sketch(ws.frame_pose(F, c.frame))
        out.append(shapes[0].label if shapes else c.type)
    return out


def _add_mapping(scene: StateScene, m: InputMapping, F: se3.Flat, ws: Workspace, obj: str) -> None:
    effects = axis_effects(m, F, ws)
    scene.effects += effects
    scene.text += [e.words(obj) for e in effects]
    for _, model in m.models():
        owner = np.argmax(model.responsibilities, axis=1) if len(model.points) else np.zeros(0, int)
        for k, f in enumerate(model.fields):
            mine = model.points[owner == k]
            scene.shapes += [("field", s) for s in f.sketch(mine)]
            if not isinstance(f, SphereField):  # a sphere's vectors are its normals: no way to go
                scene.arrows.append(field_arrows(f"field {k + 1}: {f.type}", k, f, mine))


def axis_effects(m: InputMapping, F: se3.Flat, ws: Workspace) -> list[AxisEffect]:
    """What each input axis the mapping reads does at the ee pose F (object frame):
    the mapping's ``apply`` of a full push of that axis alone over :data:`PUSH_DT`."""
    G = ws.frame_pose(F, m.frame)
    R = np.asarray(G[:9]).reshape(3, 3)
    out = []
    for j in sorted(m.input_axes()):
        u = [0.0] * (j + 1)
        u[j] = 1.0
        G2 = ws.frame_pose(m.apply(F, u, PUSH_DT, ws), m.frame)
        v = (np.asarray(G2[9:]) - np.asarray(G[9:])) / PUSH_DT
        w = se3.rotvec_from_matrix(np.asarray(G2[:9]).reshape(3, 3) @ R.T) / PUSH_DT
        out.append(AxisEffect(j, m.frame, np.asarray(G[9:]), v, w))
    return out


def field_arrows(label: str, index: int, f, points: Array) -> FieldArrows:
    """The field ``f``'s unit directions on a grid over ``points`` (n, 3; the ones it
    explains), at most :data:`GRID_NEAR` from one of them."""
    if not len(points):
        return FieldArrows(label, index, np.zeros((0, 3)), np.zeros((0, 3)))
    lo, hi = points.min(axis=0) - GRID_NEAR / 2, points.max(axis=0) + GRID_NEAR / 2
    axes = [np.linspace(a, b, max(2, min(GRID_MAX, int((b - a) / GRID_SPACING) + 1)))
            for a, b in zip(lo, hi, strict=True)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    near = np.min(np.linalg.norm(grid[:, None, :] - points[None, ::max(1, len(points) // 200), :], axis=2),
                  axis=1) < GRID_NEAR
    grid = grid[near]
    vectors = f.vectors(grid) if len(grid) else np.zeros((0, 3))
    keep = np.linalg.norm(vectors, axis=1) > 0.5
    return FieldArrows(label, index, grid[keep], vectors[keep])


def demo_states(skill: Skill, demo: Demo) -> NDArray[np.int64]:
    """The index of the state ``skill``'s FSM is in at each sample of ``demo`` (object
    frame): the runtime's engine, started in the start state, updated with each pose at
    the sample's time (its dwell and hysteresis as in the daemon)."""
    engine = SkillEngine(skill)
    engine.reset(float(demo.t[0]))
    out = np.empty(len(demo), dtype=np.int64)
    for k, (t, pose) in enumerate(zip(demo.t, demo.poses, strict=True)):
        engine.update(se3.flat_from_pose(pose.tolist()), float(t))
        out[k] = engine.index
    return out


def _hand_pose(skill: Skill, i: int, labelled: list[tuple[Demo, NDArray[np.int64]]],
               before: Array | None) -> Array:
    """Where the hand is shown in state ``i``: the demonstration sample in that state
    nearest the mean of all such samples; else a vector-field model's point nearest
    its points' mean (the mapping frame's pose, taken back to the ee); else ``before``
    the point of a distance guard that leads into it (upright); else ``before`` (the
    previous state's), else :data:`FALLBACK_HAND` upright."""
    poses = [d.poses[s == i] for d, s in labelled]
    samples = np.concatenate(poses) if poses else np.zeros((0, 7))
    if len(samples):
        mean = samples[:, :3].mean(axis=0)
        return se3.transform_from_pose(samples[np.argmin(np.linalg.norm(samples[:, :3] - mean, axis=1))])
    for m in skill.states[i].input_mappings:
        for _, model in m.models():
            if len(model.points):
                k = int(np.argmin(np.linalg.norm(model.points - model.points.mean(axis=0), axis=1)))
                T_obj_frame = se3.transform_from_pose(np.concatenate([model.points[k], model.quaternions[k]]))
                return T_obj_frame @ se3.invert_transform(skill.frames[m.frame].T_parent_frame) \
                    if m.frame in skill.frames and skill.frames[m.frame].parent == "ee" else T_obj_frame
    for t in skill.transitions:  # where a distance guard brings the hand into it
        if t.target == skill.states[i].name and isinstance(t, Distance) and t.direction == "below":
            T_ee_frame = skill.frames[t.frame].T_parent_frame if skill.frames[t.frame].parent == "ee" \
                else np.eye(4)
            return se3.transform_from_pose([*t.point, 0.0, 0.0, 0.0, 1.0]) @ se3.invert_transform(T_ee_frame)
    if before is not None:
        return before
    return se3.transform_from_pose([*FALLBACK_HAND, 0.0, 0.0, 0.0, 1.0])

