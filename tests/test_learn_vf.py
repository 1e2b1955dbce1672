"""Vector fields (Ch. 4.2): RANSAC finds planted fields under outliers for every seed,
least-squares refinement keeps centres stable, EM and the generated tasks."""

from __future__ import annotations

import numpy as np
import pytest

from sctd.bench.demos import demo_kind
from sctd.learn import Demo, VectorFieldLearner, field_kinds_by_phase, learn_vector_fields, ransac_iterations
from sctd.learn.vf import DEFAULT_FIELDS, cylinder_field, sphere_field
from sctd.task import find_task
from sctd_sim import demogen
from tests.shipped import assert_same_models


def _arcs(rng, centre, n_arcs=6, radius=0.12, steps=25):
    """Trajectories on great-circle arcs about ``centre`` with different axes."""
    out = []
    for _ in range(n_arcs):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        start = np.cross(axis, rng.normal(size=3))
        start = radius * start / np.linalg.norm(start)
        ang = np.linspace(0, 1.5, steps)
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        pts = [centre + (np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K) @ start for a in ang]
        out.append(np.array(pts) + rng.normal(0, 0.0005, (steps, 3)))
    return out


def _with_outliers(rng, trajs, frac=0.3):
    """Add random-walk trajectories (outliers) making up ``frac`` of the points."""
    n = sum(len(t) for t in trajs)
    k = int(frac / (1 - frac) * n)
    walk = np.cumsum(rng.normal(0, 0.01, (k, 3)), axis=0) + rng.uniform(-0.3, 0.3, 3)
    return [*trajs, walk]


@pytest.mark.parametrize("seed", range(10))
def test_ransac_finds_planted_sphere_under_outliers(seed):
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-0.2, 0.2, 3)
    trajs = _with_outliers(rng, _arcs(rng, centre))
    vf = VectorFieldLearner(n_fields=1, random_state=seed).fit(trajs)
    f = vf.ransac_fields_[0]
    assert f.type == "sphere"
    assert np.linalg.norm(f.centre - centre) < 0.005
    assert np.linalg.norm(vf.fields_[0].centre - centre) < 0.005


@pytest.mark.parametrize("seed", range(10))
def test_ransac_finds_planted_translation_under_outliers(seed):
    rng = np.random.default_rng(100 + seed)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    trajs = [rng.uniform(-0.2, 0.2, 3) + np.outer(np.linspace(0, 0.3, 30), d)
             + rng.normal(0, 0.001, (30, 3)) for _ in range(5)]
    vf = VectorFieldLearner(n_fields=1, random_state=seed).fit(_with_outliers(rng, trajs))
    f = vf.fields_[0]
    assert f.type == "translation"
    assert np.degrees(np.arccos(np.clip(f.direction @ d, -1, 1))) < 3.0


def test_cylinder_and_sphere_least_squares_are_exact():
    rng = np.random.default_rng(0)
    axis = np.array([0.0, 0.6, 0.8])
    point = np.array([0.1, -0.2, 0.3])
    p = point + rng.normal(size=(40, 3)) * 0.1
    v = np.cross(axis, p - point)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    f = cylinder_field(p, v)
    np.testing.assert_allclose(f.axis, axis, atol=1e-9)
    assert np.linalg.norm(np.cross(f.point - point, axis)) < 1e-9  # on the axis line
    c = np.array([0.05, 0.0, 0.1])
    q = c + rng.normal(size=(40, 3)) * 0.1
    t = np.cross(rng.normal(size=(40, 3)), q - c)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    np.testing.assert_allclose(sphere_field(q, t).centre, c, atol=1e-9)


def test_ransac_iterations_eq_4_23():
    assert ransac_iterations(0.99, 0.5, 1) == 7
    assert ransac_iterations(0.99, 0.5, 3) == 35
    assert ransac_iterations(0.99, 0.0, 3) == 1
    with pytest.raises(ValueError):
        ransac_iterations(0.99, 1.0, 2)


