"""Skill loading, validation errors, and the engine's mappings, constraints and FSM."""

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from sctd import se3
from sctd.skill import (
    Bundle,
    CylinderField,
    SkillEngine,
    SkillError,
    SphereField,
    TranslationField,
    VectorFieldModel,
    bundle_from_file,
    load_skill,
    skill_from_bundle,
    skill_summary,
    vector_field_model_to_bytes,
)
from sctd.skill.fields import Field, sigmoid

ROOT = Path(__file__).resolve().parents[1]
POUR = ROOT / "skills" / "pour.yaml"


def skill_text(**overrides) -> str:
    doc = yaml.safe_load(POUR.read_text())
    for path, value in overrides.items():
        node = doc
        keys = path.split("__")
        for k in keys[:-1]:
            node = node[int(k)] if isinstance(node, list) else node[k]
        last = keys[-1]
        if isinstance(node, list):
            node[int(last)] = value
        elif value is ...:
            del node[last]
        else:
            node[last] = value
    return yaml.safe_dump(doc)


def load_text(text: str, files=None):
    return skill_from_bundle(Bundle("t.yaml", text, files or {}))


def test_shipped_skills_load():
    for name in ("pour.yaml", "drawer.yaml"):
        s = load_skill(ROOT / "skills" / name)
        assert s.id == bundle_from_file(ROOT / "skills" / name).id
        assert s.start in [x.name for x in s.states]


def test_bundle_round_trip_keeps_id():
    b = bundle_from_file(POUR)
    b2 = Bundle.unpack(b.pack())
    assert b2.id == b.id and skill_from_bundle(b2).id == b.id


@pytest.mark.parametrize(
    "overrides, where, what",
    [
        ({"sctd_skill": 2}, "sctd_skill", "format version"),
        ({"object": ...}, "object", "non-empty string"),
        ({"states__carry__input_mapping__0__axes": ["tx", "tq", "tz"]}, "input_mapping[0].axes[1]", "tq"),
        ({"states__carry__input_mapping__0__frame": "nose"}, "input_mapping[0].frame", "unknown frame"),
        ({"fsm__start": "nowhere"}, "fsm.start", "expected one of"),
        ({"frames__tip__pose": [0, 0, 0.1, 0, 0, 0, 2]}, "frames.tip.pose", "unit"),
        ({"states__carry__active_constraints__1__upper": 0.0}, "active_constraints[1].upper", ">= lower"),
        ({"fsm__transitions__0__below": float("nan")}, "transitions[0].below", "finite"),
        ({"limits__max_linear_speed": 5.0}, "limits.max_linear_speed", "<= 1.0"),
        ({"states__carry__colour": "red"}, "states.carry.colour", "unknown field"),
        ({"colour": "red"}, "t.yaml: colour: ", "unknown field"),
    ],
)
def test_validation_names_file_field_and_problem(overrides, where, what):
    with pytest.raises(SkillError) as e:
        load_text(skill_text(**overrides))
    msg = str(e.value)
    assert msg.startswith("t.yaml: ") and where in msg and what in msg, msg


def test_unreachable_state_is_refused():
    doc = yaml.safe_load(POUR.read_text())
    doc["fsm"]["transitions"] = [t for t in doc["fsm"]["transitions"] if t["to"] != "pour"]
    with pytest.raises(SkillError, match="not reachable"):
        load_text(yaml.safe_dump(doc))


def test_invalid_yaml_names_line():
    with pytest.raises(SkillError, match=r"t.yaml: line \d+: invalid YAML"):
        load_text("sctd_skill: 1\nstates: [\n")


def test_missing_and_escaping_model_files(tmp_path):
    doc = vf_skill_doc()
    with pytest.raises(SkillError, match="missing"):
        load_text(yaml.safe_dump(doc))
    doc["states"]["go"]["input_mapping"][0]["model"] = "../evil.json"
    with pytest.raises(SkillError, match="relative"):
        load_text(yaml.safe_dump(doc))


def test_pickled_npz_is_refused():
    import io
    buf = io.BytesIO()
    np.savez(buf, fields=np.array([{"type": "sphere"}], dtype=object), points=np.zeros((1, 3)))
    with pytest.raises(SkillError, match="pickle-free"):
        load_text(yaml.safe_dump(vf_skill_doc("m.npz")), {"m.npz": buf.getvalue()})


# --- engine: linear mappings ----------------------------------------------------------


def command(eng: SkillEngine, T, u, dt):
    """The engine's command on a 4x4 pose (the tick's Flat pose in and out)."""
    return se3.transform_from_flat(eng.command(se3.flat_from_transform(T), u, dt))


def project(eng: SkillEngine, T, c):
    """The engine's projection onto constraint c, on a 4x4 pose."""
    return se3.transform_from_flat(eng.project(se3.flat_from_transform(T), c))


def violation(eng: SkillEngine, T, c) -> float:
    """How far pose T is outside constraint c (m or rad; 0 when satisfied), written out
    plainly in numpy as the reference for the tick's float-level checks."""
    T_f = T @ eng.skill.frames[c.frame].T_parent_frame
    if c.type == "band":
        s = float(np.dot(c.normal, T_f[:3, 3] - c.point))
        return max(0.0, c.lower - s, s - c.upper)
    if c.type == "box":
        p = T_f[:3, 3]
        return float(np.linalg.norm(p - np.clip(p, c.lower, c.upper)))
    assert c.type == "tilt_cone"
    a = T_f[:3, :3] @ c.axis
    return max(0.0, math.acos(max(-1.0, min(1.0, float(np.dot(a, c.reference))))) - c.max_angle)


def engine_for(doc) -> SkillEngine:
    return SkillEngine(load_text(yaml.safe_dump(doc)))


def one_state(mapping, constraints=(), frames=None, limits=None):
    return {
        "sctd_skill": 1, "name": "t", "object": "obj",
        "limits": limits or {"max_linear_speed": 0.1, "max_angular_speed": 0.5},
        "frames": frames or {"tip": {"parent": "ee", "pose": [0, 0, 0.12, 0, 0, 0, 1]}},
        "fsm": {"start": "s", "end": "s", "transitions": []},
        "states": {"s": {"input_mapping": [mapping], "active_constraints": list(constraints)}},
    }


@given(st.lists(st.floats(-1, 1), min_size=3, max_size=3),
       st.sampled_from([["tx", "ty", "tz"], ["rx", "ry", "rz"], ["tx", "ry", "rz"], ["ty", "tz", "rx"]]),
       st.sampled_from(["ee", "tip"]))
