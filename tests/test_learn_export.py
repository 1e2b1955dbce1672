"""End to end: demonstration folder -> skill YAML (+ model) -> load_skill; report."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from sctd import se3
from sctd.cli.learn import add_dtw_arguments, add_learn_arguments, main_dtw, main_learn, parse_frame
from sctd.skill import SkillEngine, load_skill
from sctd.task import find_task
from sctd_sim import demogen


@pytest.fixture(scope="module")
def pour_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("pour")
    demogen.write_demo_set(demogen.generate(find_task("pour"), 6, outliers=0.05, seed=3), d)
    return d


@pytest.fixture(scope="module")
def pour10_dir(tmp_path_factory):
    """The shipped pour's demonstrations (10, seed 1): with 6 from azimuths +-45 deg
    apart, the likelihood explains the carry by two translations before the pour's
    sphere (each sharper than the sphere's plane)."""
    d = tmp_path_factory.mktemp("pour10")
    demogen.write_demo_set(demogen.generate(find_task("pour"), 10, outliers=0.05, seed=1), d)
    return d


# The keys summary.json's "hyperparameters" has had since it exists (both methods'),
# which scripts may read; new ones may be added, none may go.
SUMMARY_HYPERPARAMETERS = {
    "spacing", "vf_spacing", "smooth", "despike", "alpha", "beta", "smoothness", "radius", "max_n", "C",
    "cut", "min_segment", "axis_support", "margin", "dtw_align", "n_fields", "em_iterations",
    "angle_sphere", "angle_translation", "angle_cylinder", "max_radius", "max_cylinder_radius",
    "chance_weight", "min_v",
    "max_d", "k_s", "vf_max_n", "vf_combine", "vf_rotation_weight", "vf_motion", "object",
    "max_linear_speed", "max_angular_speed", "seed"}


def _learn(argv):
    return main_learn(add_learn_arguments(argparse.ArgumentParser()).parse_args(argv))


def test_learn_linear_writes_a_loadable_skill_and_report(pour_dir, tmp_path, capsys):
    out, rep = tmp_path / "s" / "pour-linear.yaml", tmp_path / "rep"
    rc = _learn([str(pour_dir), "--method", "linear", "--out", str(out), "--object", "mug",
                 "--frame", "tip=0,0,0.12,0,0,0,1", "--report", str(rep), "--quiet"])
    assert rc == 0, capsys.readouterr().err
    # Ch. 6.2: s0 is no trap; s1 (ry about the tip) has no way back by motion, and says so
    assert "s1 -> s0: no way back by motion" in capsys.readouterr().out
    assert "s1 -> s0: no way back by motion" in out.read_text().split("sctd_skill")[0]
    skill = load_skill(out)
    assert skill.object == "mug" and [s.name for s in skill.states] == ["s0", "s1"]
    assert skill.states[1].input_mappings[0].frame == "tip"
    assert {(t.source, t.target) for t in skill.transitions} == {("s0", "s1"), ("s1", "s0")}
    summary = json.loads((rep / "summary.json").read_text())
    truth = json.loads((pour_dir / "truth.json").read_text())
    assert set(summary["labels"]) == set(truth["labels"])
    for name, lab in summary["labels"].items():
        assert len(lab) == len(truth["labels"][name])
        assert set(lab) <= {0, 1}
    assert summary["hyperparameters"]["alpha"] == 0.4
    assert SUMMARY_HYPERPARAMETERS <= set(summary["hyperparameters"])  # both methods', as always
    assert summary["hyperparameters"]["seed"] == summary["hyperparameters"]["random_state"] == 0
    assert summary["skill"]["states"][0]["name"] == "s0"
    (trap,) = summary["traps"]
    assert trap["state"] == "s0" and not trap["trap"] and trap["added"] is None and not trap["way_back"]
    for fig in summary["figures"]:
        assert (rep / fig).stat().st_size > 1000
    # The runtime engine accepts it and moves the tip only by rotation in s1.
    eng = SkillEngine(skill)
    eng.reset(0.0, "s1")
    T = np.eye(4)
    T2 = se3.transform_from_flat(eng.command(se3.flat_from_transform(T), np.array([1.0, 0.0, 0.0]), 0.01))
    tip = T @ np.r_[0, 0, 0.12, 1]
    np.testing.assert_allclose(T2 @ np.r_[0, 0, 0.12, 1], tip, atol=1e-12)


def test_learn_vf_writes_model_and_candidate_frames(pour10_dir, tmp_path):
    out = tmp_path / "pour-vf.yaml"
    assert _learn([str(pour10_dir), "--method", "vf", "--out", str(out), "--quiet",
                   "--report", str(tmp_path / "r")]) == 0
    assert (tmp_path / "pour-vf.npz").exists()
    skill = load_skill(out)
    im = skill.states[0].input_mappings[0]
    assert im.type == "vector_field" and im.min_v == 0.1 and im.k_s == 0.5 and im.max_n == 5
    assert skill.states[0].active_constraints[0].type == "neighbour_orientation"
    assert any(c["kind"] == "sphere" for c in skill.candidate_frames)
    summary = json.loads((tmp_path / "r" / "summary.json").read_text())
    assert {f["type"] for f in summary["fields"]} == {"sphere", "translation"}
    assert SUMMARY_HYPERPARAMETERS <= set(summary["hyperparameters"])
    assert "candidate_frame.png" in summary["figures"]


def test_learn_reports_bad_input(tmp_path, capsys):
    (tmp_path / "a.csv").write_text("t,x,y,z,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n")
    assert _learn([str(tmp_path), "--out", str(tmp_path / "x.yaml"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "a.csv" in err and "too few samples" in err
    assert not (tmp_path / "x.yaml").exists()
    with pytest.raises(ValueError, match="quaternion"):
        parse_frame("tip=0,0,0.1,0,0,0,2")
    with pytest.raises(ValueError, match="NAME="):
        parse_frame("0,0,0")


def test_dtw_command(pour_dir, capsys):
    args = add_dtw_arguments(argparse.ArgumentParser()).parse_args(
        [str(pour_dir / "demo_00.csv"), str(pour_dir / "demo_00.csv"), "--json"])
    assert main_dtw(args) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["cost"] == pytest.approx(0.0, abs=1e-9)
    args = add_dtw_arguments(argparse.ArgumentParser()).parse_args(
        [str(pour_dir / "demo_00.csv"), str(pour_dir / "demo_01.csv")])
    assert main_dtw(args) == 0
    assert "DTW cost" in capsys.readouterr().out
