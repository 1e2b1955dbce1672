"""The vector-field learner's parts on their own: the coherence filter, the chance
correction of the MSAC score, and one shape's RANSAC."""

from __future__ import annotations

import math

import numpy as np

from sctd.learn.vfcoherence import coherent
from sctd.learn.vffields import Displacements, FieldAngles
from sctd.learn.vfransac import Ransac, chance


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