@settings(max_examples=60, deadline=None)
def test_linear_mapping_reproduces_identified_displacement(u, axes, frame):
    """Applying an IM is the displacement M u of its frame (the round trip of docs/skill-format.md), and
    the least-squares command recovers u from that displacement (eq. 4.6)."""
    eng = engine_for(one_state({"type": "linear", "frame": frame, "axes": axes}))
    T = se3.transform_from_pose([0.1, -0.2, 0.3, *se3.quaternion_from_rotvec([0.3, -0.2, 0.5])])
    dt = 0.01
    T2 = command(eng, T, np.array(u), dt)
    T_ee_f = eng.skill.frames[frame].T_parent_frame
    d6 = se3.displacement_from_transforms(T @ T_ee_f, T2 @ T_ee_f)
    M = eng.skill.states[0].input_mappings[0].matrix * np.array([0.1] * 3 + [0.5] * 3)[:, None] * dt
    assert np.allclose(d6, M @ u, atol=1e-12)
    assert np.allclose(np.linalg.pinv(M) @ d6, u, atol=1e-9)



def reference_linear(T, T_f, M, u, dt, in_frame):
    """Algorithm 2 written out plainly: rotate by r about the frame's origin and axes
    (R_w = R_f Rot(r) R_f^T), then translate by d in the object's or the frame's axes."""
    d6 = M @ u * dt
    R_f, p_f = T_f[:3, :3], T_f[:3, 3]
    R_w = R_f @ se3.matrix_from_rotvec(d6[3:]) @ R_f.T
    out = np.eye(4)
    out[:3, :3] = R_w @ T[:3, :3]
    out[:3, 3] = R_w @ (T[:3, 3] - p_f) + p_f + (R_f @ d6[:3] if in_frame else d6[:3])
    return out


@given(st.lists(st.floats(-1, 1), min_size=3, max_size=3),
       st.lists(st.floats(-1, 1), min_size=18, max_size=18),
       st.sampled_from(["ee", "tip", "tilted", "fixed"]), st.sampled_from(["object", "frame"]))
@settings(max_examples=80, deadline=None)
def test_linear_mapping_matches_plain_algorithm_2(u, m, frame, translation):
    """The tick's float-level mapping computes what the plain matrix formula does, for
    frames on the ee (none, a translated and a rotated offset) and fixed in the object."""
    def q(*w):
        return se3.quaternion_from_rotvec(w).tolist()

    frames = {"tip": {"parent": "ee", "pose": [0, 0, 0.12, 0, 0, 0, 1]},
              "tilted": {"parent": "ee", "pose": [0.02, -0.01, 0.1, *q(0.3, -0.4, 0.2)]},
              "fixed": {"parent": "object", "pose": [0.1, 0.2, 0.0, *q(0.0, 0.5, 1.0)]}}
    assume(any(m))  # the loader refuses an all-zero matrix
    matrix = np.array(m).reshape(6, 3).tolist()
    eng = engine_for(one_state({"type": "linear", "frame": frame, "matrix": matrix,
                                "translation": translation}, frames=frames))
    T = se3.transform_from_pose([0.1, -0.2, 0.3, *se3.quaternion_from_rotvec([0.3, -0.2, 0.5])])
    f = eng.skill.frames[frame]
    T_f = T @ f.T_parent_frame if f.parent == "ee" else f.T_parent_frame
    speeds = np.array([0.1] * 3 + [0.5] * 3)[:, None]
    expected = reference_linear(T, T_f, np.array(matrix) * speeds, np.array(u), 0.01,
                                translation == "frame")
    assert np.allclose(command(eng, T, np.array(u), 0.01), expected, atol=1e-12)
    assert np.allclose(command(eng, T, tuple(u), 0.01), expected, atol=1e-12)

def test_rotation_about_tip_keeps_tip_fixed():
    eng = engine_for(one_state({"type": "linear", "frame": "tip", "axes": ["rx", "ry", "rz"]}))
    T = np.eye(4)
    T2 = command(eng, T, np.array([1.0, 0.5, -0.3]), 0.1)
    tip = eng.skill.frames["tip"].T_parent_frame
    assert np.allclose((T @ tip)[:3, 3], (T2 @ tip)[:3, 3], atol=1e-12)
    assert not np.allclose(T2[:3, 3], T[:3, 3])


def test_zero_input_is_identity():
    eng = engine_for(one_state({"type": "linear", "frame": "tip", "axes": ["tx", "ry", "rz"]}))
    T = se3.transform_from_pose([0.1, 0.2, 0.3, 0, 0, 0, 1])
    assert np.array_equal(command(eng, T, np.zeros(3), 0.001), T)


# --- engine: constraints --------------------------------------------------------------


@given(st.lists(st.floats(-3, 3), min_size=3, max_size=3), st.floats(0.05, 2.5))
@settings(max_examples=80, deadline=None)
def test_tilt_cone_projection_satisfies_and_is_idempotent(w, max_angle):
    doc = one_state({"type": "linear", "frame": "tip", "axes": ["tx"]},
                    [{"type": "tilt_cone", "frame": "tip", "axis": [0, 0, 1], "max_angle": max_angle}])
    eng = engine_for(doc)
    c = eng.skill.states[0].active_constraints[0]
    T = se3.transform_from_rt(se3.matrix_from_rotvec(w), [0.1, 0.0, 0.2])
    P = project(eng, T, c)
    assert violation(eng, P, c) < 1e-9
    assert np.allclose(project(eng, P, c), P)
    tip = eng.skill.frames["tip"].T_parent_frame
    assert np.allclose((P @ tip)[:3, 3], (T @ tip)[:3, 3], atol=1e-9)  # rotates about the tip
    if violation(eng, T, c) == 0:
        assert np.array_equal(P, T)


@given(st.lists(st.floats(-1, 1), min_size=3, max_size=3))
def test_box_and_band_projection(p):
    doc = one_state({"type": "linear", "frame": "ee", "axes": ["tx"]},
                    [{"type": "box", "frame": "tip", "lower": [-0.1, -0.1, 0.0], "upper": [0.1, 0.2, 0.3]},
                     {"type": "band", "frame": "ee", "normal": [0, 0, 1], "lower": 0.05, "upper": 0.1}])
    eng = engine_for(doc)
    T = se3.transform_from_rt(np.eye(3), p)
    for c in eng.skill.states[0].active_constraints:
        P = project(eng, T, c)
        assert violation(eng, P, c) < 1e-12
        assert np.allclose(P[:3, :3], T[:3, :3])


# --- vector fields --------------------------------------------------------------------


def vf_skill_doc(model="m.json", mode="scale"):
    return {
        "sctd_skill": 1, "name": "vf", "object": "obj",
        "limits": {"max_linear_speed": 0.1, "max_angular_speed": 0.5},
        "fsm": {"start": "go", "end": "go"},
        "states": {"go": {
            "input_mapping": [{"type": "vector_field", "model": model, "mode": mode,
                               "min_v": 0.1, "k_s": 0.5, "max_d": 0.2}],
            "active_constraints": [{"type": "neighbour_orientation", "model": model}]}},
    }


