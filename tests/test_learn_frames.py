"""Feature frames found in the demonstrations feed the linear learner: the pour's
bottle tip and the crank's axis are found with no --frame; given frames still win."""

from __future__ import annotations

import numpy as np
import pytest

from sctd.bench.demos import demo_kind
from sctd.learn import Demo, LinearIMLearner, learn_linear, read_demos
from sctd.learn.frames import automatic_frames
from sctd_sim import demogen

from .conftest import ROOT


def _demos(task, seed):
    ds = demogen.generate(demo_kind(task), 10, noise=0.001, outliers=0.05, seed=seed)
    return ds, [Demo(d.name, d.t, d.poses) for d in ds.demos]


def _states(result):
    return [(st.label.frame, st.label.axes) for st in result.learner.states_]


def test_the_pour_finds_the_tip_and_segments_as_with_the_given_frame():
    demos = read_demos(ROOT / "skills" / "demos" / "pour")
    auto = learn_linear(demos)
    (f,) = auto.found_frames
    assert f.kind == "sphere" and set(auto.frames) == {f.name}
    np.testing.assert_allclose(f.pose[:3], [0.0, 0.0, 0.12], atol=0.005)
    assert _states(auto) == [("ee", (0, 1, 2)), (f.name, (4,))]  # carry, then ry about the tip
    given = learn_linear(demos, {"tip": [0, 0, 0.12, 0, 0, 0, 1]})
    assert given.found_frames == [] and set(given.frames) == {"tip"}
    assert auto.labels == given.labels


@pytest.mark.parametrize("seed", range(4))
def test_the_crank_finds_its_axis_and_turns_about_it(seed):
    ds, demos = _demos("crank", seed)
    r = learn_linear(demos, learner=LinearIMLearner(random_state=seed))
    (f,) = r.found_frames
    assert f.kind == "cylinder"
    np.testing.assert_allclose(f.pose[:3], ds.truth["axis_ee_offset"], atol=0.005)
    z = f.pose[3:]  # the frame's z axis is the crank's axis as the hand sees it (ee z up)
    assert np.degrees(2 * np.arccos(min(1.0, abs(z[3])))) < 3.0
    assert _states(r)[-1] == (f.name, (5,))  # rz about the axis


def test_straight_motions_have_no_frame():
    _, demos = _demos("drawer", 0)
    assert automatic_frames(demos) == []
    assert set(learn_linear(demos).frames) == set()


def test_no_auto_frames_learns_in_the_hand_frame_alone():
    demos = read_demos(ROOT / "skills" / "demos" / "pour")
    r = learn_linear(demos, learner=LinearIMLearner(auto_frames=False))
    assert r.found_frames == [] and r.frames == {}
    assert {st.label.frame for st in r.learner.states_} == {"ee"}
