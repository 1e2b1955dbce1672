"""Fast, in-process tests of what the process-level tests otherwise reach only from a
child: the kinematic stand-in robot, the EMG guided calibration and its benchmark, and
the ``python -m`` entry points (run here through runpy)."""

from __future__ import annotations

import itertools
import math
import runpy
import sys

import numpy as np
import pytest

from sctd import se3
from sctd.task import find_task
from sctd.wire import codec
from sctd_services.input.device import InputError
from sctd_services.input.emg import guided
from sctd_services.input.emg.bench import bench_processing
from sctd_services.input.emg.calibration import PHASES, Phase
from sctd_services.input.emg.processing import Chain, Filters
from sctd_sim.guard import TargetGuard, TargetLimits
from sctd_sim.kinematic import KinematicRobot, _take_target, kinematic_scene


def test_the_kinematic_robot_relaxes_towards_its_target_and_carries_the_bottle_tip():
    robot = KinematicRobot(kinematic_scene(find_task("pour")), tau=0.02)
    start = robot.T_world_ee.copy()
    goal = start @ se3.transform_from_pose([0.03, 0.0, 0.0, 0, 0, 0, 1])
    robot.T_world_target = goal
    gaps = []
    for _ in range(100):  # 0.1 s = 5 time constants
        robot.step(0.001)
        gaps.append(float(np.linalg.norm(goal[:3, 3] - robot.T_world_ee[:3, 3])))
    assert all(b <= a + 1e-15 for a, b in itertools.pairwise(gaps)), "never overshoots"
    assert gaps[-1] == pytest.approx(0.03 * math.exp(-5), rel=0.02)
    tip = robot.objects()["bottle_tip"]
    np.testing.assert_allclose(tip, robot.T_world_ee @ robot.scene.attached["bottle_tip"])
    assert "mug" in robot.objects()
    with pytest.raises(ValueError, match="kitchen: no such file, and no task of that name"):
        kinematic_scene(find_task("kitchen"))


def test_the_kinematic_scene_is_the_task_files():
    """The stand-in puts the bodies where the task file does, starts the hand at its
    start and carries the held object's frames: the numbers come from the file."""
    for name in ("pour", "drawer"):
        task = find_task(name)
        scene = kinematic_scene(task)
        assert set(scene.objects) == set(task.scene.bodies)
        for body in task.scene.bodies.values():
            np.testing.assert_array_equal(scene.objects[body.name], body.T_world)
        np.testing.assert_array_equal(scene.T_world_ee0, task.scene.start.T_world)
        held = task.scene.held.frames if task.scene.held else {}
        assert set(scene.attached) == set(held)
        for frame, T in held.items():
            np.testing.assert_array_equal(scene.attached[frame], T)
    tip = kinematic_scene(find_task("pour")).attached["bottle_tip"]
    np.testing.assert_array_equal(tip[:3, 3], [0.0, 0.0, 0.12])


def test_the_kinematic_drawer_opens_once_grasped_and_only_up_to_its_stop():
    scene = kinematic_scene(find_task("drawer"))
    robot = KinematicRobot(scene, tau=0.001)
    handle = scene.objects["drawer_handle"]
    robot.T_world_target = handle.copy()
    for _ in range(50):
        robot.step(0.001)
    assert robot.grasped and robot.joint_position == pytest.approx(0.0, abs=1e-6)
    robot.T_world_target = handle @ se3.transform_from_pose([0.6, 0, 0, 0, 0, 0, 1])  # along +x
    for _ in range(50):
        robot.step(0.001)
    assert scene.joint is not None and robot.travel == scene.joint.travel == 0.30
    assert robot.joint_position == 0.30, "the drawer stops at the end of its travel"


def test_the_kinematic_robot_follows_what_its_guard_admits_and_ignores_garbage():
    robot = KinematicRobot(kinematic_scene(find_task("pour")))
    guard = TargetGuard(TargetLimits(), 0.001, 0.0)
    pose = se3.pose_from_transform(robot.T_world_ee).tolist()
    _take_target(robot, guard, b"\xc1 not a target")
    assert robot.T_world_target is None
    near = [pose[0] + 0.001, *pose[1:]]
    _take_target(robot, guard, codec.encode_target(1, 1.0, near, "carry", "id", 1))
    np.testing.assert_allclose(robot.T_world_target, se3.transform_from_pose(near))
    far = [pose[0] + 0.5, *pose[1:]]  # beyond the 0.10 m a target may be from the arm
    _take_target(robot, guard, codec.encode_target(2, 1.001, far, "carry", "id", 2))
    assert robot.T_world_target is None, "refused: the arm stays where it is"


class _Board:
    """A board of the BoardSource interface that hands out ``chunk`` rows per poll,
    ``total`` in all."""

    name = "fake"
    rate_hz = 250.0

    def __init__(self, total: int, chunk: int = 25, channels: int = 2):
        self.left, self.chunk, self.channels = total, chunk, channels
        self.flushes = 0

    def poll(self, rows):
        n = min(self.chunk, self.left)
        self.left -= n
        return np.full((n, len(rows)), 1e-5)

    def flush(self):
        self.flushes += 1


def test_guided_calibration_cuts_the_stream_into_phases_of_exactly_the_asked_length():
    phases = PHASES[:3]
    board = _Board(total=round(0.2 * 250) * len(phases) + 7)
    said: list[str] = []
    out = guided.record(board, [1, 2], Chain(Filters(), 250.0, 2), seconds=0.2, interactive=False,
                        say=said.append, phases=phases)
    assert list(out) == [p.name for p in phases]
    assert all(v.shape == (50, 2) and np.isfinite(v).all() for v in out.values())
    assert said[0].startswith("[1/3] rest: relax every muscle (0.2 s)") and board.flushes == 0


def test_guided_calibration_waits_for_enter_and_names_the_phase_a_silent_board_stopped_in(monkeypatch):
    monkeypatch.setattr(guided, "NO_DATA_S", 0.05)
    board = _Board(total=50 + 10)
    asked: list[str] = []
    with pytest.raises(InputError, match=r"stopped delivering data in phase '\+x' \(10 of 50 samples\)"):
        guided.record(board, [1, 2], Chain(Filters(), 250.0, 2), seconds=0.2, interactive=True,
                      say=lambda s: None, ask=lambda s: asked.append(s) or "",
                      phases=(PHASES[0], Phase("+x", (1.0, 0.0, 0.0), "push")))
    assert len(asked) == 2 and board.flushes == 2


def test_the_emg_benchmark_reports_its_reads():
    r = bench_processing(seconds=0.3, rate=50.0)
    assert 10 <= r["reads"] <= 16 and r["board_rate_hz"] == 250.0
    assert 0 <= r["p50_ms"] <= r["p99_ms"] <= r["max_ms"] and r["envelope_group_delay_ms"] > 0


@pytest.mark.parametrize("module, prog", [("sctd_services.input", "sctd input"),
                                          ("sctd_services.learner", "sctd-learner")])
def test_python_m_entry_points_answer_help(module, prog, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", [module, "--help"])
    with pytest.raises(SystemExit) as done:
        runpy.run_module(module, run_name="__main__", alter_sys=False)
    assert done.value.code == 0
    assert capsys.readouterr().out.startswith(f"usage: {prog}")