def x_field_model() -> VectorFieldModel:
    pts = np.stack([np.linspace(-0.3, 0.3, 61), np.zeros(61), np.zeros(61)], axis=1)
    q = np.tile(se3.quaternion_from_rotvec([0.0, 0.0, 0.4]), (61, 1))
    return VectorFieldModel((TranslationField(direction=np.array([1.0, 0, 0]), weight=1.0),),
                            pts, q, np.ones((61, 1)))


@pytest.mark.parametrize("fmt", ["m.json", "m.npz"])
def test_vector_field_scaling(fmt):
    files = {fmt: vector_field_model_to_bytes(x_field_model(), fmt)}
    eng = SkillEngine(load_text(yaml.safe_dump(vf_skill_doc(fmt)), files))
    T = np.eye(4)
    dt = 0.01
    along = command(eng, T, np.array([1.0, 0, 0]), dt)[:3, 3]
    across = command(eng, T, np.array([0, 1.0, 0]), dt)[:3, 3]
    against = command(eng, T, np.array([-1.0, 0, 0]), dt)[:3, 3]
    assert np.allclose(along, [0.1 * dt, 0, 0])             # aligned: scale 1 (eq. 4.34)
    assert np.allclose(across, [0, 0.1 * 0.1 * dt, 0])      # orthogonal: clipped to min_v
    assert np.allclose(against, [-0.1 * 0.1 * dt, 0, 0])
    assert np.array_equal(command(eng, T, np.zeros(3), dt)[:3, 3], T[:3, 3])
    # Orientation pulled towards the neighbours' (rz 0.4) by the constraint, at most as
    # far per command as the push may turn the hand (|u| * max_angular_speed * dt).
    R = command(eng, T, np.array([1.0, 0, 0]), dt)[:3, :3]
    assert np.allclose(se3.rotvec_from_matrix(R), [0, 0, 0.5 * dt], atol=1e-9)
    R = command(eng, T, np.array([0.5, 0, 0]), dt)[:3, :3]
    assert np.allclose(se3.rotvec_from_matrix(R), [0, 0, 0.25 * dt], atol=1e-9)
    T_k = T
    for _ in range(100):  # 0.4 rad at 0.005 rad per command: there in 80
        T_k = command(eng, T_k, np.array([1.0, 0, 0]), dt)
    assert np.allclose(se3.rotvec_from_matrix(T_k[:3, :3]), [0, 0, 0.4], atol=1e-9)
    # A projection outside a command is a whole one.
    c = eng.skill.states[0].active_constraints[0]
    assert np.allclose(se3.rotvec_from_matrix(project(eng, T, c)[:3, :3]), [0, 0, 0.4], atol=1e-9)


@pytest.mark.parametrize("mode", ["scale", "blend"])
def test_a_field_both_ways_takes_a_push_back_along_it_at_full_speed(mode):
    """``direction: both``: back along the field (out of a drawer, off the lips) as fast
    as along it, across it as slow as ever (scale) or bent onto the field's line the way
    the push goes (blend); zero input still never moves the hand."""
    files = {"m.json": vector_field_model_to_bytes(x_field_model(), "m.json")}
    doc = vf_skill_doc("m.json", mode)
    doc["states"]["go"]["input_mapping"][0]["direction"] = "both"
    eng = SkillEngine(load_text(yaml.safe_dump(doc), files))
    assert eng.skill.states[0].input_mappings[0].to_yaml()["direction"] == "both"
    T, dt = np.eye(4), 0.01
    back = command(eng, T, np.array([-1.0, 0, 0]), dt)[:3, 3]
    assert np.allclose(back, [-0.1 * dt, 0, 0])
    if mode == "scale":
        across = command(eng, T, np.array([0, 1.0, 0]), dt)[:3, 3]
        assert np.allclose(across, [0, 0.1 * 0.1 * dt, 0])
    else:  # a push mostly back and a little across: bent towards -x, not +x
        bent = command(eng, T, np.array([-0.8, 0.6, 0]), dt)[:3, 3]
        assert bent[0] < -0.8 * 0.1 * dt and 0 < bent[1] < 0.6 * 0.1 * dt
    assert np.array_equal(command(eng, T, np.zeros(3), dt)[:3, 3], T[:3, 3])
    doc["states"]["go"]["input_mapping"][0]["direction"] = "backwards"
    with pytest.raises(SkillError, match=r"input_mapping\[0\]\.direction"):
        load_text(yaml.safe_dump(doc), files)


def two_field_model() -> VectorFieldModel:
    """A reach along -x next to the end of a pull along +x (the drawer's overlap):
    points of both at x in [0, 0.2]; those of the pull upright, of the reach turned
    about z by 1 rad; the position alone says "pull" (responsibilities 0.1 / 0.9)."""
    n = 41
    x = np.linspace(0.0, 0.2, n)
    pts = np.concatenate([np.stack([x, np.zeros(n), np.zeros(n)], 1),
                          np.stack([x, np.zeros(n), np.full(n, 0.01)], 1)])
    q = np.concatenate([np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)),
                        np.tile(se3.quaternion_from_rotvec([0.0, 0.0, 1.0]), (n, 1))])
    resp = np.tile([0.1, 0.9], (2 * n, 1))
    fields = (TranslationField(direction=np.array([-1.0, 0, 0]), weight=0.5),
              TranslationField(direction=np.array([1.0, 0, 0]), weight=0.5))
    return VectorFieldModel(fields, pts, q, resp)


def _two_field_engine(combine, rotation_weight=0.0):
    doc = vf_skill_doc("m.json")
    doc["states"]["go"]["input_mapping"][0]["combine"] = combine
    doc["states"]["go"]["active_constraints"][0]["rotation_weight"] = rotation_weight
    files = {"m.json": vector_field_model_to_bytes(two_field_model(), "m.json")}
    return SkillEngine(load_text(yaml.safe_dump(doc), files))


def test_intent_membership_follows_the_push_where_fields_overlap():
    """By position alone a push along the reach runs at the min_v floor; weighing the
    fields by the push as well, the reach is what the user means."""
    T = se3.transform_from_rt(np.eye(3), [0.1, 0.0, 0.0])
    dt = 0.01
    weighted, intent = _two_field_engine("weighted"), _two_field_engine("intent")
    push = np.array([-1.0, 0.0, 0.0])
    assert command(weighted, T, push, dt)[0, 3] - 0.1 > -0.1 * dt * 0.2  # s = 0.1 - 0.9 < 0: the min_v floor
    assert np.isclose(command(intent, T, push, dt)[0, 3] - 0.1, -0.1 * dt, rtol=0.05)
    assert intent.last_membership[0] > 0.9
    # and a pull is still a pull
    assert np.isclose(command(intent, T, -push, dt)[0, 3] - 0.1, 0.1 * dt, rtol=0.01)
    assert intent.last_membership[1] > 0.99
    # zero input never moves the hand, whatever the fields say
    for eng in (weighted, intent):
        assert np.array_equal(command(eng, T, np.zeros(3), dt), T)


