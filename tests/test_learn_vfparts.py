"""The vector-field learner's parts on their own: the coherence filter, the chance
correction of the MSAC score, one shape's RANSAC, the point of the hand a field's
steps turn about, and the point field of reaches."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sctd import se3
from sctd.learn.vfcoherence import coherent
from sctd.learn.vffields import Displacements, FieldAngles, point_field
from sctd.learn.vfframes import candidate_frames, turning_point
from sctd.learn.vfransac import Ransac, chance
from sctd.skill.fields import PointField, SphereField


def test_coherence_keeps_runs_of_consecutive_points_with_a_neighbour():
    demo = np.array([0] * 8 + [1] * 4)
    sample = np.array([0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3])
    points = np.zeros((12, 3))
    points[:, 0] = np.arange(12) * 0.01
    points[11] = [5.0, 0.0, 0.0]  # far from every other point
    assigned = np.array([1, 1, 0, 1, 1, 1, 0, 1, 0, 1, 1, 1], dtype=bool)
    keep = coherent(assigned, demo, sample, points, run=3, radius=0.05)
    # runs: [0, 1] too short, [3, 4, 5] kept, [7] too short; demo 1's [9, 10, 11] is a run,
    # but point 11 has no other kept point within 5 cm
    assert np.flatnonzero(keep).tolist() == [3, 4, 5, 9, 10]
    assert np.flatnonzero(coherent(assigned, demo, sample, points, run=1, radius=1.0)).tolist() == \
        np.flatnonzero(assigned[:11]).tolist()


def test_chance_is_the_mean_msac_score_of_a_random_direction():
    thr = math.radians(15.0)
    assert chance("sphere", thr) == math.sin(thr) * 2.0 / 3.0
    assert chance("translation", thr) == chance("cylinder", thr) == 0.25 * (1.0 - math.cos(thr))
    rng = np.random.default_rng(0)  # Monte Carlo: within 2 % of the translation's
    d = rng.normal(size=(400_000, 3))
    a = np.arccos(np.clip(d[:, 0] / np.linalg.norm(d, axis=1), -1.0, 1.0))
    mc = np.mean(np.where(a < thr, 1.0 - (a / thr) ** 2, 0.0))
    assert abs(mc - chance("translation", thr)) < 0.02 * chance("translation", thr)


def test_one_shapes_ransac_finds_a_planted_translation_among_outliers():
    rng = np.random.default_rng(3)
    n = 200
    p = rng.uniform(-0.2, 0.2, (n, 3))
    d = np.array([0.6, 0.0, 0.8])
    v = np.tile(d, (n, 1)) + rng.normal(0, 0.02, (n, 3))
    v[:60] = rng.normal(size=(60, 3))  # outliers
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    data = Displacements(p, v, np.tile([0.0, 0.0, 0.0, 1.0], (n, 1)), np.zeros(n, dtype=np.int64),
                         np.arange(n))
    ransac = Ransac({"translation": math.radians(25.0)}, 0.99, 0.7, 2, 0.5,
                    FieldAngles(data, 0.02, 0.3))
    f, inliers, score = ransac.fit("translation", p, v, rng)
    assert f is not None and f.type == "translation"
    assert math.degrees(math.acos(min(1.0, float(f.direction @ d)))) < 2.0
    assert inliers[60:].all() and inliers[:60].sum() < 10 and score > 0


def _tilted_about(point_ee, centre, angles, axis):
    """ee poses (R (n, 3, 3), p (n, 3)) turned by ``angles`` about ``axis`` (object
    frame) through ``centre``, where the point ``point_ee`` of the hand stays."""
    R = np.array([se3.matrix_from_rotvec(np.asarray(axis) * a) for a in angles])
    p = centre - np.einsum("nij,j->ni", R, point_ee)
    return R, p


def test_the_turning_point_is_the_point_of_the_hand_that_stays_put():
    """Tilts about a cup's rim, among steps that only carry the hand and steps of an arm
    that overshoots (turning and moving at once): the rim comes back to 0.1 mm; along
    the axis it always turned about, the point nearest the hand's origin."""
    rng = np.random.default_rng(0)
    rim = np.array([0.035, 0.0, 0.10])
    R1, p1 = _tilted_about(rim, np.array([0.01, 0.0, 0.01]), np.linspace(0.0, 1.0, 40), [0, 1, 0])
    R2, p2 = _tilted_about(rim, np.array([0.02, 0.01, 0.0]), np.linspace(0.9, 0.0, 30), [0, 1, 0])
    carried = np.repeat(R1[:1], 20, axis=0), p1[0] + np.linspace(0.2, 0.0, 20)[:, None] * [1.0, 0.0, 0.0]
    R = np.concatenate([carried[0], R1, R2])
    p = np.concatenate([carried[1], p1, p2]) + rng.normal(0.0, 2e-5, (90, 3))
    # an overshooting arm: six steps that turn and slide at once
    p[25:31] += np.linspace(0.0, 0.01, 6)[:, None] * [-1.0, 0.0, 0.5]
    steps = np.array([i for i in range(89) if i not in (19, 59)])  # (a demonstration ends at 59)
    start = np.array([0.03, 0.02, 0.09])
    x = turning_point(R, p, steps, start)
    assert abs(x[0] - rim[0]) < 1e-4 and abs(x[2] - rim[2]) < 1e-4
    assert abs(x[1]) < 1e-3  # along the turning axis: free, nearest the hand's origin
    # turned about two axes: the point is fixed in all three directions
    R3, p3 = _tilted_about(rim, np.array([0.0, 0.0, 0.0]), np.linspace(0.0, 0.8, 30), [1, 0, 0])
    R = np.concatenate([R1, R3])
    p = np.concatenate([p1, p3])
    x = turning_point(R, p, np.array([i for i in range(69) if i != 39]), start)
    np.testing.assert_allclose(x, rim, atol=1e-9)
    assert np.array_equal(turning_point(R, p, np.array([], dtype=int), start), start)


