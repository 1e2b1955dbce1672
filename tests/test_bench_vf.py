"""`sctd bench vf`: the resized models keep the learned skill's fields and paths, and the
command reports a row per point count (its figures are for the docs; the suite asserts
no times)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd.bench.vf import DEMO_GAP, resized_model, resized_skill
from sctd.skill import SkillEngine, load_skill
from tests.conftest import ROOT

POUR_VF = ROOT / "skills" / "pour-vf.yaml"


@pytest.fixture(scope="module")
def model():
    return load_skill(POUR_VF).states[0].input_mappings[0].model


@given(n=st.integers(1, 6000))
@settings(max_examples=25, deadline=None)
def test_a_resized_model_has_the_points_asked_for_on_the_demonstrations_paths(model, n):
    m = resized_model(model, n)
    assert len(m.points) == len(m.quaternions) == len(m.responsibilities) == n
    assert m.fields == model.fields
    assert np.allclose(np.linalg.norm(m.quaternions, axis=1), 1.0)
    assert np.allclose(m.responsibilities.sum(axis=1), 1.0)  # as the learned ones
    original = {tuple(p) for p in model.points.tolist()}
    if n <= len(model.points):  # a subset, in order
        assert all(tuple(p) in original for p in m.points.tolist())
        return
    assert original <= {tuple(p) for p in m.points.tolist()}  # every learned point kept
    # every added point lies on the segment between two consecutive points of one demonstration
    a, b = model.points[:-1], model.points[1:]
    inner = np.linalg.norm(b - a, axis=1) < DEMO_GAP
    a, b = a[inner], b[inner]
    ab = b - a
    for p in m.points[np.random.default_rng(0).choice(n, 50, replace=False)]:
        t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
        assert np.min(np.linalg.norm(a + t[:, None] * ab - p, axis=1)) < 1e-9


def test_a_resized_skill_loads_and_runs(tmp_path, model):
    path = resized_skill(str(POUR_VF), 2000, tmp_path)
    skill = load_skill(path)
    assert len(skill.states[0].input_mappings[0].model.points) == 2000
    assert len(skill.states[0].active_constraints[0].model.points) == 2000
    eng = SkillEngine(skill)
    F = eng.command((1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, *(model.points[40] - [0, 0, 0.12])),
                    (0.5, 0.2, 0.0), 0.001)
    assert all(np.isfinite(F))


@pytest.mark.slow
def test_bench_vf_reports_every_point_count_next_to_the_baseline():
    out = subprocess.run([sys.executable, "-m", "sctd.cli.main", "bench", "vf", "--points", "100,700",
                          "--ticks", "60", "--rounds", "1", "--json"],
                         capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert [row["points"] for row in r["rows"]] == [100, 700]
    assert r["baseline_tick_ms"]["n"] == 60
    for row in r["rows"]:
        h = row["tick_ms"]
        assert h["n"] == 60 and 0 < h["p50"] <= h["p99"] <= h["max"]


@pytest.mark.slow
def test_bench_vf_names_a_bad_point_list():
    out = subprocess.run([sys.executable, "-m", "sctd.cli.main", "bench", "vf", "--points", "100,x"],
                         capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert out.returncode != 0 and "--points" in out.stderr and "100,x" in out.stderr
