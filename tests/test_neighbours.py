"""The tick's neighbour queries (answered from points fetched around the frame) give the
answers of the whole model, computed directly."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import sctd.skill.neighbours as neighbours_module
from sctd.skill import TranslationField, VectorFieldModel
from sctd.skill.neighbours import POSE_CANDIDATES, Neighbours


def random_model(seed: int, n: int, fields: int = 3) -> VectorFieldModel:
    """``n`` points along a few noisy random walks (demonstrations), random unit
    quaternions and responsibilities."""
    rng = np.random.default_rng(seed)
    walks = rng.normal(scale=0.004, size=(n, 3)).cumsum(axis=0)
    points = walks + rng.normal(scale=0.002, size=(n, 3))
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    resp = rng.random((n, fields)) + 1e-3
    resp /= resp.sum(axis=1, keepdims=True)
    fs = tuple(TranslationField(direction=np.array([1.0, 0.0, 0.0]), weight=1.0 + k) for k in range(fields))
    return VectorFieldModel(fs, points, q, resp)


def direct(model: VectorFieldModel, p, k: int, max_d: float) -> tuple[np.ndarray, np.ndarray]:
    """Indices (nearest first) and distances of the up to k points within max_d of p,
    over every point."""
    d = np.sqrt(np.sum((model.points - np.asarray(p)) ** 2, axis=1))
    order = np.argsort(d, kind="stable")
    order = order[d[order] < max_d][:k]
    return order, d[order]


def weights(d: np.ndarray) -> np.ndarray:
    w = 1.0 / (d + 1e-3)
    return w / w.sum()


def direct_membership(model, prior, p, k, max_d) -> np.ndarray:
    i, d = direct(model, p, k, max_d)
    if len(i) == 0:
        return prior
    r = weights(d) @ model.responsibilities[i]
    return r / r.sum()


def direct_pose(model, p, q, k, max_d, rotation_weight) -> tuple[np.ndarray, np.ndarray]:
    i, d = direct(model, p, POSE_CANDIDATES * k, max_d)
    angle = 2.0 * np.arccos(np.clip(np.abs(model.quaternions[i] @ np.asarray(q)), 0.0, 1.0))
    dist = np.sqrt(d * d + (rotation_weight * angle) ** 2)
    best = np.argsort(dist, kind="stable")[:k]
    return i[best], weights(dist[best]) if len(best) else dist[best]


def walk(seed: int, model: VectorFieldModel, steps: int, step: float):
    """A path from near the model's first point, ``step`` m per move, turning slowly."""
    rng = np.random.default_rng(seed + 1)
    p = model.points[0] + rng.normal(scale=0.005, size=3)
    heading = rng.normal(size=3)
    q = np.array([0.0, 0.0, 0.0, 1.0])
    for _ in range(steps):
        heading += rng.normal(scale=0.3, size=3)
        p = p + step * heading / np.linalg.norm(heading)
        q = q + rng.normal(scale=0.01, size=4)
        q /= np.linalg.norm(q)
        yield tuple(p.tolist()), tuple(q.tolist())


@pytest.fixture
def no_reuse(monkeypatch):
    """Every query answered anew (the reuse of answers is a separate matter)."""
    monkeypatch.setattr(neighbours_module, "REUSE_DISTANCE", 0.0)
    monkeypatch.setattr(neighbours_module, "REUSE_ANGLE", 0.0)


@given(seed=st.integers(0, 10_000), n=st.sampled_from([1, 7, 60, 300, 2000]),
       max_n=st.integers(1, 8), max_d=st.sampled_from([0.002, 0.01, 0.05, 0.15]),
       step=st.sampled_from([1e-4, 1e-3, 1e-2]), rotation_weight=st.sampled_from([0.0, 0.1, 1.0]))
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
def test_answers_equal_the_direct_computation_over_every_point(no_reuse, seed, n, max_n, max_d, step,
                                                               rotation_weight):
    model = random_model(seed, n)
    nb = Neighbours(model)
    for p, q in walk(seed, model, 40, step):
        i, w = nb.query(p, max_n, max_d)
        i_ref, d_ref = direct(model, p, max_n, max_d)
        assert np.array_equal(i, i_ref)
        assert np.allclose(w, weights(d_ref), rtol=1e-9, atol=0.0)
        assert np.allclose(nb.membership(p, max_n, max_d),
                           direct_membership(model, nb.prior, p, max_n, max_d), rtol=1e-9, atol=1e-15)
        i, w = nb.query_pose(p, q, max_n, max_d, rotation_weight)
        i_ref, w_ref = direct_pose(model, p, q, max_n, max_d, rotation_weight)
        assert np.array_equal(i, i_ref)
        assert np.allclose(w, w_ref, rtol=1e-9, atol=0.0)
        mean = nb.mean_orientation((i, w))
        if len(i) == 0:
            assert mean is None
        else:
            qs = model.quaternions[i]
            qs = qs * np.where(qs @ qs[0] < 0.0, -1.0, 1.0)[:, None]
            assert np.allclose(mean, w @ qs, rtol=1e-9, atol=1e-15)