@given(st.lists(st.floats(0, 1), min_size=2, max_size=4), st.lists(st.floats(-1, 1), min_size=4, max_size=4),
       st.floats(0, 20))
@settings(deadline=None)
def test_intent_membership_is_a_distribution_that_favours_agreement(p, s, kappa):
    from sctd.skill.mappings import intent_membership

    k = len(p)
    P = np.asarray(p) + 1e-3
    P /= P.sum()
    prior = np.full(k, 1.0 / k)
    post = intent_membership(P, prior, s[:k], kappa)
    assert np.all(post >= 0) and np.isclose(post.sum(), 1.0)
    base = intent_membership(P, prior, [0.0] * k, kappa)  # no evidence: the mixed prior
    assert np.allclose(base, 0.9 * P + 0.1 * prior)
    i, j = int(np.argmax(s[:k])), int(np.argmin(s[:k]))
    assert post[i] / base[i] >= post[j] / base[j] - 1e-12  # the push's field gains most


def test_neighbour_orientation_by_pose_follows_the_demonstrations_turned_as_the_hand():
    """At a position both upright and turned demonstrations passed, by position the
    constraint turns an upright hand towards their mean; by pose it keeps it upright,
    and keeps a turned hand turned."""
    T_up = se3.transform_from_rt(np.eye(3), [0.1, 0.0, 0.005])
    T_turned = se3.transform_from_rt(se3.matrix_from_rotvec([0.0, 0.0, 0.95]), [0.1, 0.0, 0.005])
    by_position, by_pose = _two_field_engine("weighted", 0.0), _two_field_engine("weighted", 0.1)
    c = by_pose.skill.states[0].active_constraints[0]
    assert c.rotation_weight == 0.1
    angle = lambda T: float(se3.rotvec_from_matrix(T[:3, :3])[2])  # noqa: E731
    assert 0.3 < angle(project(by_position, T_up, by_position.skill.states[0].active_constraints[0])) < 0.7
    assert abs(angle(project(by_pose, T_up, c))) < 1e-9
    assert np.isclose(angle(project(by_pose, T_turned, c)), 1.0, atol=1e-9)


@pytest.mark.parametrize("max_turn", [None, 1.2])
def test_a_hand_turned_away_from_every_demonstration_keeps_its_orientation(max_turn):
    """The demonstrations near held the hand at rz 0.4: a hand within ``max_turn``
    (default 90 deg) of that is turned towards it; one brought in turned further (half a
    turn about the vertical, from another task's start) keeps its own, and still moves."""
    files = {"m.json": vector_field_model_to_bytes(x_field_model(), "m.json")}
    doc = vf_skill_doc("m.json")
    if max_turn is not None:
        doc["states"]["go"]["active_constraints"][0]["max_turn"] = max_turn
    eng = SkillEngine(load_text(yaml.safe_dump(doc), files))
    c = eng.skill.states[0].active_constraints[0]
    limit = math.pi / 2 if max_turn is None else max_turn
    assert c.max_turn == limit and (("max_turn" in c.to_yaml()) == (max_turn is not None))
    dt = 0.01
    for off in (limit - 0.05, limit + 0.05, math.pi - 0.01):
        T = se3.transform_from_rt(se3.matrix_from_rotvec([0.0, 0.0, 0.4 + off]), [0.0, 0.0, 0.0])
        T1 = command(eng, T, np.array([1.0, 0, 0]), dt)
        turned = se3.angle_between3(T[:3, :3], T1[:3, :3])
        assert T1[0, 3] > 0.0  # the push moves it either way
        if off < limit:
            assert np.isclose(turned, 0.5 * dt, atol=1e-9)  # towards the demonstrations
        else:
            assert turned == 0.0


def cylinder_model(radius=0.3) -> VectorFieldModel:
    """A door's handle swung about the vertical axis through the origin, demonstrated by a
    hand that turned with it (points on a quarter arc, each turned by its angle)."""
    a = np.linspace(0.0, math.pi / 2, 25)
    pts = np.array([[radius * math.cos(x), radius * math.sin(x), 0.0] for x in a])
    q = np.array([se3.quaternion_from_rotvec([0.0, 0.0, x]) for x in a])
    f = CylinderField(weight=1.0, axis=np.array([0.0, 0.0, 1.0]), point=np.zeros(3))
    return VectorFieldModel((f,), pts, q, np.ones((len(a), 1)))


@pytest.mark.parametrize("field", ["sphere", "cylinder"])
def test_rigid_motion_moves_a_turned_away_hand_along_a_far_axis_unturned(field):
    """A hand held as the demonstrations held it turns with the field as it moves. The
    same hand brought in turned half a turn about the vertical: the pour's sphere, a
    turn about a point of the hand (its pivot), still turns it; a door's cylinder, a
    turn about a far axis, moves it along the arc without turning it."""
    doc = vf_skill_doc("m.json")
    doc["states"]["go"]["input_mapping"][0]["motion"] = "rigid"
    doc["states"]["go"]["active_constraints"] = []
    if field == "sphere":
        centre, pivot = np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.0, 0.12])
        model, at, u = sphere_model(centre, pivot), centre, np.array([1.0, 0.0, 0.0])
    else:
        pivot, model = np.zeros(3), cylinder_model()
        at, u = np.array([0.3, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])
    files = {"m.json": vector_field_model_to_bytes(model, "m.json")}
    eng = SkillEngine(load_text(yaml.safe_dump(doc), files))
    dt = 0.01
    for yaw in (0.0, math.pi):
        R = se3.matrix_from_rotvec([0.0, 0.0, yaw])
        T = se3.transform_from_rt(R, at - R @ pivot)
        T1 = command(eng, T, u, dt)
        turned = se3.angle_between3(T[:3, :3], T1[:3, :3])
        assert np.linalg.norm(T1[:3, 3] - T[:3, 3]) > 0.5 * 0.1 * dt  # it moves either way
        if yaw == 0.0 or field == "sphere":
            assert turned > 0.5 * 0.1 * dt / 0.3
        else:
            assert turned == 0.0


@given(st.lists(st.floats(-1, 1), min_size=3, max_size=3))
@settings(deadline=None)
def test_blend_bends_but_keeps_magnitude_and_zero_stays_zero(u):
    files = {"m.json": vector_field_model_to_bytes(x_field_model(), "m.json")}
    eng = SkillEngine(load_text(yaml.safe_dump(vf_skill_doc("m.json", "blend")), files))
    T = np.eye(4)
    step = command(eng, T, np.array(u), 1.0)[:3, 3]
    mag = min(1.0, float(np.linalg.norm(u)))
    assert np.isclose(np.linalg.norm(step), 0.1 * mag, atol=1e-9)
    if mag > 1e-6:
        unit = np.asarray(u) / np.linalg.norm(u)
        assert step[0] / 0.1 >= unit[0] * mag - 1e-9  # bent towards +x, never away