def test_pour_sphere_centre_is_stable_and_gives_the_tip():
    ds = demogen.generate(find_task("pour"), 8, noise=0.001, outliers=0.05, seed=5)
    demos = [Demo(d.name, d.t, d.poses) for d in ds.demos]
    truth = np.asarray(ds.truth["sphere_centre"])
    centres = []
    for s in range(3):
        res = learn_vector_fields(demos, learner=VectorFieldLearner(random_state=s))
        kinds = sorted(f.type for f in res.learner.fields_)
        assert kinds == ["sphere", "translation"]
        sph = next(f for f in res.learner.fields_ if f.type == "sphere")
        centres.append(sph.centre)
        cf = res.learner.candidate_frames_[0]
        np.testing.assert_allclose(cf["ee_offset"], ds.truth["tip_offset"], atol=0.01)
        r = res.learner.responsibilities_
        np.testing.assert_allclose(r.sum(axis=1), 1.0)
    C = np.array(centres)
    assert np.linalg.norm(C - truth, axis=1).max() < 0.005
    assert np.linalg.norm(C - C.mean(axis=0), axis=1).max() < 0.002


def test_drawer_two_translation_fields():
    ds = demogen.generate(find_task("drawer"), 8, noise=0.001, outliers=0.05, seed=6)
    demos = [Demo(d.name, d.t, d.poses) for d in ds.demos]
    res = learn_vector_fields(demos, learner=VectorFieldLearner(random_state=0))
    dirs = [f.direction for f in res.learner.fields_ if f.type == "translation"]
    assert len(dirs) == 2
    for true in ds.truth["directions"].values():
        err = min(np.degrees(np.arccos(np.clip(d @ np.asarray(true), -1, 1))) for d in dirs)
        assert err < 5.0


# --- model selection: the field each phase of a generated task is -----------------------


def _phase_kinds(task: str, seed: int, **kw):
    """The learner's fields and, per phase of the generated task, the kind of field
    most of its displacements were assigned to."""
    ds = demogen.generate(demo_kind(task), 10, noise=0.001, outliers=0.05, seed=seed)
    demos = [Demo(d.name, d.t, d.poses) for d in ds.demos]
    res = learn_vector_fields(demos, learner=VectorFieldLearner(random_state=seed, **kw))
    kinds = field_kinds_by_phase(res.field_labels, [f.type for f in res.learner.fields_],
                                 ds.truth["labels"], len(ds.truth["phases"]))
    return ds, res, kinds


@pytest.mark.parametrize("seed", range(8))
def test_crank_is_a_cylinder_about_its_axis_not_a_sphere(seed):
    _, res, kinds = _phase_kinds("crank", seed)
    assert kinds == ("translation", "cylinder")
    cyl = next(f for f in res.learner.fields_ if f.type == "cylinder")
    assert np.degrees(np.arccos(abs(cyl.axis @ [0.0, 0.0, 1.0]))) < 3.0
    assert np.hypot(*cyl.point[:2]) < 0.01  # on the vertical axis through the origin
    assert not any(f.type == "sphere" for f in res.learner.fields_)


@pytest.mark.parametrize("seed", range(6))
def test_pour_stays_a_sphere_and_drawer_two_translations(seed):
    assert _phase_kinds("pour", seed)[2] == ("translation", "sphere")
    assert _phase_kinds("drawer", seed)[2] == ("translation", "translation")


WITH_POINT = (*DEFAULT_FIELDS, "point")


@pytest.mark.parametrize("seed", range(6))
def test_with_the_point_field_a_reach_is_motion_to_its_goal(seed):
    """``--vf-models ...,point``: the generated reaches, from starts scattered over +-45
    deg onto the handle (drawer) or the crank's handle, are a point field at the goal
    (the drawer's handle is the object's origin), sharper than the translation that
    stands for them without it; the pull and the turn stay what they were."""
    _, res, kinds = _phase_kinds("drawer", seed, models=WITH_POINT)
    assert kinds == ("point", "translation")
    (pt,) = [f for f in res.learner.fields_ if f.type == "point"]
    assert np.linalg.norm(pt.point) < 0.02
    _, plain, _ = _phase_kinds("drawer", seed)
    (reach,) = [f for f in plain.learner.fields_ if f.type == "translation" and f.direction[0] < 0]
    assert pt.sigma < reach.sigma
    _, res, kinds = _phase_kinds("crank", seed, models=WITH_POINT)
    assert kinds == ("point", "cylinder")


@pytest.mark.parametrize("seed", range(6))
def test_wipe_is_a_general_field_after_a_translation(seed):
    _, res, kinds = _phase_kinds("wipe", seed)
    assert kinds == ("translation", "general")
    g = next(f for f in res.learner.fields_ if f.type == "general")
    assert np.all(np.isfinite(g.centres)) and len(g.centres) == len(g.directions)


