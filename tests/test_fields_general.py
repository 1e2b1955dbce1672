"""The general (non-parametric) vector field: what the tick evaluates equals what the
learner evaluates, it is always defined and finite, and a model file keeps it."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sctd.learn.vf import general_field, held_out_angles
from sctd.skill import SkillError
from sctd.skill.fields import Field, GeneralField
from sctd.skill.modelfile import VectorFieldModel, vector_field_model_from_bytes, vector_field_model_to_bytes


def _s_curve(n=200, seed=0):
    rng = np.random.default_rng(seed)
    x = np.linspace(-0.15, 0.15, n)
    k = 2 * np.pi / 0.3
    p = np.stack([x, 0.05 * np.sin(k * x), np.zeros(n)], axis=1)
    v = np.stack([np.ones(n), 0.05 * k * np.cos(k * x), np.zeros(n)], axis=1)
    v += rng.normal(0, 0.05, v.shape)  # a few degrees of noise on the directions
    return p + rng.normal(0, 0.0005, p.shape), v / np.linalg.norm(v, axis=1, keepdims=True)


FIELD = general_field(*_s_curve())
coord = st.floats(-0.5, 0.5, allow_nan=False)


@given(coord, coord, coord)
def test_tick_evaluation_equals_the_learners(x, y, z):
    assert isinstance(FIELD, GeneralField)
    FIELD._last[0] = None  # a fresh query (no reuse)
    g = FIELD.vector3(x, y, z)
    np.testing.assert_allclose(g, FIELD.vectors([[x, y, z]])[0], atol=1e-9)
    assert all(np.isfinite(g)) and abs(np.linalg.norm(g) - 1.0) < 1e-9


@given(coord, coord, coord, st.floats(0.0, 4e-4))
def test_a_reused_query_stays_within_its_neighbours(x, y, z, dx):
    FIELD._last[0] = None
    FIELD.vector3(x, y, z)
    g = FIELD.vector3(x + dx, y, z)  # reuses the 8 neighbours of the first point
    assert all(np.isfinite(g)) and abs(np.linalg.norm(g) - 1.0) < 1e-9


def test_it_follows_the_demonstrated_curve():
    x = np.linspace(-0.14, 0.14, 50)
    k = 2 * np.pi / 0.3
    p = np.stack([x, 0.05 * np.sin(k * x), np.zeros(50)], axis=1)
    t = np.stack([np.ones(50), 0.05 * k * np.cos(k * x), np.zeros(50)], axis=1)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    g = FIELD.vectors(p)
    assert np.degrees(np.arccos(np.clip(np.sum(g * t, axis=1), -1, 1))).max() < 10.0


def test_its_size_is_bounded_by_the_space_covered_not_the_points():
    small, big = general_field(*_s_curve(200)), general_field(*_s_curve(20000))
    assert len(big.centres) <= 2 * len(small.centres)  # 100x the points


def test_held_out_angles_ignore_a_points_own_demonstration():
    p, v = _s_curve(100)
    demo = np.zeros(100, dtype=np.int64)
    assert np.all(held_out_angles(p, v, demo, 0.02) == np.pi / 2)  # no other demonstration
    demo[::2] = 1
    assert np.degrees(held_out_angles(p, v, demo, 0.02)).max() < 15.0


@pytest.mark.parametrize("rel", ["m.npz", "m.json"])
def test_model_files_keep_a_general_field(rel):
    p, _ = _s_curve()
    K = 1
    model = VectorFieldModel(fields=(FIELD,), points=p, quaternions=np.tile([0, 0, 0, 1.0], (len(p), 1)),
                             responsibilities=np.ones((len(p), K)))
    back = vector_field_model_from_bytes(vector_field_model_to_bytes(model, rel), rel, "m")
    g = back.fields[0]
    assert isinstance(g, GeneralField) and g.bandwidth == FIELD.bandwidth
    np.testing.assert_allclose(g.vectors(p), FIELD.vectors(p), atol=1e-9)


@pytest.mark.parametrize(("doc", "where"), [
    ({"type": "general", "centres": [[0, 0, 0]], "directions": [[1, 0, 0], [0, 1, 0]]}, "directions"),
    ({"type": "general", "centres": [], "directions": []}, "centres"),
    ({"type": "general", "centres": [[0, 0, float("nan")]], "directions": [[1, 0, 0]]}, "centres[0]"),
    ({"type": "general", "centres": [[0, 0, 0]], "directions": [[1, 0, 0]], "bandwidth": 0}, "bandwidth"),
])
def test_a_malformed_general_field_is_refused_naming_where(doc, where):
    with pytest.raises(SkillError) as e:
        Field.from_yaml(doc, "fields[0]", "m.npz")
    assert f"fields[0].{where}" in str(e.value)


def test_the_brief_summary_counts_the_centres():
    b = FIELD.brief()
    assert b["type"] == "general" and b["centres"] == len(FIELD.centres) and "directions" not in b
