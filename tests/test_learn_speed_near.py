"""``sctd learn --speed-near WITHIN:V:W[:X,Y,Z]``: every state of the learned skill gets a
``speed_near`` constraint so written (after its own constraints); a bad one is refused
naming the flag, before anything is learned or written; without it nothing changes."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from sctd.cli.learn import add_learn_arguments, main_learn
from sctd.learn import HyperparameterError, SkillOptions, check_hyperparameters
from sctd.learn.results import speed_near_from_text
from sctd.skill import SpeedNear, load_skill
from sctd.task import find_task
from sctd_sim import demogen

TIP = "tip=0,0,0.12,0,0,0,1"


@pytest.fixture(scope="module")
def pour_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("pour")
    demogen.write_demo_set(demogen.generate(find_task("pour"), 6, outliers=0.05, seed=3), d)
    return d


def _learn(argv):
    return main_learn(add_learn_arguments(argparse.ArgumentParser()).parse_args(argv))


def test_every_learned_state_gets_the_cap_last(pour_dir, tmp_path):
    out = tmp_path / "capped.yaml"
    assert _learn([str(pour_dir), "--method", "linear", "--frame", TIP, "--object", "mug", "--quiet",
                   "--speed-near", "0.1:0.03:0.3:0,0,0.12", "--out", str(out)]) == 0
    skill = load_skill(out)
    assert len(skill.states) == 2
    for state in skill.states:
        cap = state.active_constraints[-1]
        assert isinstance(cap, SpeedNear) and cap.frame == "ee"
        assert (cap.within, cap.max_linear_speed, cap.max_angular_speed) == (0.1, 0.03, 0.3)
        assert cap.point is not None and cap.point.tolist() == [0.0, 0.0, 0.12]
    plain = tmp_path / "plain.yaml"
    assert _learn([str(pour_dir), "--method", "linear", "--frame", TIP, "--object", "mug", "--quiet",
                   "--out", str(plain)]) == 0
    uncapped = load_skill(plain)
    assert not any(isinstance(c, SpeedNear) for s in uncapped.states for c in s.active_constraints)
    # the same skill but for the cap: the same mappings and transitions
    assert uncapped.transitions == skill.transitions
    assert [s.input_mappings for s in uncapped.states] == [s.input_mappings for s in skill.states]


def test_a_vector_field_skill_gets_it_after_its_orientation(pour_dir, tmp_path):
    out = tmp_path / "vf.yaml"
    assert _learn([str(pour_dir), "--method", "vf", "--object", "mug", "--quiet", "--speed-near",
                   "0.15:0.05:0.4", "--out", str(out)]) == 0
    (state,) = load_skill(out).states
    assert [c.type for c in state.active_constraints] == ["neighbour_orientation", "speed_near"]
    assert state.active_constraints[1].point is None


@pytest.mark.parametrize(("text", "problem"), [
    ("0.1:0.03", "expected WITHIN:V:W[:X,Y,Z], got '0.1:0.03'"),
    ("near:0.03:0.3", "expected numbers as in WITHIN:V:W[:X,Y,Z]"),
    ("0:0.03:0.3", "within: must be > 0.0, got 0.0"),
    ("0.1:2:0.3", "max_linear_speed: must be <= 1.0, got 2.0"),
    ("0.1:0.03:nan", "max_angular_speed: must be finite"),
    ("0.1:0.03:0.3:0,0,3", "point: must be within 1 m of the frame's origin"),
    ("0.1:0.03:0.3:0,0", "point: expected a list of 3 numbers"),
])
def test_a_bad_cap_is_refused_naming_the_flag(pour_dir, tmp_path, capsys, text, problem):
    out = tmp_path / "x.yaml"
    assert _learn([str(pour_dir), "--method", "vf", "--quiet", "--speed-near", text, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sctd learn: --speed-near: ") and problem in err, err
    assert not out.exists()
    with pytest.raises(ValueError, match=problem.replace("(", r"\(").replace("[", r"\[")):
        speed_near_from_text(text)


def test_the_cap_is_a_hyperparameter_of_both_methods():
    """A learner's request names it as the command line does (``speed_near``), checked the
    same way."""
    assert SkillOptions().speed_near == ""
    for method in ("linear", "vf"):
        check_hyperparameters(method, {"speed_near": "0.1:0.03:0.3"})
        with pytest.raises(HyperparameterError, match=r"speed_near: within: must be > 0\.0"):
            check_hyperparameters(method, {"speed_near": "-1:0.03:0.3"})
    c = speed_near_from_text("0.1:0.03:0.3:0.035,0,0.1")
    np.testing.assert_array_equal(c.point, [0.035, 0.0, 0.1])


def test_the_shipped_drink_skill_caps_the_rim_near_the_mouth():
    from sctd.skill.catalog import shipped_folder

    skill = load_skill(shipped_folder() / "drink-vf.yaml")
    assert skill.object == "mouth"
    for state in skill.states:
        cap = state.active_constraints[-1]
        assert isinstance(cap, SpeedNear) and cap.frame == "ee"
        assert (cap.within, cap.max_linear_speed, cap.max_angular_speed) == (0.1, 0.03, 0.3)
        assert cap.point is not None and cap.point.tolist() == [0.035, 0.0, 0.1]
