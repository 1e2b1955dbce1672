"""Sequential vector fields become states: a state per field in the
order the demonstrations use them, on when the hand is where they switched."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sctd import se3
from sctd.bench.demos import demo_kind
from sctd.learn import Demo, VectorFieldLearner, VectorFieldOptions, learn_vector_fields, skill_bundle
from sctd.learn.vfstates import plan_states
from sctd.skill import SkillEngine, skill_from_bundle
from sctd.skill.summary import skill_summary
from sctd_sim import demogen


def _result(task, seed, states="auto"):
    ds = demogen.generate(demo_kind(task), 10, noise=0.001, outliers=0.05, seed=seed)
    demos = [Demo(d.name, d.t, d.poses) for d in ds.demos]
    return ds, learn_vector_fields(demos, learner=VectorFieldLearner(random_state=seed),
                                   field_options=VectorFieldOptions(vf_states=states))


@pytest.mark.parametrize("seed", range(4))
def test_the_drawer_is_reach_then_pull_switching_at_the_handle(seed):
    _, res = _result("drawer", seed)
    plan = res.plan
    assert plan.sequential, plan.reason
    first, second = (res.learner.fields_[m] for m in plan.order)
    assert first.direction[0] < -0.5 and second.direction[0] > 0.9  # towards the handle, then out
    (h,) = plan.transitions
    assert np.linalg.norm(h.point) < 0.03 and h.radius >= 0.01
    for name, labels in res.labels.items():  # states in time: reach (0) before pull (1)
        lab = np.asarray(labels)
        assert lab[0] == 0 and lab[-1] == 1, name


def test_the_skill_has_a_state_per_field_and_moves_on_at_the_switch():
    _, res = _result("drawer", 0)
    bundle = skill_bundle(res, "drawer-vf")
    assert set(bundle.files) == {"drawer-vf-s0.npz", "drawer-vf-s1.npz"}
    skill = skill_from_bundle(bundle)
    assert [s.name for s in skill.states] == ["s0", "s1"] and skill.start == "s0" and skill.end == "s1"
    (t,) = skill.transitions
    assert t.type == "distance" and (t.source, t.target) == ("s0", "s1")
    summary = skill_summary(skill)
    assert [f["state"] for f in summary["fields"]] == ["s0", "s1"]
    eng = SkillEngine(skill)
    far = se3.flat_from_pose([0.25, 0.0, 0.1, 0, 0, 0, 1])
    assert not eng.update(far, 1.0) and eng.state == "s0"
    at = se3.flat_from_pose([*res.plan.transitions[0].point.tolist(), 0, 0, 0, 1])
    assert eng.update(at, 2.0) and eng.state == "s1"


def test_blend_keeps_the_thesis_single_state():
    _, res = _result("drawer", 0, states="blend")
    assert not res.plan.sequential
    skill = skill_from_bundle(skill_bundle(res, "d"))
    assert [s.name for s in skill.states] == ["default"] and skill.transitions == ()


def test_fields_used_back_and_forth_stay_blended():
    """A zig-zag along x: the two translation fields alternate in every demonstration."""
    rng = np.random.default_rng(0)
    trajs = []
    for _ in range(6):
        leg = np.linspace(0, 0.15, 12)
        x = np.concatenate([leg, leg[::-1][1:], leg[1:], leg[::-1][1:]])
        pts = np.stack([x, np.zeros_like(x), np.linspace(0, 0.1, len(x))], axis=1)
        trajs.append(pts + rng.normal(0, 0.0005, pts.shape) + rng.uniform(-0.01, 0.01, 3))
    vf = VectorFieldLearner(random_state=0, models=("translation",)).fit(trajs)
    assert len(vf.fields_) == 2
    plan = plan_states(vf)
    assert not plan.sequential and plan.reason


def test_a_state_of_one_field_scales_by_parts_and_a_blended_one_as_a_whole():
    """The shipped pour's demonstrations as states: the pour state's sphere turns the
    hand, and each part of a push is scaled on its own there; blended, the whole push."""
    from sctd.learn import learn, read_demos

    demos = read_demos(Path(__file__).resolve().parents[1] / "skills" / "demos" / "pour")
    kinds = ["translation", "cylinder", "sphere", "point", "general"]
    for states, expected in (("auto", [("point", "parts"), ("sphere", "parts")]),
                             ("blend", [("point sphere", "whole")])):
        res = learn(demos, method="vf", random_state=0, models=kinds, vf_states=states, object="mug")
        skill = skill_from_bundle(skill_bundle(res, "pour-vf"))
        got = [(" ".join(f.type for f in m.model.fields), m.scale_by)
               for m in (s.input_mappings[0] for s in skill.states)]
        assert got == expected


def test_a_pour_state_turns_the_stick_with_the_bottle_from_where_the_demonstrations_entered():
    """Learned from the shipped pour's demonstrations as states: the pour state's sphere
    turns the hand about the opening, so its stick's axes turn with the bottle from the
    direction the bottle's axis had where the demonstrations entered the state (near
    upright: the carry brings it upright); the carry's point field has no pivot and
    reads the stick in the mug's axes; blended, no state turns it."""
    from sctd.learn import learn, read_demos

    demos = read_demos(Path(__file__).resolve().parents[1] / "skills" / "demos" / "pour")
    kinds = ["translation", "cylinder", "sphere", "point", "general"]
    res = learn(demos, method="vf", random_state=0, models=kinds, vf_states="auto", object="mug")
    carry, pour = (s.input_mappings[0] for s in skill_from_bundle(skill_bundle(res, "pour-vf")).states)
    assert carry.command_turns_from is None
    assert pour.command_turns_from == (0.0, 0.0, 1.0)  # entered 6 deg from upright: the mug's z
    axis = np.array([0.0, 0.0, 1.0])
    # the state's own points tilt far from it (deep in the pour): it is where the
    # demonstrations entered, not the state's average
    pivot = pour.model.fields[0].pivot
    on = np.flatnonzero(res.learner.assignment_ == res.plan.order[1])
    assert min(se3.matrix_from_quaternion(res.learner.quaternions_[i]) @ pivot / np.linalg.norm(pivot) @ axis
               for i in on) < np.cos(np.radians(60))
    blended = learn(demos, method="vf", random_state=0, models=kinds, vf_states="blend", object="mug")
    (only,) = skill_from_bundle(skill_bundle(blended, "pour-vf")).states
    assert only.input_mappings[0].command_turns_from is None


def test_an_entry_direction_near_an_object_axis_is_that_axis():
    from sctd.learn.vfstates import snapped

    tilt = np.radians(25)
    assert np.array_equal(snapped(np.array([-np.sin(tilt), 0.0, np.cos(tilt)])), [0.0, 0.0, 1.0])
    assert np.array_equal(snapped(np.array([0.0, -np.cos(tilt), np.sin(tilt)])), [0.0, -1.0, 0.0])
    far = np.array([np.sin(np.radians(40)), 0.0, np.cos(np.radians(40))])
    assert np.array_equal(snapped(far), far)