def test_the_tree_is_asked_rarely_on_a_slow_path_through_a_dense_model(no_reuse):
    """At 0.1 mm per query (the speed limit at 1 kHz) through 20,000 points, the points
    fetched around the frame answer hundreds of queries per KD-tree query."""
    model = random_model(3, 20_000)
    nb = Neighbours(model)
    for p, q in walk(3, model, 2000, 1e-4):
        nb.membership(p, 5, 0.15)
        nb.query_pose(p, q, 5, 0.15, 0.1)
    assert nb.queries == 4000
    assert nb.fetches < 4000 / 100, nb.fetches


def test_two_kinds_of_query_asking_for_means_in_turn_have_each_mean_worked_out_once():
    """A mapping's position query and a constraint's pose query ask for the mean
    orientation of their answers in turn every tick: while each answer is reused, its
    mean is the one worked out the first time (the same tuple), not worked out again."""
    model = random_model(7, 500)
    nb = Neighbours(model)
    p = tuple(model.points[20].tolist())
    q = tuple(model.quaternions[20].tolist())
    a, b = nb.query(p, 5, 0.15), nb.query_pose(p, q, 5, 0.15, 0.1)
    first = nb.mean_orientation(a), nb.mean_orientation(b)
    assert first[0] is not None and first[1] is not None
    for _ in range(3):  # the same place: both answers are reused, and so are their means
        assert nb.query(p, 5, 0.15) is a and nb.query_pose(p, q, 5, 0.15, 0.1) is b
        assert nb.mean_orientation(a) is first[0] and nb.mean_orientation(b) is first[1]


def test_far_from_every_point_the_answer_is_empty_and_membership_the_prior(no_reuse):
    model = random_model(5, 500)
    nb = Neighbours(model)
    far = tuple((model.points.max(axis=0) + 1.0).tolist())
    i, w = nb.query(far, 5, 0.15)
    assert len(i) == 0 and len(w) == 0
    assert np.array_equal(nb.membership(far, 5, 0.15), nb.prior)
    i, w = nb.query_pose(far, (0.0, 0.0, 0.0, 1.0), 5, 0.15, 0.1)
    assert len(i) == 0 and nb.mean_orientation((i, w)) is None
    # and back near the points, the answers are the direct ones again
    p = tuple(model.points[10].tolist())
    assert np.array_equal(nb.query(p, 5, 0.15)[0], direct(model, p, 5, 0.15)[0])


def test_a_fetched_set_proves_its_answer_or_declines():
    """A set's answer at a point beyond its proof (the reach less the distance from its
    centre) is declined, not guessed."""
    model = random_model(7, 1000)
    nb = Neighbours(model)
    centre = tuple(model.points[500].tolist())
    fetched = neighbours_module._Fetched(model, nb.tree, centre, 64)
    rows, d2 = fetched.nearest(centre, 5, 0.15)
    assert [fetched.index[j] for j in rows] == direct(model, centre, 5, 0.15)[0].tolist()
    assert math.isclose(math.sqrt(d2[-1]), direct(model, centre, 5, 0.15)[1][-1], rel_tol=1e-9)
    away = (centre[0] + fetched.reach, centre[1], centre[2])
    assert fetched.nearest(away, 5, 0.15) is None


# --- answers worked out ahead between ticks (Neighbours.refresh) -------------------------


@settings(max_examples=25, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 1000), st.floats(1e-5, 4e-4))
def test_refreshed_answers_are_answers_made_within_reuse_of_the_query(seed, step):
    model = random_model(seed, 600)
    nb = Neighbours(model)
    for p, q in walk(seed, model, 60, step):
        i, w = nb.query(p, 5, 0.05)
        anchor, _, _ = nb._last[("query", 5, 0.05)]
        assert math.dist(anchor, p) <= neighbours_module.REUSE_DISTANCE
        ei, ed = direct(model, anchor, 5, 0.05)
        assert list(i) == list(ei)
        np.testing.assert_allclose(w, weights(ed), rtol=1e-9)
        pi, pw = nb.query_pose(p, q, 5, 0.05, 0.1)
        anchor, q_anchor, _ = nb._last[("pose", 5, 0.05, 0.1)]
        ei, ew = direct_pose(model, anchor, q_anchor, 5, 0.05, 0.1)
        assert list(pi) == list(ei)
        np.testing.assert_allclose(pw, ew, rtol=1e-9)
        np.testing.assert_allclose(m := nb.membership(p, 5, 0.05),
                                   direct_membership(model, nb.prior, nb._last[("membership", 5, 0.05)][0],
                                                     5, 0.05), rtol=1e-9)
        assert abs(float(np.sum(m)) - 1.0) < 1e-9
        nb.refresh()


def test_at_the_speed_limit_the_queries_themselves_work_nothing_out():
    """0.1 mm per tick (0.1 m/s at 1 kHz): after the first answer, every answer is worked
    out by refresh between ticks, none by the tick's own query."""
    model = random_model(3, 2000)
    nb = Neighbours(model)
    for k, (p, _) in enumerate(walk(3, model, 400, 1e-4)):
        nb.membership(p, 5, 0.05)
        if k == 0:
            assert nb.queries == 1
        nb.refresh()
    assert nb.queries == 1 and nb.refreshes > 10
