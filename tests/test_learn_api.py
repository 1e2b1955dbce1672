"""The notebook API of sctd.learn (keyword hyperparameters in, a skill out) and the
library's purity: no argument parsing, printing, file writing or I/O-layer imports."""

from __future__ import annotations

import argparse
import ast
import re
from pathlib import Path

import pytest

from sctd.cli.learn import add_learn_arguments
from sctd.learn import (
    STAGES,
    Demo,
    LinearIMLearner,
    VectorFieldLearner,
    get_params,
    hyperparameter_names,
    learn,
    learn_skill,
    skill_bundle,
)
from sctd.skill import Skill, skill_from_bundle
from sctd.task import find_task
from sctd_sim import demogen

ROOT = Path(__file__).resolve().parents[1]
LEARN = ROOT / "sctd" / "learn"
FORBIDDEN = {"argparse", "subprocess", "matplotlib", "zenoh", "pinocchio", "can", "cantools",
             "sctd_sim", "sctd_services"}
TIP = [0.0, 0.0, 0.12, 0.0, 0.0, 0.0, 1.0]


@pytest.fixture(scope="module")
def pour():
    ds = demogen.generate(find_task("pour"), 6, noise=0.001, outliers=0.05, seed=3)
    return [Demo(d.name, d.t, d.poses) for d in ds.demos]


def test_learn_skill_with_keywords(pour):
    stages: list[str] = []
    skill = learn_skill(pour, method="linear", name="pour", frames={"tip": TIP}, object="mug",
                        smoothness=0.005, random_state=0, progress=stages.append)
    assert isinstance(skill, Skill) and skill.object == "mug"
    assert [s.name for s in skill.states] == ["s0", "s1"]
    assert stages == list(STAGES["linear"])


def test_learn_vf_result_and_bundle(pour):
    result = learn(pour, method="vf", random_state=1, vf_max_n=4, angle_sphere=12.0)
    assert isinstance(result.learner, VectorFieldLearner) and result.learner.angle_sphere == 12.0
    bundle = skill_bundle(result, "pour-vf")
    assert set(bundle.files) == {"pour-vf.npz"}
    skill = skill_from_bundle(bundle)
    assert skill.states[0].input_mappings[0].max_n == 4
    assert result.hyperparameters()["random_state"] == 1


def test_unknown_or_misplaced_hyperparameters(pour):
    with pytest.raises(TypeError, match="n_fields"):
        learn(pour, method="linear", n_fields=3)
    with pytest.raises(TypeError, match="frames"):
        learn(pour, method="vf", frames={"tip": TIP})
    with pytest.raises(ValueError, match="method"):
        learn(pour, method="splines")
    assert "smoothness" in hyperparameter_names("linear")
    assert "vf_max_n" in hyperparameter_names("vf") and "smoothness" not in hyperparameter_names("vf")


def test_estimators_follow_the_get_params_convention():
    est = LinearIMLearner(smoothness=2.0)
    params = get_params(est)
    assert params["smoothness"] == 2.0 and params["random_state"] == 0
    assert LinearIMLearner(**params) == est


def test_every_hyperparameter_flag_of_sctd_learn():
    """Flags derived from the definitions: exactly those sctd learn always had, and the
    gripper events' (GripperOptions)."""
    parser = add_learn_arguments(argparse.ArgumentParser())
    flags = {s for a in parser._actions for s in a.option_strings} - {"-h", "--help"}
    assert flags == {
        "--method", "--out", "--frame", "--report", "--seed", "--object", "--quiet", "--spacing",
        "--vf-spacing", "--smooth", "--no-despike", "--alpha", "--beta", "--lambda", "--radius",
        "--max-n", "--C", "--cut", "--min-segment", "--axis-support", "--margin", "--dtw-align",
        "--no-auto-frames",
        "--n-fields", "--em-iterations", "--angle-sphere", "--angle-translation",
        "--angle-cylinder", "--angle-point", "--vf-models", "--coherence-run", "--max-radius",
        "--max-cylinder-radius", "--chance-weight",
        "--selection",
        "--demo-tolerance",
        "--general-bandwidth", "--general-parameters", "--min-v", "--max-d", "--k-s",
        "--vf-max-n", "--vf-motion", "--vf-rotation-weight", "--vf-combine", "--vf-direction", "--vf-states",
        "--vf-pivot-within", "--vf-arrive",
        "--max-linear-speed", "--max-angular-speed", "--speed-near",
        "--grasp-force", "--grasp-timeout", "--gripper-radius"}
    ns = parser.parse_args(["d", "--out", "x.yaml"])
    assert ns.smoothness == 0.005 and ns.random_state == 0 and ns.vf_max_n == 5 and ns.despike
    assert ns.models == ("translation", "cylinder", "sphere", "general")
    ns = parser.parse_args(["d", "--out", "x.yaml", "--vf-models", "translation, sphere"])
    assert ns.models == ("translation", "sphere")


def _modules_and_calls(path: Path) -> tuple[set[str], set[str]]:
    tree = ast.parse(path.read_text())
    mods: set[str] = set()
    calls: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            mods |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            mods.add(node.module.split(".")[0])
        elif isinstance(node, ast.Call):
            f = node.func
            calls.add(f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else "")
    return mods, calls


@pytest.mark.parametrize("path", sorted(LEARN.glob("*.py")), ids=lambda p: p.name)
def test_learn_is_a_plain_library(path):
    mods, calls = _modules_and_calls(path)
    assert not mods & FORBIDDEN
    assert not calls & {"print", "write_text", "write_bytes", "mkdir", "savefig", "tofile"}


def test_the_notebook_example_in_docs_runs(monkeypatch):
    text = (ROOT / "docs" / "learning.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S)
    assert code is not None
    monkeypatch.chdir(ROOT)
    scope: dict = {}
    exec(compile(code.group(1), "docs/learning.md", "exec"), scope)
    assert [s.input_mappings[0].frame for s in scope["skill"].states] == ["ee", "tip"]
