"""The simulated user's intent steering the simulated arm itself, without shared control:
the task file's intent alone opens the door (and the drawer) in the Pinocchio simulation,
judged by the evaluation's own trial recorder.

The loop is lockstep's (``services/eval/lockstep.py``) on the simulator's clock, with the
skill and the runtime taken out: the user looks at 100 Hz, at objects published at 50 Hz
and the scene's outcome at 10 Hz; its desired twist moves the arm's target every cycle,
never further than 5 cm from the measured pose (the runtime's ``max_offset``)."""

from __future__ import annotations

import numpy as np
import pytest
from can.interfaces import virtual as can_virtual

from sctd import se3
from sctd.task import Task, find_task
from sctd_services.eval.trial import TrialRecorder, TrialResult
from sctd_services.user import Observation, TaskIntent
from sctd_sim.simulation import Simulation, trial_scene

MAX_OFFSET = 0.05  # m between the target and the measured pose (RuntimeConfig.max_offset)

# Seed 0 in the fast tier; the others (the same loop from other starts) in the full one.
SEEDS = [0, pytest.param(1, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow)]


@pytest.fixture(autouse=True)
def no_leaked_buses():
    before = set(can_virtual.channels)
    yield
    assert set(can_virtual.channels) == before


def steer(task: Task, seed: int) -> tuple[TrialResult, float]:
    """Trial ``seed`` of ``task`` with the hand moved as the intent wishes; the result
    and the furthest the arm lagged behind its target (m)."""
    scene, q0 = trial_scene(task, seed)
    intent = TaskIntent(task)
    rec = TrialRecorder(task, seed, switch_time=0.0, time_limit=task.outcome.time_limit)
    lag = 0.0
    with Simulation(scene=scene, q0=q0) as sim:
        every_user, every_object, every_scene = (round(1.0 / (hz * sim.dt)) for hz in (100.0, 50.0, 10.0))
        T_target = se3.transform_from_pose(sim.state_message()["pose"])
        twist, objects, outcome = np.zeros(6), {}, {}
        k = 0
        while True:
            T = se3.transform_from_pose(sim.state_message()["pose"])
            if k % every_object == 0:
                objects = {n: se3.transform_from_pose(p) for n, p in sim.objects().items()}
            if k % every_scene == 0:
                outcome = sim.scene_outcome()
            if k % every_user == 0:
                obs = Observation(sim.t, T, objects, outcome)
                if rec.add(obs, (0.0, 0.0, 0.0), (0, 1, 0)) is not None:
                    break
                twist = intent.desire(obs).twist
            p = T_target[:3, 3] + twist[:3] * sim.dt
            if np.linalg.norm(p - T[:3, 3]) <= MAX_OFFSET:  # (a step further is refused)
                R = se3.matrix_from_rotvec(twist[3:] * sim.dt) @ T_target[:3, :3]
                T_target = se3.transform_from_rt(R, p)
            lag = max(lag, float(np.linalg.norm(T_target[:3, 3] - T[:3, 3])))
            sim.set_target(se3.pose_from_transform(T_target), stamp=sim.t)
            sim.step()
            k += 1
    return rec.result(), lag


@pytest.mark.parametrize("seed", SEEDS)
def test_the_intent_alone_opens_the_cabinet_door_in_the_simulation(seed):
    """From three seeded starts (the hand and the cabinet placed as the file's vary
    says), the hand reaches the handle, grasps it and swings the door 65 deg open along
    its arc, well within the 60 s limit, the arm never more than 2 cm behind its target."""
    task = find_task("cabinet")
    res, lag = steer(task, seed)
    assert (res.outcome, res.reason) == ("success", "opened"), res
    assert res.time_s is not None and res.time_s < 15.0 and res.duration_s < 20.0, res
    assert list(res.phase_s) == ["reach", "swing"] and res.progress >= np.radians(65.0), res
    assert lag < 0.02, lag


def test_the_same_loop_opens_the_drawer():
    res, _ = steer(find_task("drawer"), 0)
    assert (res.outcome, res.reason) == ("success", "opened") and list(res.phase_s) == ["reach", "pull"], res


def test_the_same_loop_lowers_the_oven_door_about_its_horizontal_hinge():
    """The oven's door turns about a horizontal axis at its bottom edge: the handle goes
    out towards the arm and down, to 60 deg."""
    res, lag = steer(find_task("oven"), 1)
    assert (res.outcome, res.reason) == ("success", "opened") and list(res.phase_s) == ["reach", "lower"], res
    assert res.progress >= np.radians(60.0) and lag < 0.02, (res, lag)


@pytest.mark.parametrize("seed", SEEDS)
def test_the_intent_alone_switches_on_the_light_in_the_simulation(seed):
    """From three seeded starts (the hand and the wall placed as the file's vary says),
    the hand comes onto the switch's axis, pushes it in until it clicks on, gently enough
    for the task's 10 N bound, and takes the hand back off the wall, the arm never more
    than 2 cm behind its target."""
    task = find_task("light_switch")
    res, lag = steer(task, seed)
    assert (res.outcome, res.reason) == ("success", "switched on"), res
    assert res.time_s is not None and res.time_s < 10.0 and res.duration_s < 15.0, res
    assert list(res.phase_s) == ["press", "retreat"] and res.progress == 1.0, res
    assert lag < 0.02, lag


@pytest.mark.parametrize("seed", SEEDS)
def test_the_intent_alone_gives_the_person_a_sip_in_the_simulation(seed):
    """From three seeded starts (the cup and the person's head placed as the file's vary
    says), the cup's rim comes to the lips, the cup tilts until a fifth of it is in the
    mouth, comes upright and backs off: a success (nothing spilled, under 5 N on the face,
    no more than a sip), the arm never more than 2 cm behind its target."""
    task = find_task("drink")
    res, lag = steer(task, seed)
    assert (res.outcome, res.reason) == ("success", "drunk"), res
    assert list(res.phase_s) == ["bring", "sip", "upright", "away"], res
    assert res.readings["cup.spilled"] == 0.0 and 0.2 <= res.progress <= 0.3, res
    assert res.time_s is not None and res.time_s < 12.0, res
    assert lag < 0.02, lag