def test_a_sphere_turned_about_a_rim_is_centred_on_it():
    """Tilts about a cup's rim, all about one axis (the hand's y), fitted by a sphere whose
    centre the arcs leave free along that axis and which the fit put 6 cm aside: the
    candidate frame and the field end up centred where the rim was, the pivot on the rim,
    the radius the hand's distance from it."""
    rim = np.array([0.035, 0.0, 0.10])
    at = np.array([0.01, 0.0, 0.01])
    R, p = _tilted_about(rim, at, np.linspace(0.0, 1.0, 40), [0, 1, 0])
    aside = at + np.array([0.0, 0.06, 0.0])
    fitted = SphereField(centre=aside, radius=float(np.linalg.norm(p[0] - aside)), weight=1.0)
    q = se3.quaternion_from_matrix(R)
    frames, fields = candidate_frames([fitted], np.zeros(40, dtype=np.int64), p, q, 0.02,
                                      np.arange(39))
    f = fields[0]
    assert isinstance(f, SphereField) and f.pivot is not None
    np.testing.assert_allclose(f.pivot, rim, atol=1e-6)
    np.testing.assert_allclose(f.centre, at, atol=1e-6)
    assert f.radius is not None and abs(f.radius - np.linalg.norm(rim)) < 1e-6
    assert frames[0]["position"] == [round(float(x), 6) for x in at]
    np.testing.assert_allclose(frames[0]["ee_offset"], rim, atol=1e-6)
    assert frames[0]["ee_offset_spread"] < 1e-6


# --- the point field: a reach's goal ---------------------------------------------------


def _reaches(rng, goal, n=8, steps=20, spread=0.15):
    """Straight reaches from starts scattered about ``goal`` onto it, with small noise:
    their chords' points and unit directions."""
    P, V = [], []
    for _ in range(n):
        start = goal + rng.normal(0.0, spread, 3) + [0.25, 0.0, 0.0]
        line = start + np.linspace(0.0, 0.9, steps)[:, None] * (goal - start)
        line += rng.normal(0.0, 0.0002, line.shape)
        d = np.diff(line, axis=0)
        P.append(0.5 * (line[1:] + line[:-1]))
        V.append(d / np.linalg.norm(d, axis=1, keepdims=True))
    return np.concatenate(P), np.concatenate(V)


@pytest.mark.parametrize("seed", range(5))
def test_the_point_field_of_reaches_is_their_goal(seed):
    """Reaches from scattered starts onto one goal give it back by least squares, and
    a RANSAC among 30 % outliers finds it as well; the directions agree with the field
    (median deviation under 2 degrees)."""
    rng = np.random.default_rng(seed)
    goal = rng.uniform(-0.1, 0.1, 3)
    p, v = _reaches(rng, goal)
    f = point_field(p, v)
    assert isinstance(f, PointField) and np.linalg.norm(f.point - goal) < 0.003
    assert np.median(np.degrees(f.deviation_angles(p, v))) < 2.0
    n = len(p)
    k = int(0.3 * n / 0.7)
    p_all = np.concatenate([p, rng.uniform(-0.3, 0.3, (k, 3))])
    v_all = np.concatenate([v, rng.normal(size=(k, 3))])
    v_all /= np.linalg.norm(v_all, axis=1, keepdims=True)
    data = Displacements(p_all, v_all, np.tile([0.0, 0.0, 0.0, 1.0], (len(p_all), 1)),
                         np.zeros(len(p_all), dtype=np.int64), np.arange(len(p_all)))
    ransac = Ransac({"point": math.radians(25.0)}, 0.99, 0.7, 2, 0.5, FieldAngles(data, 0.02, 0.3))
    g, inliers, _ = ransac.fit("point", p_all, v_all, rng)
    assert g is not None and np.linalg.norm(g.point - goal) < 0.005
    assert inliers[:n].mean() > 0.95 and inliers[n:].mean() < 0.2


def test_parallel_or_departing_lines_have_no_point():
    """Lines that never meet are a translation; motion away from where the lines meet
    reaches no goal: neither gives a point field."""
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.2, 0.2, (50, 3))
    assert point_field(p, np.tile([0.0, 0.6, 0.8], (50, 1))) is None
    goal = np.zeros(3)
    away = (p - goal) / np.linalg.norm(p - goal, axis=1, keepdims=True)
    assert point_field(p, away) is None
    assert point_field(p, -away) is not None


def test_the_point_fields_direction_is_the_same_on_floats_and_arrays():
    rng = np.random.default_rng(1)
    f = PointField(point=np.array([0.1, -0.05, 0.2]))
    pts = rng.uniform(-0.3, 0.3, (50, 3))
    pts[0] = f.point + np.array([0.0005, 0.0, 0.0])  # within POINT_UNDEFINED: no direction
    V = f.vectors(pts)
    for x, row in zip(pts, V, strict=True):
        np.testing.assert_allclose(f.vector3(*x.tolist()), row, atol=1e-12)
    assert not V[0].any() and np.allclose(np.linalg.norm(V[1:], axis=1), 1.0)
    ahead = (f.point - pts[1]) / np.linalg.norm(f.point - pts[1])
    assert f.agreement3(tuple(pts[1]), tuple(ahead)) == pytest.approx(1.0)
