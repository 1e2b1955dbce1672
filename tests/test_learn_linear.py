"""Linear input mappings (Ch. 4.1): label set, IM identification with the shared
displacement convention, and the pipeline on generated pouring demonstrations."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd import se3
from sctd.learn import (
    SELECTIONS,
    Demo,
    IMLabel,
    LinearIMLearner,
    im_costs,
    label_set,
    learn_linear,
    least_squares_command,
    neighbour_graph,
    segmentation_accuracy,
    selection_matrices,
)
from sctd.learn.linear import dtw_edges, frame_displacements
from sctd.task import find_task
from sctd_sim import demogen

from .strategies import poses, unit_quaternions

TIP = [0.0, 0.0, 0.12, 0.0, 0.0, 0.0, 1.0]


def test_forty_one_selections():
    assert len(SELECTIONS) == 41
    assert [len(s) for s in SELECTIONS].count(1) == 6
    assert [len(s) for s in SELECTIONS].count(2) == 15
    assert [len(s) for s in SELECTIONS].count(3) == 20
    Ms = selection_matrices()
    assert len({M.tobytes() for M in Ms}) == 41
    assert all(M.shape[0] == 6 and np.all(M.sum(axis=0) == 1) for M in Ms)
    labels = label_set(["ee", "tip", "rim"])
    assert len(labels) == 41 + 34 + 34  # translation-only selections once (ee)
    assert all(lab.rotates for lab in labels if lab.frame != "ee")


@settings(max_examples=80, deadline=None)
@given(pose=poses(scale=0.5), offset=poses(scale=0.2), k=st.integers(0, 40),
       u=st.lists(st.floats(-0.05, 0.05), min_size=3, max_size=3))
def test_identified_im_reproduces_the_displacement(pose, offset, k, u):
    """Move a frame with M u (se3.apply_displacement), recover the displacement from
    the ee poses, identify: the least-squares command is u, the residual zero, and
    applying it reproduces the motion."""
    axes = SELECTIONS[k]
    M = IMLabel("f", axes).matrix
    u = np.asarray(u[: len(axes)])
    T_obj_ee = se3.transform_from_pose(pose)
    T_ee_f = se3.transform_from_pose(offset)
    T_f = T_obj_ee @ T_ee_f
    T_f_next = se3.apply_displacement(T_f, M @ u)
    T_ee_next = T_f_next @ se3.invert_transform(T_ee_f)
    d6 = frame_displacements(np.stack([T_obj_ee, T_ee_next]), T_ee_f)[0]
    u_hat, res = least_squares_command(M, d6)
    np.testing.assert_allclose(u_hat, u, atol=1e-9)
    assert np.abs(res).max() < 1e-9
    np.testing.assert_allclose(se3.apply_displacement(T_f, M @ u_hat), T_f_next, atol=1e-9)
    # Its cost is beta * DoF and no label of fewer DoF explains it better.
    labels = label_set(["ee", "f"]) if any(a >= 3 for a in axes) else label_set(["ee"])
    D = np.stack([frame_displacements(np.stack([T_obj_ee, T_ee_next]), off)
                  for off in ([np.eye(4), T_ee_f] if len(labels) > 41 else [np.eye(4)])])
    names = ["ee", "f"][: D.shape[0]]
    c = im_costs(D, labels, names, alpha=0.4, beta=0.01)[0]
    own = labels.index(IMLabel("f" if any(a >= 3 for a in axes) else "ee", axes))
    assert c[own] == pytest.approx(0.01 * len(axes), abs=1e-9)


@given(q=unit_quaternions())
def test_pure_rotation_about_tip_is_rotation_only_in_tip_frame(q):
    T = se3.transform_from_pose([0.1, 0.2, 0.3, *q])
    T_ee_tip = se3.transform_from_pose(TIP)
    T_tip = T @ T_ee_tip
    T_tip2 = se3.apply_displacement(T_tip, [0, 0, 0, 0, 0.05, 0])
    T2 = T_tip2 @ se3.invert_transform(T_ee_tip)
    d_tip = frame_displacements(np.stack([T, T2]), T_ee_tip)[0]
    d_ee = frame_displacements(np.stack([T, T2]), np.eye(4))[0]
    np.testing.assert_allclose(d_tip, [0, 0, 0, 0, 0.05, 0], atol=1e-9)
    assert np.linalg.norm(d_ee[:3]) == pytest.approx(0.12 * 2 * np.sin(0.025), rel=1e-6)


def test_neighbour_graph():
    P = np.zeros((6, 7))
    P[:, 6] = 1.0
    P[:, 0] = [0, 0.01, 0.02, 0.5, 0.51, 0.0]
    E, w = neighbour_graph(P, [0, 0, 0, 1, 1, 1], radius=0.04, max_n=10)
    pairs = {tuple(e) for e in E}
    assert {(0, 1), (1, 2), (3, 4), (4, 5)} <= pairs  # temporal successors
    assert (0, 5) in pairs and (2, 3) not in pairs  # spatial within 4 cm only
    assert np.all(E[:, 0] < E[:, 1]) and np.all((w > 0) & (w <= 1))


@pytest.fixture(scope="module")
def pour_result():
    ds = demogen.generate(find_task("pour"), 8, noise=0.001, outliers=0.05, seed=11)
    demos = [Demo(d.name, d.t, d.poses) for d in ds.demos]
    return ds, learn_linear(demos, {"tip": TIP}, learner=LinearIMLearner(random_state=0))


def test_pour_known_answer(pour_result):
    ds, res = pour_result
    L = res.learner
    assert [st.label.name for st in L.states_] == ["ee:txtytz", "tip:ry"]
    assert len(L.transitions_) == 1 and L.transitions_[0].reachable
    hits = total = 0
    for name, truth in ds.truth["labels"].items():
        lab = np.asarray(res.labels[name])
        assert len(lab) == len(truth)
        assert np.all(np.diff(lab) >= 0)  # every demo follows the chain in order
        hits += int(np.sum(lab == np.asarray(truth)))
        total += len(truth)
    assert hits / total >= 0.95
    assert L.energy_ <= L.energy_initial_


def test_expansion_option_gives_the_same_states(pour_result):
    ds, res = pour_result
    demos = [Demo(d.name, d.t, d.poses) for d in ds.demos]
    res2 = learn_linear(demos, {"tip": TIP}, learner=LinearIMLearner(cut="expansion", random_state=0))
    assert [s.label for s in res2.learner.states_] == [s.label for s in res.learner.states_]


def test_dtw_edges_pair_the_same_stage_of_identical_demos():
    """Two copies of a demonstration, the second sampled twice as densely: DTW pairs
    each displacement with the ones at the same place, across the two demos."""

    x = np.linspace(0.0, 0.3, 16)
    a = np.stack([x, np.zeros(16), np.zeros(16), np.zeros(16), np.zeros(16), np.zeros(16), np.ones(16)], 1)
    x2 = np.linspace(0.0, 0.3, 31)
    b = np.stack([x2, np.zeros(31), np.zeros(31), np.zeros(31), np.zeros(31), np.zeros(31), np.ones(31)], 1)
    E, w = dtw_edges([a, b, a.copy()])
    assert len(E) and np.all(E[:, 0] < E[:, 1])
    assert np.all((w > 0) & (w <= 1))
    off = [0, 16, 47]
    # Every edge joins two different demonstrations at (nearly) the same position.
    demo_of = np.searchsorted(off, E, side="right") - 1
    assert np.all(demo_of[:, 0] != demo_of[:, 1])
    allp = np.concatenate([a, b, a])[:, 0]
    assert np.all(np.abs(allp[E[:, 0]] - allp[E[:, 1]]) <= 0.01 + 1e-12)
    # The identical copy (demo 2) is matched index for index with the reference...
    # or the reference is b (median length) and both copies map onto it.
    assert set(map(tuple, demo_of.tolist())) <= {(0, 1), (1, 2), (0, 2)}


def test_dtw_align_option_learns_the_same_skill_shape():
    ds = demogen.generate(find_task("pour"), 6, noise=0.001, outliers=0.05, seed=3)
    demos = [Demo(d.name, d.t, d.poses) for d in ds.demos]
    r = learn_linear(demos, {"tip": np.array([0, 0, 0.12, 0, 0, 0, 1.0])},
                     learner=LinearIMLearner(dtw_align=True, random_state=3))
    assert [s.label.name for s in r.learner.states_] == ["ee:txtytz", "tip:ry"]
    assert segmentation_accuracy(r.labels, ds.truth["labels"])[0] >= 0.95
