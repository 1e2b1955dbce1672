"""A task's scene judged beside an arm that is not ours: the objects where the task file
puts them (the held ones carried by the hand), and the outcome from the hand's readings.

It applies no physics: the arm's own stack moves the hand. Tasks whose outcome needs the
scene to push back (a handle on a joint, a surface, a button) stay in sctd's simulator,
which has the physics; :func:`observer_for` says so. What the hand takes (an item, a
knob) is judged from the arm's gripper readings: the item taken when the real fingers
hold something with its axis between them, let go when they open. A head (the drink's face) is judged
from the hand's pose alone: its readings need no force, and the face's push back, which
sctd's simulator applies, is not felt by the arm.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sctd import se3
from sctd.robots import RobotError
from sctd.task import Task
from sctd.wire.codec import GripperReading
from sctd_sim.fingers import MirroredFingers
from sctd_sim.scenes import TaskScene, make_scene

Array = np.ndarray


class SceneObserver:
    """The scene of ``task`` stepped with the hand's measured poses.

    Attributes
    ----------
    t : float
        Time since the first reading, s (on the readings' stamps): the task's clock.
    """

    def __init__(self, task: Task, trial_seed: int | None = None):
        scene = make_scene(task, trial_seed=trial_seed)
        assert isinstance(scene, TaskScene)
        self.scene = scene
        # the arm's own gripper, as its readings say: what the hand takes is judged from them
        self.fingers = scene.fingers = scene.world.fingers = MirroredFingers()
        self.t = 0.0
        self._last: tuple[float, Array] | None = None  # (stamp, T_world_ee) of the last reading

    def step(self, stamp: float, T_world_ee: Array, gripper: GripperReading | None = None) -> None:
        """One reading (with the gripper's, where the arm has one): the scene advances by
        the time since the previous one."""
        if gripper is not None:
            self.fingers.mirror(gripper.width, gripper.grasped)
        if self._last is None:
            self._last = (stamp, T_world_ee)
            self.scene.step(T_world_ee, np.zeros(6), 0.0)
            return
        stamp0, T0 = self._last
        dt = stamp - stamp0
        if dt <= 0.0:
            return  # the same state again (or a clock step back): nothing happened
        twist = np.zeros(6)
        twist[:3] = (T_world_ee[:3, 3] - T0[:3, 3]) / dt
        twist[3:] = np.array(se3.rotvec_from_matrix3(T_world_ee[:3, :3] @ T0[:3, :3].T)) / dt
        self.scene.step(T_world_ee, twist, dt)
        self.t += dt
        self._last = (stamp, T_world_ee)

    def objects(self) -> dict[str, Array]:
        T = self._last[1] if self._last is not None else self.scene.start_pose()
        return self.scene.objects(T)

    def outcome(self) -> dict[str, Any]:
        return self.scene.outcome()

    def reset(self) -> None:
        """The scene back to its start (contents full); the clock goes on."""
        self.scene.reset()


def observer_for(task: Task, trial_seed: int | None = None) -> SceneObserver:
    """The observer of ``task``'s scene (with ``trial_seed``, the seeded random start of
    an evaluation trial, as ``sctd sim --trial-seed`` draws it); RobotError when the task
    needs contact physics."""
    sc = task.scene
    # (a head is watched, not felt: the cup's touch of the lips is a reading of the
    # hand's pose; the arm's own stack feels no push back from the face)
    pushing = [*(f"joint {n}" for n in sc.joints),
               *(f"surface {n}" for n, b in sc.bodies.items()
                 if b.surface is not None or b.button is not None)]
    observer = SceneObserver(task, trial_seed)
    if pushing or observer.scene.contacts:
        what = ", ".join(pushing) or "a contact"
        raise RobotError(f"task {task.name}: its outcome needs contact physics ({what}), which only "
                         "sctd's simulator has: run it with sctd sim (or sctd robot sim)")
    return observer