def test_sigmoid_known_values():
    """Eq. 4.33: identity at k = 0, f(+-1) = +-1, stricter for k > 0."""
    x = np.linspace(-1, 1, 11)
    assert np.allclose(sigmoid(x, 0.0), x)
    assert np.isclose(sigmoid(1.0, 0.5), 1.0) and np.isclose(sigmoid(-1.0, 0.7), -1.0)
    assert np.isclose(sigmoid(0.5, 0.5), 0.25)
    assert np.all(np.abs(sigmoid(x, 0.5)) <= np.abs(x) + 1e-12)


# --- FSM ------------------------------------------------------------------------------


def at(x, y, z):
    # the ee pose (Flat) with the tip (0.12 up the ee z) at (x, y, z)
    return se3.flat_from_transform(se3.transform_from_rt(np.eye(3), [x, y, z - 0.12]))


def test_fsm_hysteresis_and_dwell():
    eng = SkillEngine(load_skill(POUR))
    eng.reset(0.0)
    clock = iter(range(1, 100))

    def step(x, z):
        return eng.update(at(x, 0, z), float(next(clock)))

    assert eng.state == "carry"
    # carry -> approach below 0.15 - 0.01 from (0, 0, 0.08)
    assert not step(0.145, 0.08)  # inside 0.15 but within the margin
    assert step(0.13, 0.08) and eng.state == "approach"
    # No chatter on the boundary: between 0.14 and 0.18 nothing fires.
    for x in (0.16, 0.15, 0.17, 0.179, 0.14):
        assert not step(x, 0.08)
    assert step(0.19, 0.08) and eng.state == "carry"
    assert step(0.0, 0.08) and eng.state == "approach"
    t = eng.entered
    assert not eng.update(at(0.0, 0, 0.06), t + 0.01)  # within min_dwell of entering
    assert eng.update(at(0.0, 0, 0.06), t + 0.2) and eng.state == "pour" and eng.finished


def test_hyperplane_timeout_force_transitions():
    doc = one_state({"type": "linear", "frame": "ee", "axes": ["tx"]})
    doc["states"]["b"] = {"input_mapping": [{"type": "linear", "axes": ["ty"]}]}
    doc["states"]["c"] = {}
    doc["fsm"] = {"start": "s", "end": "c", "min_dwell": 0.0, "transitions": [
        {"from": "s", "to": "b", "type": "hyperplane", "normal": [2, 0, 0], "offset": -0.2, "margin": 0.01},
        {"from": "b", "to": "c", "type": "force", "above": 5.0, "axis": [0, 0, -1], "margin": 1.0},
        {"from": "b", "to": "s", "type": "timeout", "after": 3.0}]}
    eng = engine_for(doc)
    assert not eng.update(at(0.105, 0, 0), 0.0)  # plane x = 0.1, margin 1 cm
    assert eng.update(at(0.111, 0, 0.12), 0.0) and eng.state == "b"
    assert not eng.update(at(0, 0, 0), 1.0, np.array([0, 0, -5.5]))
    assert not eng.update(at(0, 0, 0), 1.0, None)
    assert eng.update(at(0, 0, 0), 3.5) and eng.state == "s"
    eng.reset(0.0, "b")
    assert eng.update(at(0, 0, 0), 0.1, np.array([0, 0, -6.5])) and eng.state == "c"


def test_summary_is_json_and_has_matrix():
    s = skill_summary(load_skill(POUR))
    text = json.dumps(s)
    assert json.loads(text)["object"] == "mug"
    carry = s["states"][0]["input_mappings"][0]
    assert np.allclose(carry["matrix"], np.vstack([np.eye(3), np.zeros((3, 3))]))
    assert s["transitions"][0]["below"] == 0.15 and math.isclose(s["transitions"][0]["margin"], 0.01)


def sphere_model(centre, pivot) -> VectorFieldModel:
    """A pouring sphere of radius 0.12 about ``centre``, demonstrated by a hand whose
    point ``pivot`` (ee offset) sat on the centre; points on its lower half."""
    a = np.linspace(-0.6, 0.6, 25)
    pts = np.array([[0.12 * math.sin(x), 0.0, -0.12 * math.cos(x)] for x in a]) + centre
    q = np.array([se3.quaternion_from_rotvec([0.0, x, 0.0]) for x in a])
    f = SphereField(weight=1.0, centre=np.asarray(centre, float), radius=0.12,
                    pivot=np.asarray(pivot, float))
    return VectorFieldModel((f,), pts, q, np.ones((len(a), 1)))


def test_rigid_motion_turns_the_hand_about_its_pivot_on_a_sphere():
    centre, pivot = np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.0, 0.12])
    doc = vf_skill_doc("m.json")
    doc["states"]["go"]["input_mapping"][0]["motion"] = "rigid"
    doc["states"]["go"]["active_constraints"] = []
    files = {"m.json": vector_field_model_to_bytes(sphere_model(centre, pivot), "m.json")}
    eng = SkillEngine(load_text(yaml.safe_dump(doc), files))
    T = se3.transform_from_rt(np.eye(3), centre - pivot)  # upright, the pivot on the centre
    dt = 0.01
    T1 = command(eng, T, np.array([1.0, 0.0, 0.0]), dt)  # tangent at the sphere's bottom
    assert np.linalg.norm((T1 @ np.append(pivot, 1.0))[:3] - centre) < 1e-9  # the opening stays
    assert np.isclose(np.linalg.norm(T1[:3, 3] - T[:3, 3]), 0.1 * dt, rtol=1e-3)  # at the speed
    w = se3.rotvec_from_matrix(T1[:3, :3])
    assert w[1] < 0 and np.isclose(np.linalg.norm(w), 0.1 * dt / 0.12, rtol=1e-3)  # tilts about y
    assert np.array_equal(command(eng, T, np.zeros(3), dt), T)  # zero input: nothing turns
    # far from the centre (the opening not brought there yet) the push only translates
    # (scaled by its agreement with the field, eq. 4.34)
    T_far = se3.transform_from_rt(np.eye(3), centre - pivot + [0.1, 0.0, 0.0])
    T2 = command(eng, T_far, np.array([1.0, 0.0, 0.0]), dt)
    d = T2[:3, 3] - T_far[:3, 3]
    assert np.allclose(T2[:3, :3], np.eye(3)) and 0 < d[0] <= 0.1 * dt and np.allclose(d[1:], 0)


