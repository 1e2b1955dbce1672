"""The simulated user presses a button: the intent's press step (onto the button's axis,
in along it, gently, until the light is on), a perfect device that does what it wishes
switching the light on, and a user who learns nothing of the stick from a hand held by
a wall."""

from __future__ import annotations

import numpy as np
import pytest

from sctd import se3
from sctd.task import find_task
from sctd_services.user import DeviceModel, Observation, SimulatedUser, TaskIntent
from sctd_services.user.human import PROFILES
from sctd_sim.scenes import TaskScene

TASK = find_task("light_switch")
PRESS = TASK.intent[0].action
BODY = TASK.scene.bodies["light_switch"]
T_B = BODY.T_world  # the switch: x out of the wall (world -x), z up


def _obs(t: float, p_B, readings: dict | None = None, mode: str = "") -> Observation:
    """The hand at ``p_B`` in the switch's frame, seen with ``readings``."""
    T = se3.transform_from_rt(np.diag([-1.0, -1.0, 1.0]), (T_B @ np.append(p_B, 1.0))[:3])
    return Observation(t, T, {"light_switch": T_B}, {"readings": readings or {}}, mode)


def _in_B(v: np.ndarray) -> np.ndarray:
    """A world velocity in the switch's axes."""
    return T_B[:3, :3].T @ v[:3]


def test_off_the_axis_the_user_comes_onto_it_in_front_of_the_face():
    it = TaskIntent(TASK)
    near_off = _in_B(it.desire(_obs(0.0, [0.005, 0.012, 0.0])).twist)  # 5 mm out, 12 mm aside
    assert near_off[0] > 0 and near_off[1] < 0  # back out towards the clearance, onto the axis
    far = _in_B(it.desire(_obs(0.0, [0.2, 0.05, -0.03])).twist)
    assert far[0] < 0 and far[1] < 0 and far[2] > 0  # towards the point in front of the face
    assert np.linalg.norm(far) == pytest.approx(it.v_max)


def test_on_the_axis_the_user_pushes_in_gently_and_backs_off_past_the_bound():
    """In front of the face: in, at ``press_speed`` within ``slow`` of it; touching it, at
    ``press_speed`` up to half the step's bound, slower above, not at all at the bound,
    back out beyond it."""
    it = TaskIntent(TASK)
    v = _in_B(it.desire(_obs(0.0, [0.1, 0.0, 0.0])).twist)
    assert v[0] < -it.press_speed and abs(v[1]) < 1e-12 and abs(v[2]) < 1e-12
    v = _in_B(it.desire(_obs(0.0, [0.015, 0.0, 0.0])).twist)
    assert v[0] == pytest.approx(-it.press_speed)
    for force, along in [(2.0, -1.0), (4.0, -1.0), (6.0, -0.5), (8.0, 0.0), (10.0, 0.5), (20.0, 1.0)]:
        r = {"light_switch.force": force, "light_switch.touching": True, "light_switch.position": 0.002}
        v = _in_B(it.desire(_obs(0.0, [-0.004, 0.0, 0.0], r)).twist)
        assert v[0] == pytest.approx(along * it.press_speed, abs=1e-15), force
    d = it.desire(_obs(0.0, [-0.004, 0.0, 0.0], {"light_switch.force": 4.0}))
    assert d.phase == "press" and not d.done and not d.close_enough
    assert d.error == pytest.approx(BODY.button.travel - 0.004)  # to the face pushed to its travel


def test_the_light_on_ends_the_press_and_the_user_retreats():
    it = TaskIntent(TASK)
    on = {"light_switch.on": True, "light_switch.force": 4.0, "light_switch.touching": True}
    d = it.desire(_obs(0.0, [-0.004, 0.0, 0.0], on))
    assert d.phase == "retreat" and _in_B(d.twist)[0] > 0.05
    assert it.touching(_obs(0.0, [0.0, 0.0, 0.0], on))
    assert not it.touching(_obs(0.0, [0.0, 0.0, 0.0], {"light_switch.touching": False}))
    assert it.desire(_obs(0.1, [0.08, 0.0, 0.005], on)).done


@pytest.mark.parametrize("start", [[0.25, 0.04, -0.05], [0.12, -0.06, 0.08], [0.02, 0.03, 0.0]])
def test_a_perfect_device_switches_the_light_on_gently(start):
    """A hand that moves exactly as the intent wishes, seeing the scene at once, presses
    the switch until it clicks, never harder than the step's bound, and takes the hand
    back off the wall: the task is done and a success."""
    scene = TaskScene(TASK)
    it = TaskIntent(TASK)
    T = _obs(0.0, start).T_world_ee
    dt, t = 0.001, 0.0
    phases = []
    while t < 20.0:
        scene.step(T, np.zeros(6), dt)
        obs = Observation(t, T, scene.objects(T), scene.outcome())
        d = it.desire(obs)
        if not phases or phases[-1] != d.phase:
            phases.append(d.phase)
        if d.done:
            break
        T = T.copy()
        T[:3, 3] += d.twist[:3] * dt
        t += dt
    r = scene.readings()
    assert phases == ["press", "retreat", "done"], phases
    assert r["light_switch.on"] and r["light_switch.presses"] == 1.0 and not r["light_switch.touching"]
    assert BODY.button.click_force < r["light_switch.max_force"] < PRESS.force
    assert scene.outcome()["done"] and scene.outcome()["success"] and t < 10.0


def test_the_user_learns_nothing_of_the_stick_while_a_wall_holds_the_hand():
    """Pushing the stick while the hand presses the switch moves nothing: that is the wall,
    not the stick, and the user's model of the stick stays as it was; nor does the user,
    getting nowhere there, try the stick out."""
    user = SimulatedUser(TASK, 3, PROFILES["steady"], seed=0)
    model = user.models["m"] = DeviceModel(3)
    B = np.zeros((6, 3))
    B[:3, :3] = np.diag([-0.1, -0.1, 0.1])  # the stick's axes in the switch's (world -x, -y, z)
    for k in range(30):  # the stick tried out: the model knows the device
        u = np.eye(3)[k % 3] * (1 if k % 2 else -1)
        model.update(u, B @ u)
    known = model.B.copy()
    touching = {"light_switch.touching": True, "light_switch.force": 5.0, "light_switch.position": 0.003}
    t = 0.0
    for _ in range(600):  # 6 s held against the switch, nothing moving
        user.step(t, _obs(t, [-0.005, 0.0, 0.0], touching, "m"))
        t += 0.01
    np.testing.assert_array_equal(model.B, known)
    assert user.reprobes == 0 and "m" not in user._probes
