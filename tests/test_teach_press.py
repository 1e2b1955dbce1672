"""The demonstrator shows a press: planned with the task file's variation (seeded, pure),
onto the button's axis in front of its face, in past its click by the drawn margin, back
out, then the intent's next step from rest (tasks/light_switch.yaml)."""

from __future__ import annotations

import numpy as np
import pytest

from sctd.task import find_task
from sctd_services.teach import StreamLimits, plan_demonstration, scene_geometry, task_motions
from sctd_services.teach.motion import PressMotion
from sctd_services.teach.plan import PRESS_STANDOFF
from tests.test_teach import _peak_speeds, _same, _samples

G = scene_geometry(find_task("light_switch"))
V = G.teach
BUTTON = G.task.scene.bodies["light_switch"].button


def test_press_plans_are_seeded_and_within_the_variation():
    """The same seed gives the same plan; the press pushes the click depth plus a margin
    from the teach section's range; it comes onto the button's axis in front of its face,
    in the start's orientation; a mistake only moves that beside the button, by the
    step's miss along the wall."""
    margin = V.step("press").margin
    assert margin == (0.005, 0.007)
    depths = []
    for seed in range(4):
        for n in range(1, 7):
            p = plan_demonstration(G, seed, n)
            assert _same(p, plan_demonstration(G, seed, n))
            assert not _same(p, plan_demonstration(G, seed + 100, n))
            press, retreat = p.steps
            assert (press.kind, press.button, press.frame) == ("press", "light_switch", "hand")
            assert BUTTON.click + margin[0] <= press.value <= BUTTON.click + margin[1]
            depths.append(press.value)
            np.testing.assert_allclose(press.T_obj_goal[:3, 3], [PRESS_STANDOFF, 0.0, 0.0], atol=1e-12)
            np.testing.assert_array_equal(press.T_obj_goal[:3, :3], p.T_obj_start[:3, :3])
            np.testing.assert_array_equal(p.T_obj_start[:3, :3], G.T_obj_start[:3, :3])
            assert np.all(np.abs(p.T_obj_start[:3, 3] - G.T_obj_start[:3, 3]) <= V.start)
            assert retreat.kind == "reach" and retreat.value == 0.0
            wrong = plan_demonstration(G, seed, n, mistake=True)
            off = wrong.steps[0].T_obj_goal[:3, 3] - press.T_obj_goal[:3, 3]
            assert abs(off[1]) == pytest.approx(V.step("press").miss) and off[0] == off[2] == 0.0
            assert wrong.steps[0].value == press.value and np.array_equal(wrong.T_obj_start, p.T_obj_start)
    assert max(depths) - min(depths) > 0.5 * (margin[1] - margin[0])  # (it does vary)
    assert "press: light_switch" in plan_demonstration(G, 0, 1).describe()


def test_the_press_motion_pushes_in_along_the_axis_and_comes_back_out():
    lim = StreamLimits()
    for n in (1, 2, 5):
        p = plan_demonstration(G, 7, n)
        (press, m), (_, r) = task_motions(p, G)
        assert isinstance(m, PressMotion)
        A = _samples(m.inward)
        np.testing.assert_allclose(A[0], p.T_obj_start, atol=1e-12)
        # onto the axis, then straight in to the planned depth, the orientation kept
        approach, push = m.inward.parts
        np.testing.assert_allclose(approach.pose(approach.duration), press.T_obj_goal, atol=1e-12)
        P = _samples(push)
        np.testing.assert_allclose(P[:, 1:3, 3], 0.0, atol=1e-12)
        assert np.all(np.diff(P[:, 0, 3]) <= 1e-12)
        np.testing.assert_allclose(P[-1, :3, 3], [-press.value, 0.0, 0.0], atol=1e-12)
        np.testing.assert_allclose(P[:, :3, :3], np.broadcast_to(p.T_obj_start[:3, :3], P[:, :3, :3].shape),
                                   atol=1e-12)
        assert push.profile == "rest_to_rest" and push.duration > (PRESS_STANDOFF + press.value) / (
            1.0 + V.speed) / V.press_speed - 1e-9
        O = _samples(m.outward)
        np.testing.assert_allclose(O[0], P[-1], atol=1e-12)
        np.testing.assert_allclose(O[-1], press.T_obj_goal, atol=1e-12)
        np.testing.assert_allclose(m.pose(m.duration), press.T_obj_goal, atol=1e-12)
        # the retreat starts where the press ended, from rest
        np.testing.assert_allclose(r.pose(0.0), press.T_obj_goal, atol=1e-12)
        assert r.profile == "rest_to_rest"
        for M in (m, r):
            v, w = _peak_speeds(_samples(M, 4000), M.duration / 3999)
            assert v < lim.max_speed and w < lim.max_turn, (type(M).__name__, v, w)