def test_a_fields_pivot_within_makes_a_hand_on_its_way_in_move_not_turn():
    """The opening 2.5 cm from the sphere's centre: by default (fully within 3.5 cm) a push
    along the sphere turns the hand about it; with ``pivot_within: 0.012`` (none from 2.4
    cm) the same push moves the hand, and with the opening on the centre it turns it."""
    centre, pivot = np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.0, 0.12])
    doc = vf_skill_doc("m.json")
    doc["states"]["go"]["input_mapping"][0]["motion"] = "rigid"
    doc["states"]["go"]["active_constraints"] = []
    model = sphere_model(centre, pivot)
    near = VectorFieldModel((dataclasses.replace(model.fields[0], pivot_within=0.012),), model.points,
                            model.quaternions, model.responsibilities)
    T_in = se3.transform_from_rt(np.eye(3), centre - pivot + [0.025, 0.0, 0.0])
    T_on = se3.transform_from_rt(np.eye(3), centre - pivot)
    turned = {}
    for name, m in (("default", model), ("near", near)):
        blob = vector_field_model_to_bytes(m, "m.json")
        for where, T in (("in", T_in), ("on", T_on)):
            eng = SkillEngine(load_text(yaml.safe_dump(doc), {"m.json": blob}))
            T1 = command(eng, T, np.array([1.0, 0.0, 0.0]), 0.01)
            turned[name, where] = float(np.linalg.norm(se3.rotvec_from_matrix(T1[:3, :3])))
            assert np.array_equal(command(eng, T, np.zeros(3), 0.01), T)  # zero input: nothing moves
    assert turned["default", "in"] > 0.005 and turned["near", "in"] == 0.0
    assert np.isclose(turned["near", "on"], turned["default", "on"]) and turned["near", "on"] > 0.005
    text = json.dumps(near.fields[0].to_yaml())
    assert '"pivot_within": 0.012' in text and "pivot_within" not in json.dumps(model.fields[0].to_yaml())
    back = Field.from_yaml(json.loads(text), "m.json", "fields[0]")
    assert back.pivot_within == 0.012
    with pytest.raises(SkillError, match="pivot_within"):
        Field.from_yaml(json.loads(text.replace("0.012", "0")), "m.json", "fields[0]")


def test_arrive_moves_a_pivot_on_its_way_in_and_turns_it_once_there():
    """The opening 2.5 cm beside the sphere's centre: without ``arrive`` a push towards
    the centre turns the hand about it (a cup tilted before its rim is at the lips);
    with ``arrive: 0.01`` the same push moves the hand, at the push's speed, and turns
    nothing. A push away from the centre, and any push with the opening on the centre,
    turns as before."""
    centre, pivot = np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.0, 0.12])
    files = {"m.json": vector_field_model_to_bytes(sphere_model(centre, pivot), "m.json")}
    T_in = se3.transform_from_rt(np.eye(3), centre - pivot + [0.025, 0.0, 0.0])
    T_on = se3.transform_from_rt(np.eye(3), centre - pivot)
    moved, turned = {}, {}
    for arrive in (0.0, 0.01):
        doc = vf_skill_doc("m.json")
        doc["states"]["go"]["input_mapping"][0] |= {"motion": "rigid", "arrive": arrive}
        doc["states"]["go"]["active_constraints"] = []
        for where, T in (("in", T_in), ("on", T_on)):
            for way in (-1.0, 1.0):
                eng = SkillEngine(load_text(yaml.safe_dump(doc), files))
                T1 = command(eng, T, np.array([way, 0.0, 0.0]), 0.01)
                turned[arrive, where, way] = float(np.linalg.norm(se3.rotvec_from_matrix(T1[:3, :3])))
                moved[arrive, where, way] = T1[:3, 3] - T[:3, 3]
                assert np.array_equal(command(eng, T, np.zeros(3), 0.01), T)  # zero input: nothing moves
                assert np.all(np.isfinite(T1))
    assert turned[0.0, "in", -1.0] > 0.005 and turned[0.01, "in", -1.0] == 0.0
    d = moved[0.01, "in", -1.0]  # straight towards the centre, scaled by its agreement (eq. 4.34)
    assert d[0] < 0 and np.allclose(d[1:], 0.0) and -d[0] <= 0.1 * 0.01 + 1e-12
    assert turned[0.01, "in", 1.0] == turned[0.0, "in", 1.0] > 0.005  # away: turns as before
    for way in (-1.0, 1.0):  # on the centre: nothing to arrive at
        assert turned[0.01, "on", way] == turned[0.0, "on", way] > 0.005
        assert np.array_equal(moved[0.01, "on", way], moved[0.0, "on", way])


def test_arrive_is_written_only_when_set_and_read_with_its_place():
    doc = vf_skill_doc("m.json")
    model = sphere_model(np.zeros(3), np.array([0.0, 0.0, 0.12]))
    files = {"m.json": vector_field_model_to_bytes(model, "m.json")}
    plain = load_text(yaml.safe_dump(doc), files)
    assert "arrive" not in plain.states[0].input_mappings[0].to_yaml()
    doc["states"]["go"]["input_mapping"][0] |= {"motion": "rigid", "arrive": 0.015}
    m = load_text(yaml.safe_dump(doc), files).states[0].input_mappings[0]
    assert m.arrive == 0.015 and m.to_yaml()["arrive"] == 0.015
    doc["states"]["go"]["input_mapping"][0]["motion"] = "translate"
    where = r"states\.go\.input_mapping\[0\]\.arrive"
    with pytest.raises(SkillError, match=where + ": arrive needs motion: rigid"):
        load_text(yaml.safe_dump(doc), files)  # motion translate: nothing to split
    doc["states"]["go"]["input_mapping"][0] |= {"motion": "rigid", "arrive": -0.01}
    with pytest.raises(SkillError, match=where):
        load_text(yaml.safe_dump(doc), files)


def test_rigid_motion_moves_each_part_of_a_push_at_its_own_agreement():
    """A push 0.6 along the pouring sphere and 0.8 across it (down, off the sphere) at its
    bottom: the bottle tilts at 0.6 of full speed (not at the sigmoid of the whole push's
    agreement, f(0.6) = 1/3 at k_s 0.5), and the opening it turns about moves down at
    min_v (0.1) of the 0.8 only."""
    centre, pivot = np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.0, 0.12])
    doc = vf_skill_doc("m.json")
    doc["states"]["go"]["input_mapping"][0] |= {"motion": "rigid", "scale_by": "parts"}
    doc["states"]["go"]["active_constraints"] = []
    files = {"m.json": vector_field_model_to_bytes(sphere_model(centre, pivot), "m.json")}
    eng = SkillEngine(load_text(yaml.safe_dump(doc), files))
    T = se3.transform_from_rt(np.eye(3), centre - pivot)
    dt = 0.01
    T1 = command(eng, T, np.array([0.6, 0.0, -0.8]), dt)
    w = se3.rotvec_from_matrix(T1[:3, :3])
    assert w[1] < 0 and np.isclose(np.linalg.norm(w), 0.6 * 0.1 * dt / 0.12, rtol=1e-3)
    moved = (T1 @ np.append(pivot, 1.0))[:3] - centre
    assert np.allclose(moved, [0.0, 0.0, -0.1 * 0.8 * 0.1 * dt], atol=1e-12)
    assert eng.last_scale < 0.34  # the whole push's scaling, as status reports it
    assert np.array_equal(command(eng, T, np.zeros(3), dt), T)  # zero input: nothing moves
    # scaled as a whole (the thesis, what a file without scale_by reads): both parts at f(0.6) = 1/3
    del doc["states"]["go"]["input_mapping"][0]["scale_by"]
    eng = SkillEngine(load_text(yaml.safe_dump(doc), files))
    T2 = command(eng, T, np.array([0.6, 0.0, -0.8]), dt)
    w2 = se3.rotvec_from_matrix(T2[:3, :3])
    assert np.isclose(np.linalg.norm(w2), 0.6 * 0.1 * dt / 0.12 / 3, rtol=1e-3)
    moved = (T2 @ np.append(pivot, 1.0))[:3] - centre
    assert np.allclose(moved, [0.0, 0.0, -0.8 * 0.1 * dt / 3], atol=1e-12)


