"""A body's surface and the push button in it, as the simulator steps them: the button
gives way against its spring and switches past its click depth, the wall holds the hand
with the surface's stiffness, the readings say the force, and a hand that never touches
does nothing (tasks/light_switch.yaml's switch, and the equations of
docs/tasks.md)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import yaml
from can.interfaces import virtual as can_virtual

from sctd import se3
from sctd.task import find_task, shipped_folder, task_from_document
from sctd.task.kinds.surface import Contact, PushButton
from sctd_sim.scenes import TaskScene
from sctd_sim.simulation import Simulation

TASK = find_task("light_switch")
BODY = TASK.scene.bodies["light_switch"]
K, C, MU = BODY.surface.stiffness, BODY.surface.damping, BODY.surface.friction
B = BODY.button
STILL = np.zeros(6)


@pytest.fixture(autouse=True)
def no_leaked_buses():
    before = set(can_virtual.channels)
    yield
    assert set(can_virtual.channels) == before


def hand_at(scene: TaskScene, x: float, y: float = 0.0, z: float = 0.0) -> np.ndarray:
    """The hand (the scene's start orientation) at ``(x, y, z)`` in the switch's frame."""
    T = scene.start_pose()
    T[:3, 3] = (scene.poses["light_switch"] @ np.array([x, y, z, 1.0]))[:3]
    return T


def push(scene: TaskScene, depths, y: float = 0.0) -> list[dict]:
    """Step the scene with the hand still at each depth past the face's rest plane in turn;
    the readings after each."""
    out = []
    for d in depths:
        scene.step(hand_at(scene, -d, y), STILL, 0.001)
        out.append(scene.readings())
    return out


def balance(d: float) -> float:
    """Where the button's face is with the hand ``d`` past its rest plane (k (d - s) =
    preload + spring s, within [0, travel])."""
    return min(B.travel, max(0.0, (K * d - B.preload) / (K + B.spring)))


def test_a_hand_that_never_touches_does_nothing():
    scene = TaskScene(TASK)
    for x in (0.2, 0.05, 1e-4):
        for y in (0.0, 0.01, 0.3):
            w = scene.step(hand_at(scene, x, y), np.array([-0.1, 0.0, 0.0, 0.0, 0.0, 0.0]), 0.001)
            assert not np.any(w)
    r = scene.readings()
    assert r == {"light_switch.force": 0.0, "light_switch.max_force": 0.0, "light_switch.touching": False,
                 "light_switch.position": 0.0, "light_switch.on": False, "light_switch.presses": 0.0}
    assert not scene.outcome()["done"]


def test_pushing_past_the_click_switches_it_once_until_it_comes_back_out():
    """In 0.1 mm steps to 9 mm and out: the face follows the balance of the contact and its
    spring, rests on the wall at its travel, and the light switches on once, when the face
    passes its click depth; out past half that and in again, it switches off."""
    scene = TaskScene(TASK)
    push(scene, [-0.02])  # in front of it first
    depths = np.arange(0.0, 0.0091, 0.0001)
    readings = push(scene, depths)
    for d, r in zip(depths, readings, strict=True):
        s = balance(d)
        assert r["light_switch.position"] == pytest.approx(s, abs=1e-12)
        assert r["light_switch.force"] == pytest.approx(K * (d - s) if d > 0 else 0.0, abs=1e-9)
        assert r["light_switch.on"] == (r["light_switch.position"] >= B.click)
        assert r["light_switch.touching"] == (d > 0)
    assert readings[-1]["light_switch.presses"] == 1.0
    # at the click the push is the preload and the spring's; past the travel the wall's
    at_click = next(r for r in readings if r["light_switch.on"])
    assert at_click["light_switch.force"] == pytest.approx(B.click_force, abs=K * 1e-4)
    d_end = (B.preload + (K + B.spring) * B.travel) / K  # where the face reaches its travel
    assert readings[-1]["light_switch.force"] == pytest.approx(
        B.preload + B.spring * B.travel + K * (depths[-1] - d_end), rel=1e-9)
    assert d_end < depths[-1] and readings[-1]["light_switch.position"] == B.travel
    # back out to just short of half the click depth: still on, not re-armed for another
    back = push(scene, [balance_inverse(0.6 * B.click), balance_inverse(0.55 * B.click)])
    again = push(scene, [0.007])
    assert back[-1]["light_switch.on"] and again[-1]["light_switch.on"]
    assert again[-1]["light_switch.presses"] == 1.0
    out = push(scene, [balance_inverse(0.4 * B.click), 0.0, -0.01])
    assert out[-1]["light_switch.position"] == 0.0 and not out[-1]["light_switch.touching"]
    off = push(scene, [0.007])[-1]
    assert not off["light_switch.on"] and off["light_switch.presses"] == 2.0


def balance_inverse(s: float) -> float:
    """The hand's depth that holds the face at ``s``."""
    return (B.preload + (K + B.spring) * s) / K