def test_the_thesis_inlier_score_still_takes_the_crank_for_a_sphere():
    """The known weakness the likelihood fixes: by inliers, some seed's crank has no
    cylinder (a sphere centred on the axis fits at least as well)."""
    found = [_phase_kinds("crank", s, selection="inliers")[2][1] for s in range(4)]
    assert any(k != "cylinder" for k in found)


def test_a_sphere_of_planted_arcs_about_random_axes_beats_every_cylinder():
    rng = np.random.default_rng(3)
    centre = np.array([0.05, -0.02, 0.1])
    vf = VectorFieldLearner(n_fields=1, random_state=3).fit(_arcs(rng, centre, n_arcs=8))
    assert vf.ransac_fields_[0].type == "sphere"
    assert np.linalg.norm(vf.fields_[0].centre - centre) < 0.005


def test_a_cylinder_of_planted_arcs_about_one_axis_beats_the_sphere():
    rng = np.random.default_rng(4)
    axis = np.array([0.0, 0.6, 0.8])
    point = np.array([0.1, -0.2, 0.3])
    trajs = []
    e1 = np.cross(axis, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    for _ in range(6):
        r, h, a0 = rng.uniform(0.12, 0.2), rng.uniform(-0.05, 0.05), rng.uniform(0, 2 * np.pi)
        a = a0 + np.linspace(0, 1.5, 30)
        pts = point + h * axis + r * (np.cos(a)[:, None] * e1 + np.sin(a)[:, None] * e2)
        trajs.append(pts + rng.normal(0, 0.0005, pts.shape))
    vf = VectorFieldLearner(n_fields=1, random_state=4).fit(trajs)
    f = vf.fields_[0]
    assert f.type == "cylinder"
    assert np.degrees(np.arccos(abs(f.axis @ axis))) < 2.0


def test_the_pour_pivot_is_the_bottle_tip():
    """The sphere's pivot is the point of the hand the tilts turn about: the bottle's
    tip, to a millimetre along the hand's x and z (every tilt turns about the
    hand's y, which leaves the point free along it: there it is the sphere centre's mean
    offset, to 2 mm)."""
    ds = demogen.generate(find_task("pour"), 8, noise=0.001, outliers=0.05, seed=5)
    demos = [Demo(d.name, d.t, d.poses) for d in ds.demos]
    res = learn_vector_fields(demos, learner=VectorFieldLearner(random_state=0))
    sph = next(f for f in res.learner.fields_ if f.type == "sphere")
    tip = np.asarray(ds.truth["tip_offset"])
    np.testing.assert_allclose(sph.pivot[[0, 2]], tip[[0, 2]], atol=1e-3)
    np.testing.assert_allclose(sph.pivot, tip, atol=2e-3)


def test_the_shipped_drink_is_learned_with_arrive_on_its_rims_sphere():
    """``skills/drink-vf.yaml`` is what the learner writes from the drink's taught
    demonstrations with ``vf_arrive`` (its README's command): ``arrive`` on the mapping
    whose sphere turns the cup about its rim; without the option, none."""
    from sctd.learn import learn, read_demos, skill_bundle
    from sctd.skill import load_skill, skill_from_bundle
    from sctd.skill.catalog import shipped_folder

    demos = read_demos(shipped_folder() / "demos" / "drink")
    common = {"object": "mouth", "random_state": 0, "vf_direction": "both",
              "speed_near": "0.10:0.03:0.3:0.035,0,0.10"}
    bundle = skill_bundle(learn(demos, "vf", vf_arrive=0.01, **common), "drink-vf")
    assert bundle.yaml_text == (shipped_folder() / "drink-vf.yaml").read_text()
    learned, shipped = skill_from_bundle(bundle), load_skill(shipped_folder() / "drink-vf.yaml")
    (mapping,) = shipped.states[0].input_mappings
    assert mapping.arrive == 0.01 and any(f.pivot is not None for f in mapping.model.fields)
    for rel, a in learned.models().items():
        assert_same_models(a, shipped.models()[rel], rel)  # to the CPU's kernels' rounding
    plain = skill_from_bundle(skill_bundle(learn(demos, "vf", **common), "drink-vf"))
    assert plain.states[0].input_mappings[0].arrive == 0.0
