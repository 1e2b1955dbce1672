"""The demonstrator shows steps of registered kinds by their legs: a cup taken off the
shelf and put on the table top, a tap turned; seeded, pure, then on the simulator with
the fingers (tasks/cup_to_table.yaml, tasks/tap.yaml)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sctd import se3
from sctd.learn.demos import read_demos
from sctd.task import find_task
from sctd.task.kinds.handling import HIGHER, MISS, OFF_SPOT, TURN_AWAY
from sctd.task.kinds.pickable import FREE
from sctd_services.teach import StreamLimits, plan_demonstration, scene_geometry, task_motions
from sctd_services.teach.motion import LegsMotion
from tests.test_teach import _peak_speeds, _same, _samples

CUP = scene_geometry(find_task("cup_to_table"))
TAP = scene_geometry(find_task("tap"))


def _in_obj(G, name: str) -> np.ndarray:
    return G.body(name)


def test_a_grasp_and_a_place_are_legs_with_the_fingers_and_what_they_wait_for():
    for seed in range(3):
        for n in range(1, 5):
            p = plan_demonstration(CUP, seed, n)
            assert _same(p, plan_demonstration(CUP, seed, n))
            assert [(s.name, s.kind) for s in p.steps] == [("take", "grasp"), ("put", "place")]
            motions = task_motions(p, CUP)
            (_, take), (_, put) = motions
            assert isinstance(take, LegsMotion) and isinstance(put, LegsMotion)
            assert [(leg.grip, leg.until) for _, leg in take.legs] == \
                [(None, None), ("close", ("cup.held", True)), (None, None)]
            assert take.legs[1][1].force == 20.0
            assert [(leg.grip, leg.until) for _, leg in put.legs] == \
                [(None, None), (None, None), ("open", ("cup.held", False)), (None, None)]
            # the grip about the cup's middle, its axis between the fingers; lifted 5-7 cm
            grip = take.legs[1][1].T_world_ee
            np.testing.assert_allclose(grip[:3, 3], [0.0, 0.0, 0.05], atol=1e-12)
            up = take.legs[2][1].T_world_ee[2, 3] - grip[2, 3]
            assert 0.05 <= up <= 0.05 + HIGHER
            # the approach along the hand's own x, turned by at most TURN_AWAY
            before = take.legs[0][1].T_world_ee
            back = grip[:3, 3] - before[:3, 3]
            np.testing.assert_allclose(back / np.linalg.norm(back), grip[:3, 0], atol=1e-9)
            yaw = se3.rotvec_from_matrix(grip[:3, :3] @ p.T_obj_start[:3, :3].T)
            assert abs(yaw[2]) <= TURN_AWAY + 1e-12 and np.allclose(yaw[:2], 0.0)
            # put down on the table top's middle, within OFF_SPOT, the base 2 mm over it
            down = put.legs[2][1].T_world_ee[:3, 3]
            top = _in_obj(CUP, "tabletop")[:3, 3]
            assert np.all(np.abs(down[:2] - top[:2]) <= OFF_SPOT + 1e-12)
            assert down[2] == pytest.approx(top[2] + 0.05 + 0.002)
            # each leg starts where the one before ended, and the motions join up
            T = _samples(take)
            assert _peak_speeds(T, take.duration / (len(T) - 1))[0] < StreamLimits().max_speed
            np.testing.assert_allclose(put.pose(0.0), take.pose(take.duration), atol=1e-12)


def test_a_mistaken_grasp_closes_beside_the_cup():
    right = task_motions(plan_demonstration(CUP, 0, 1), CUP)[0][1]
    wrong = task_motions(plan_demonstration(CUP, 0, 1, mistake=True), CUP)[0][1]
    a, b = right.legs[1][1].T_world_ee, wrong.legs[1][1].T_world_ee
    np.testing.assert_allclose(b[:3, 3] - a[:3, 3], MISS * a[:3, 1], atol=1e-12)


def test_a_turn_takes_the_tap_turns_it_past_its_threshold_and_lets_go():
    task = TAP.task
    step = task.intent[0].action
    for seed in range(3):
        p = plan_demonstration(TAP, seed, 1)
        (s, m), = task_motions(p, TAP)
        assert s.kind == "turn" and isinstance(m, LegsMotion)
        assert [(leg.grip, leg.until) for _, leg in m.legs] == \
            [(None, None), ("close", ("tap.held", True)), ("open", ("tap.held", False)), (None, None)]
        grip, turned = m.legs[1][1].T_world_ee, m.legs[2][1].T_world_ee
        np.testing.assert_allclose(turned[:3, 3], grip[:3, 3], atol=1e-12)  # (turned in place)
        w = se3.rotvec_from_matrix(turned[:3, :3] @ grip[:3, :3].T)
        np.testing.assert_allclose(w[:2], 0.0, atol=1e-9)  # about the tap's vertical axis
        assert math.radians(60.0) < w[2] <= step.target + 1e-9


@pytest.mark.slow
def test_teach_picks_and_places_the_cup_with_the_fingers(tmp_path):
    """`sctd teach --task cup_to_table --demos 1 --mistake 1`: the mistaken grasp never
    holds the cup and is discarded, saying so; the next is kept, with the fingers in its
    rows: open, closed on the cup (grasped) from the grasp to the put-down, open again."""
    from tests.conftest import free_port, port_is_free, sctd

    port = free_port()
    out = tmp_path / "taught"
    proc = sctd("teach", "--task", "cup_to_table", "--demos", "1", "--mistake", "1", "--out", str(out),
                "--listen", f"tcp/127.0.0.1:{port}", "--logs", str(tmp_path / "logs"),
                log=tmp_path / "teach.log")
    try:
        assert proc.p.wait(300) == 0, proc.output()
    finally:
        proc.stop()
    text = proc.output()
    lines = [ln for ln in text.splitlines() if ln.strip().startswith("attempt")]
    assert len(lines) == 2, text
    assert "discarded" in lines[0] and "cup.held was not true within 3 s of the fingers' close" in lines[0]
    assert "demo_000" in lines[1] and "kept" in lines[1] and "tabletop.items 1.000 of 1" in lines[1]
    (demo,) = read_demos(out)
    assert demo.width is not None and demo.grasped is not None
    changes = np.flatnonzero(np.diff(demo.grasped.astype(int)))
    assert len(changes) == 2 and demo.grasped[0] == 0 and demo.grasped[changes[0] + 1] == 1
    held = demo.width[changes[0] + 1:changes[1] + 1]
    assert np.all((held >= 0.07) & (held <= 0.07 + FREE))  # (the cup's 7 cm; they take it from 7.2 cm)
    assert port_is_free(port)