def test_the_force_readings_and_the_wrench_on_the_hand():
    """The force now, the highest so far; the wrench pushes the hand out of the wall
    (along the switch's +x, the world's -x), its damping against the speed into it,
    friction against the slip along it."""
    scene = TaskScene(TASK)
    push(scene, [-0.02])
    T = hand_at(scene, -0.004)
    w = scene.step(T, STILL, 0.001)
    F = K * (0.004 - balance(0.004))
    np.testing.assert_allclose(w, [-F, 0, 0, 0, 0, 0], atol=1e-9)  # (the hand's own point: no moment)
    moving = np.array([0.05, 0.02, -0.01, 0.0, 0.0, 0.0])  # into the wall (world +x) and along it
    w = scene.step(T, moving, 0.001)
    Fn = F + C * 0.05
    slip = math.hypot(0.02, 0.01)
    held = MU * Fn * math.tanh(slip / BODY.surface.friction_speed) / slip
    np.testing.assert_allclose(w[:3], [-Fn, -held * 0.02, held * 0.01], rtol=1e-12)
    r = scene.readings()
    assert r["light_switch.force"] == pytest.approx(Fn) and r["light_switch.max_force"] == pytest.approx(Fn)
    w = scene.step(T, np.array([-0.1, 0.0, 0.0, 0.0, 0.0, 0.0]), 0.001)  # pulled out faster than the
    # spring pushes: the damper lets go, no pull on the hand
    assert not np.any(w) and scene.readings()["light_switch.touching"]
    assert scene.readings()["light_switch.force"] == 0.0
    assert scene.readings()["light_switch.max_force"] == pytest.approx(Fn)
    scene.reset()
    assert scene.readings()["light_switch.max_force"] == 0.0 and not scene.readings()["light_switch.on"]


def test_beside_the_button_the_wall_holds_the_hand_with_its_stiffness():
    """2 cm beside the button's centre (outside its 15 mm face) the wall gives nothing:
    the force is the surface's stiffness times the depth, and the light stays off."""
    scene = TaskScene(TASK)
    push(scene, [-0.02], y=0.02)
    for d in (0.001, 0.004, 0.008):
        r = push(scene, [d], y=0.02)[-1]
        assert r["light_switch.force"] == pytest.approx(K * d, rel=1e-12)
        assert r["light_switch.position"] == 0.0 and not r["light_switch.on"]


def test_a_point_first_seen_behind_the_wall_is_not_pushed_until_it_came_out():
    scene = TaskScene(TASK)
    assert not np.any(scene.step(hand_at(scene, -0.01), STILL, 0.001))
    assert not scene.readings()["light_switch.touching"]
    scene.step(hand_at(scene, 0.001), STILL, 0.001)
    assert scene.step(hand_at(scene, -0.01), STILL, 0.001)[0] < 0.0  # (pushed back towards the arm)


def test_a_held_frame_touches_and_its_force_turns_the_hand():
    """A stylus whose tip is 12 cm ahead of the hand and 3 cm below it presses the button:
    the force acts at its tip, so the hand feels its moment ``r x F`` about its own
    origin."""
    doc = copy.deepcopy(yaml.safe_load((shipped_folder() / "light_switch.yaml").read_text()))
    doc["scene"]["start"]["position"] = [0.40, 0.05, 0.70]
    doc["scene"]["held"] = {"name": "stylus", "mass": 0.0, "com": [0.0, 0.0, 0.0],
                            "frames": {"stylus_tip": {"position": [-0.12, 0.0, -0.03]}}}
    doc["scene"]["bodies"]["light_switch"]["surface"]["touch"] = ["stylus_tip"]
    doc["intent"][0]["press"]["frame"] = "stylus_tip"
    scene = TaskScene(task_from_document(doc, "stylus.yaml"))
    assert isinstance(scene.contacts[0], PushButton) and isinstance(scene.contacts[0], Contact)
    T = scene.start_pose()
    r = T[:3, :3] @ np.array([-0.12, 0.0, -0.03])  # from the hand to the tip (world)
    T_B = scene.poses["light_switch"]

    def tip_at(x: float) -> np.ndarray:
        T[:3, 3] = (T_B @ np.array([x, 0.0, 0.005, 1.0]))[:3] - r
        return T.copy()
    scene.step(tip_at(0.02), STILL, 0.001)
    w = scene.step(tip_at(-0.0025), STILL, 0.001)
    F = K * (0.0025 - balance(0.0025))
    force = T_B[:3, 0] * F  # out of the wall
    assert np.linalg.norm(np.cross(r, force)) > 0.02 * F
    np.testing.assert_allclose(w, [*force, *np.cross(r, force)], atol=1e-9)
    assert scene.readings()["light_switch.force"] == pytest.approx(F)


def test_the_wall_stops_the_arm_with_the_surface_stiffness():
    """The simulated arm sent 3 cm into the wall beside the switch stops where its
    impedance and the wall's stiffness balance (3000 N/m against 2500 N/m: 1.64 cm in),
    and the state's wrench is the wall's push."""
    sc = TaskScene(TASK)
    T0 = hand_at(sc, 0.05, 0.04)
    with Simulation(scene=sc, q0=_posture(T0)) as sim:
        target = hand_at(sc, -0.03, 0.04)
        for _ in range(2000):
            sim.set_target(se3.pose_from_transform(target), stamp=sim.t)
            sim.step()
        T = se3.transform_from_pose(sim.state_message()["pose"])
        depth = -(se3.invert_transform(sc.poses["light_switch"]) @ T)[0, 3]
        F = sc.readings()["light_switch.force"]
        assert F == pytest.approx(K * depth, rel=1e-3)  # (the damper on what motion is left)
        assert 0.012 < depth < 0.02 and 30.0 < F < 50.0  # (the arm's own damping and friction aside)
        wrench = sim.state_message()["wrench"]
        assert wrench[0] == pytest.approx(-F, rel=0.05) and abs(wrench[1]) < 0.1 * F
        assert not sc.readings()["light_switch.on"]


def _posture(T: np.ndarray) -> np.ndarray:
    from sctd_sim.robot import load_arm_model
    from sctd_sim.simulation import start_posture

    return start_posture(load_arm_model(), T)
