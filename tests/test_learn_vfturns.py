"""A gripper phase in which the demonstrations turn the hand in place (a tap's handle)
is learned as a cylinder field of a lever point of the hand, its pivot the hand's origin
(sctd.learn.vfturns); the learned state turns the hand about the demonstrated axis and
keeps its origin where it is."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from sctd import se3
from sctd.learn import Demo, VectorFieldLearner, VectorFieldOptions, learn_vector_fields, skill_bundle
from sctd.learn.gripper import plan_gripper
from sctd.learn.vfturns import STILL, TURN_MIN, turns_in_place
from sctd.skill import SkillEngine, skill_from_bundle
from tests.shipped import assert_same_models

HANDLE = np.array([0.0, 0.0, 0.03])  # where the hand takes the handle (object frame)
LEVER = 0.2  # m


def _rot(axis, angle):
    return se3.matrix_from_rotvec(np.asarray(axis, dtype=float) * angle)


def _quat(R):
    q = se3.quaternion_from_matrix(R)
    return q if q[3] >= 0 else -q


def _demo(name, angle, rng, axis=(0.0, 0.0, 1.0), drift=0.0):
    """Reach the handle along x, close, turn the hand by ``angle`` about ``axis`` through
    its origin (moving the origin ``drift`` m along y as it turns), open, back off along x."""
    R0 = _rot([0, 0, 1], math.radians(-70) + rng.normal(0, 0.02))
    start = HANDLE + np.array([-0.2, 0.09, 0.14]) + rng.normal(0, 0.005, 3)
    rows = []
    for s in np.linspace(0, 1, 60):  # the reach, fingers open
        rows.append((start + s * (HANDLE - start), R0, False))
    for s in np.linspace(0, 1, 80):  # the turn, holding the handle
        p = HANDLE + np.array([0.0, drift * s, 0.0]) + rng.normal(0, 3e-4, 3)
        rows.append((p, _rot(axis, s * angle) @ R0, True))
    R1 = rows[-1][1]
    for s in np.linspace(0, 1, 40)[1:]:  # let go and back off
        rows.append((HANDLE + np.array([-0.1 * s, 0.0, 0.0]), R1, False))
    poses = np.array([[*p, *_quat(R)] for p, R, _ in rows])
    grasped = np.array([g for _, _, g in rows])
    width = np.where(grasped, 0.04, 0.08)
    return Demo(name, np.arange(len(rows)) * 0.02, poses, width=width, grasped=grasped)


def _demos(n=6, seed=0, **kw):
    rng = np.random.default_rng(seed)
    return [_demo(f"demo_{k:02d}", math.radians(60) + rng.normal(0, 0.03), rng, **kw) for k in range(n)]


def test_the_held_phase_is_a_turn_about_the_handles_axis_with_a_lever_across_it():
    demos = _demos()
    turns = turns_in_place(demos, plan_gripper(demos), LEVER, 0.005)
    assert set(turns) == {1}  # the reach and the backing off move: not turns
    t = turns[1]
    assert t.axis @ [0, 0, 1] > 0.999  # the demonstrated sense: +z by the right-hand rule
    assert np.linalg.norm(t.centre - HANDLE) < 1e-3 and t.spread < 1e-3
    assert np.allclose(np.degrees(t.angles), 60, atol=6)
    # the lever: LEVER m of the hand across the axis (the axis is the hand's z here)
    assert math.isclose(np.linalg.norm(t.lever), LEVER, rel_tol=1e-5) and abs(t.lever[2]) < 1e-6
    # the lever point goes round the axis at LEVER m of it, along the field
    radius = np.linalg.norm((t.points - t.centre)[:, :2], axis=1)
    assert np.allclose(radius, LEVER, atol=2e-3) and t.sigma < 0.15  # 0.3 mm noise on 5 mm steps: ~0.09
    field = t.field()
    assert np.allclose(field.pivot, -t.lever) and field.inliers == len(t.points)
    assert len(t.points) == len(t.quaternions) == len(t.model().responsibilities)


def test_a_turn_the_other_way_has_the_opposite_sense():
    demos = _demos(axis=(0.0, 0.0, -1.0))
    (t,) = turns_in_place(demos, plan_gripper(demos), LEVER, 0.005).values()
    assert t.axis @ [0, 0, 1] < -0.999


@pytest.mark.parametrize("case", ["moving", "small", "disagreeing"])
def test_a_held_phase_that_is_no_turn_in_place_stays_as_learned(case):
    rng = np.random.default_rng(1)
    if case == "moving":  # the origin travels 4 cm as the hand turns: RMS over STILL
        demos = _demos(drift=0.04)
        assert 0.04 / math.sqrt(12) > STILL
    elif case == "small":  # one demonstration turns less than TURN_MIN
        demos = [*_demos(5), _demo("demo_05", TURN_MIN * 0.5, rng)]
    else:  # one demonstration turns about another axis
        demos = [*_demos(5), _demo("demo_05", math.radians(60), rng, axis=(1.0, 0.0, 0.0))]
    assert turns_in_place(demos, plan_gripper(demos), LEVER, 0.005) == {}


def _learned(demos):
    res = learn_vector_fields(demos, learner=VectorFieldLearner(random_state=0),
                              field_options=VectorFieldOptions(vf_states="auto", vf_direction="both"))
    return res, skill_from_bundle(skill_bundle(res, "tap-vf"))


def test_the_learned_skill_turns_the_hand_in_place_both_ways():
    res, skill = _learned(_demos())
    t = res.turns[1]
    assert np.allclose(skill.frames["lever1"].pose, [*t.lever, 0, 0, 0, 1])
    turning = [s for s in skill.states if s.input_mappings[0].frame == "lever1"]
    # the state that holds the handle and the release after it; the release opens
    assert len(turning) == 2 and not turning[0].active_constraints
    assert turning[1].gripper is not None and turning[1].gripper.action == "open"
    (m,) = turning[0].input_mappings
    assert m.model_file == "tap-vf-turn1.npz" and m.motion == "rigid" and m.scale_by == "parts"
    one = dataclasses.replace(skill, states=(turning[0],), transitions=(), start=turning[0].name,
                              end=turning[0].name)  # the held state alone: no event moves it on
    R0 = se3.matrix_from_quaternion(res.turns[1].quaternions[0])
    for sense in (1.0, -1.0):
        eng = SkillEngine(one)
        F = se3.flat_from_pose([*HANDLE, *_quat(R0)])
        for _ in range(100):  # 1 s pushing along the circle where the lever point is
            T = se3.transform_from_flat(F)
            lever = T[:3, 3] + T[:3, :3] @ t.lever
            tangent = np.cross(t.axis, lever - t.centre)
            F = eng.command(F, sense * tangent / np.linalg.norm(tangent), 0.01)
        T = se3.transform_from_flat(F)
        assert np.linalg.norm(T[:3, 3] - HANDLE) < 1e-3  # the origin stays on the handle
        w = se3.rotvec_from_matrix(T[:3, :3] @ R0.T)
        assert np.linalg.norm(w) > 0.2 and sense * (w @ t.axis) / np.linalg.norm(w) > 0.99


def test_the_shipped_tap_demonstrations_learn_the_shipped_vector_field_tap():
    """Known answer: skills/README.md's command for tap-vf learns its file, text for text,
    and its models' fields and arrays; the taught demonstrations turned the handle about the tap's
    z axis with the hand's origin on it."""
    from pathlib import Path

    from sctd.learn import learn, read_demos
    from sctd.skill import load_skill

    root = Path(__file__).resolve().parents[1]
    demos = read_demos(root / "skills" / "demos" / "tap")
    result = learn(demos, "vf", object="tap", random_state=0, vf_states="blend", vf_direction="both",
                   models=("translation", "cylinder", "sphere", "point", "general"))
    (t,) = result.turns.values()
    assert t.axis @ [0, 0, 1] > math.cos(math.radians(2)) and t.spread < 0.002
    assert abs(t.lever @ (se3.matrix_from_quaternion(t.quaternions[0]).T @ t.axis)) < 1e-6
    bundle = skill_bundle(result, "tap-vf")
    assert bundle.yaml_text == (root / "skills" / "tap-vf.yaml").read_text()
    learned, shipped = skill_from_bundle(bundle), load_skill(root / "skills" / "tap-vf.yaml")
    assert learned.models().keys() == shipped.models().keys() and "tap-vf-turn1.npz" in shipped.models()
    for rel, a in learned.models().items():
        assert_same_models(a, shipped.models()[rel], rel)  # to the CPU's kernels' rounding