def _tilted_on_sphere(centre, pivot, tilt):
    """The hand tilted by ``tilt`` rad about -y (its z to (-sin, 0, cos): the top towards
    -x), its pivot on the sphere's centre."""
    c, s = math.cos(tilt), math.sin(tilt)
    R = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    return se3.transform_from_rt(R, centre - R @ pivot)


def _tilt_of(T) -> float:
    return math.acos(float(np.clip(T[2, 2], -1.0, 1.0)))


def test_a_command_that_turns_with_the_hand_tilts_at_one_rate_at_every_tilt():
    """``command_turns_from: [0, 0, 1]``: the push that tilts the upright bottle about
    its opening keeps tilting it at full speed at 30, 60 and 100 degrees, and the
    opposite push brings it back as fast, the opening held on the centre. Read in the
    object's axes (no key) the same push is off the sphere once the bottle lies (at 100
    degrees it moves the opening at min_v and turns the bottle the other way)."""
    centre, pivot = np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.0, 0.12])
    doc = vf_skill_doc("m.json")
    doc["states"]["go"]["input_mapping"][0] |= {"motion": "rigid", "scale_by": "parts",
                                                "command_turns_from": [0.0, 0.0, 1.0]}
    doc["states"]["go"]["active_constraints"] = []
    files = {"m.json": vector_field_model_to_bytes(sphere_model(centre, pivot), "m.json")}
    eng = SkillEngine(load_text(yaml.safe_dump(doc), files))
    dt, full = 0.01, 0.1 / 0.12  # rad/s: the linear speed at the sphere's radius
    up = command(eng, _tilted_on_sphere(centre, pivot, 0.0), np.array([1.0, 0.0, 0.0]), dt)
    assert np.isclose(_tilt_of(up) / dt, full, rtol=1e-3) and up[0, 2] < 0  # x tips the top to -x
    for tilt in (0.5, 1.0, 1.75):
        T = _tilted_on_sphere(centre, pivot, tilt)
        for sign in (-1.0, 1.0):
            T1 = command(eng, T, np.array([sign, 0.0, 0.0]), dt)
            assert np.isclose((_tilt_of(T1) - tilt) / dt, sign * full, rtol=1e-3)
            assert np.linalg.norm((T1 @ np.append(pivot, 1.0))[:3] - centre) < 1e-12
    assert np.array_equal(command(eng, T, np.zeros(3), dt), T)  # zero input: nothing moves
    del doc["states"]["go"]["input_mapping"][0]["command_turns_from"]
    eng = SkillEngine(load_text(yaml.safe_dump(doc), files))
    T1 = command(eng, _tilted_on_sphere(centre, pivot, 1.75), np.array([1.0, 0.0, 0.0]), dt)
    assert (_tilt_of(T1) - 1.75) / dt < 0.2 * full  # not on: the push is (nearly) radial


@pytest.mark.parametrize("yields", [True, False])
def test_a_pull_that_yields_to_the_turn_leaves_the_turns_about_the_pivot_to_the_push(yields):
    """The demonstrations near a bottle tilted on its sphere were tilted 0.3 rad further
    (they tilt on while the person tilts back). With ``yields_to_turn`` the turns about
    the pivot are the person's: a push back tilts the bottle back at the push's full
    rate, a push on at its own rate, and a push that also leans sideways tilts and leans
    the bottle exactly as the mapping alone does; without it (the default) the pull takes
    its budget off the push back and adds it to the push on. A twist about the bottle's
    own axis is still corrected. Zero input turns nothing."""
    centre, pivot = np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.0, 0.12])
    a = np.linspace(0.0, 1.75, 71)
    pts = np.array([[0.12 * math.sin(x), 0.0, -0.12 * math.cos(x)] for x in a]) + centre
    q = np.array([se3.quaternion_from_rotvec([0.0, -(x + 0.3), 0.0]) for x in a])
    f = SphereField(weight=1.0, centre=centre, radius=0.12, pivot=pivot)
    model = VectorFieldModel((f,), pts, q, np.ones((len(a), 1)))
    doc = vf_skill_doc("m.json")
    doc["states"]["go"]["input_mapping"][0] |= {"motion": "rigid", "scale_by": "parts", "direction": "both",
                                                "command_turns_from": [0.0, 0.0, 1.0]}
    doc["states"]["go"]["active_constraints"][0] |= {"pivot": pivot.tolist(), "yields_to_turn": yields}
    files = {"m.json": vector_field_model_to_bytes(model, "m.json")}
    eng = SkillEngine(load_text(yaml.safe_dump(doc), files))
    c = eng.skill.states[0].active_constraints[0]
    assert c.yields_to_turn is yields and ("yields_to_turn" in c.to_yaml()) is yields
    doc["states"]["go"]["active_constraints"] = []
    free = SkillEngine(load_text(yaml.safe_dump(doc), files))  # the mapping alone
    dt, full, pull = 0.01, 0.1 / 0.12, 0.5  # rad/s: the push along the sphere; the pull's budget
    T = _tilted_on_sphere(centre, pivot, 1.0)
    back = command(eng, T, np.array([-1.0, 0.0, 0.0]), dt)
    assert np.isclose((_tilt_of(back) - 1.0) / dt, -full if yields else -full + pull, rtol=1e-3)
    assert np.linalg.norm((back @ np.append(pivot, 1.0))[:3] - centre) < 1e-12  # the opening stays
    on = command(eng, T, np.array([1.0, 0.0, 0.0]), dt)
    assert np.isclose((_tilt_of(on) - 1.0) / dt, full if yields else full + pull, rtol=1e-2)
    for u in ([-1.0, 0.0, 0.0], [1.0, 0.0, 0.0], [-0.8, 0.6, 0.0]):
        alone, got = command(free, T, np.array(u), dt), command(eng, T, np.array(u), dt)
        # with the key, at most a twist about the bottle's axis (the hand's z) differs
        rv = se3.rotvec_from_matrix(alone[:3, :3].T @ got[:3, :3])
        same = bool(np.abs(rv[:2]).max() < 1e-12) and bool(np.allclose(got[:3, 3], alone[:3, 3], atol=1e-12))
        assert same is yields, u
    # twisted 0.2 rad about the bottle's axis (the hand's z, through the pivot): corrected
    # by the pull's budget in a command either way
    twisted = T @ se3.transform_from_rt(se3.matrix_from_rotvec([0.0, 0.0, 0.2]), np.zeros(3))
    u = np.array([-1.0, 0.0, 0.0])
    R = command(free, twisted, u, dt)[:3, :3].T @ command(eng, twisted, u, dt)[:3, :3]
    assert abs(abs(se3.rotvec_from_matrix(R)[2]) - pull * dt) < 1e-3 * pull * dt if yields else \
        np.linalg.norm(se3.rotvec_from_matrix(R)) > pull * dt * 0.9
    assert np.array_equal(command(eng, T, np.zeros(3), dt), T)


def test_yields_to_turn_needs_a_pivot():
    """The turns a neighbour orientation leaves to the push are those about its pivot:
    the key without one is refused where it stands."""
    centre, pivot = np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.0, 0.12])
    doc = vf_skill_doc("m.json")
    doc["states"]["go"]["active_constraints"][0]["yields_to_turn"] = True
    files = {"m.json": vector_field_model_to_bytes(sphere_model(centre, pivot), "m.json")}
    where = r"states\.go\.active_constraints\[0\]\.yields_to_turn"
    with pytest.raises(SkillError, match=where + ": needs a pivot"):
        load_text(yaml.safe_dump(doc), files)


@given(st.lists(st.floats(-1, 1), min_size=3, max_size=3), st.lists(st.floats(-1, 1), min_size=3, max_size=3),
       st.lists(st.floats(-3, 3), min_size=3, max_size=3), st.lists(st.floats(-1, 1), min_size=3, max_size=3))
@settings(max_examples=300, deadline=None)
def test_a_turned_command_is_the_shortest_turn_from_the_reference_to_the_axis(frm, axis, rv, u):
    """:func:`turned_command` equals the rotation matrix of the shortest turn taking
    ``frm`` to the frame's axis, applied to the command: it keeps the command's length,
    and takes ``frm`` itself onto the axis."""
    from sctd.skill.mappings import turned_command

    f, k = np.asarray(frm), np.asarray(axis)
    assume(np.linalg.norm(f) > 1e-2 and np.linalg.norm(k) > 1e-2)
    f, k = f / np.linalg.norm(f), k / np.linalg.norm(k)
    R = se3.matrix_from_rotvec(rv)
    a = R @ k
    assume(float(f @ a) > -0.999)
    G = (*R.ravel().tolist(), 0.0, 0.0, 0.0)
    out = np.array(turned_command(G, tuple(k), tuple(f), tuple(u)))
    v = np.cross(f, a)
    ang = math.atan2(float(np.linalg.norm(v)), float(f @ a))
    Rm = se3.matrix_from_rotvec(v / np.linalg.norm(v) * ang) if np.linalg.norm(v) > 1e-12 else np.eye(3)
    assert np.allclose(out, Rm @ np.asarray(u), atol=1e-9)
    assert np.allclose(turned_command(G, tuple(k), tuple(f), tuple(f)), a, atol=1e-9)


def test_command_turns_from_needs_a_rigid_field_with_a_pivot_off_the_frame():
    """The key on a translation field, or with motion translate, is refused where it
    stands; a zero direction too."""
    centre, pivot = np.array([0.0, 0.0, 0.05]), np.array([0.0, 0.0, 0.12])
    sphere = {"m.json": vector_field_model_to_bytes(sphere_model(centre, pivot), "m.json")}
    line = {"m.json": vector_field_model_to_bytes(x_field_model(), "m.json")}
    zero = {"motion": "rigid", "command_turns_from": [0, 0, 0]}
    for files, extra, problem in ((line, {"motion": "rigid"}, "exactly one field with a pivot"),
                                  (sphere, {}, "motion: rigid"), (sphere, zero, "zero length")):
        doc = vf_skill_doc("m.json")
        doc["states"]["go"]["input_mapping"][0] |= {"command_turns_from": [0.0, 0.0, 1.0]} | extra
        with pytest.raises(SkillError, match=problem) as e:
            load_text(yaml.safe_dump(doc), files)
        assert "states.go.input_mapping[0].command_turns_from" in str(e.value)


@given(st.sampled_from(["translation", "sphere", "cylinder"]),
       st.lists(st.floats(-0.3, 0.3), min_size=3, max_size=3),
       st.lists(st.floats(-1, 1), min_size=3, max_size=3))
@settings(max_examples=200, deadline=None)
def test_agreement_on_floats_equals_the_vectorised_one(kind, p, u):
    n = float(np.linalg.norm(u))
    assume(n > 1e-3)
    unit = np.asarray(u) / n
    f = {"translation": lambda: TranslationField(direction=np.array([0.6, 0.0, 0.8])),
         "sphere": lambda: SphereField(centre=np.array([0.05, -0.02, 0.1])),
         "cylinder": lambda: CylinderField(axis=np.array([0.0, 0.6, 0.8]), point=np.array([0.1, 0.0, 0.0])),
         }[kind]()
    assert math.isclose(f.agreement3(tuple(p), tuple(unit.tolist())), f.agreement(np.asarray(p), unit),
                        rel_tol=1e-9, abs_tol=1e-12)


@pytest.mark.parametrize("name", ["pour-vf", "drawer-vf"])
def test_reused_neighbour_queries_keep_the_learned_skills_path(name, monkeypatch):
    """Reusing a neighbour query while the frame stays within 0.5 mm / 5 mrad of where it
    was made leaves a 3 s push at 1 kHz within 0.1 mm of querying every tick, with a
    fraction of the KD-tree queries; zero input still moves nothing."""
    import sctd.skill.neighbours as neighbours_module

    skill = load_skill(ROOT / "skills" / f"{name}.yaml")
    model = skill.states[0].input_mappings[0].model

    def push(reuse: bool):
        monkeypatch.setattr(neighbours_module, "REUSE_DISTANCE", 5e-4 if reuse else 0.0)
        monkeypatch.setattr(neighbours_module, "REUSE_ANGLE", 5e-3 if reuse else 0.0)
        eng = SkillEngine(skill)
        eng.reset(0.0)
        F = se3.flat_from_pose([*(model.points[0] - [0.0, 0.0, 0.12]), *model.quaternions[0]])
        path = []
        for _ in range(3000):
            F = eng.command(F, (0.8, 0.3, 0.2), 0.001)
            path.append(F[9:])
        assert eng.command(F, (0.0, 0.0, 0.0), 0.001) == F
        return np.array(path), sum(nb.queries for nb in eng.workspace.neighbours.values())

    every, n_every = push(False)
    reused, n_reused = push(True)
    assert np.abs(every - reused).max() < 1e-4 and n_reused < 0.3 * n_every, (n_reused, n_every)
