"""sctd's own arms as robot drivers (:mod:`sctd.robots`): ``sim``, the Pinocchio
simulator with its CAN joint bus and the task's physics, and ``kinematic``, the stand-in
that follows targets with a first-order lag. ``sctd robot sim --task pour`` serves either
through the same loop as any other arm. (``sctd sim`` is the simulator's own service,
with its extras: the bus mirror, the scene reset, the live view, ROS 2.)

Both run on the host's clock: :meth:`read` waits for the next period on absolute
deadlines (a late cycle is caught up, not skipped) and steps the arm once.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from sctd import se3
from sctd.robots import Reading, RobotDriver, RobotError
from sctd.task import Task
from sctd.timing import Ticker
from sctd.wire.codec import GripperCmd

from .kinematic import KinematicRobot, kinematic_scene
from .options import add_arm_arguments, arm_from_args


def _need_task(name: str, task: Task | None) -> Task:
    if task is None:
        raise RobotError(f"the {name} driver simulates a task's scene: name one with --task")
    return task


class _Clocked(RobotDriver):
    """A driver that steps its arm once per period of the host's clock."""

    owns_scene = True

    def __init__(self, rate: float):
        if not (np.isfinite(rate) and rate > 0):
            raise RobotError(f"--rate: must be positive, got {rate}")
        self._rate = rate
        self.ticker: Ticker | None = None

    @property
    def rate(self) -> float:
        return self._rate

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        parser.add_argument("--rate", type=float, default=1000.0, help="cycle rate, Hz (default %(default)s)")

    def connect(self) -> None:
        self.ticker = Ticker(1.0 / self._rate, spin=0.0)

    def recover(self) -> None:
        """Nothing faults here: the arm always follows."""

    def _tick(self, timeout: float) -> bool:
        assert self.ticker is not None, "connect() first"
        if self.ticker.due - time.monotonic() > timeout:
            time.sleep(timeout)
            return False
        self.ticker.wait()
        return True

    def health(self) -> dict[str, Any]:
        tk = self.ticker
        return {} if tk is None else {"late": tk.late, "skipped": tk.skipped, "cycles": tk.ticks}


class KinematicDriver(_Clocked):
    """The kinematic stand-in (:class:`~sctd_sim.kinematic.KinematicRobot`) behind the
    contract: no dynamics, the hand relaxes towards the target with ``--tau``."""

    name = "kinematic"
    description = "sctd's kinematic stand-in: follows targets with a first-order lag, no dynamics"

    def __init__(self, task: Task, rate: float = 1000.0, tau: float = 0.02):
        super().__init__(rate)
        self.task = task
        self.arm = KinematicRobot(kinematic_scene(task), tau=tau)

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        super().add_arguments(parser)
        parser.add_argument("--tau", type=float, default=0.02,
                            help="tracking time constant, s (default %(default)s)")

    @classmethod
    def from_args(cls, args: argparse.Namespace, task: Any) -> KinematicDriver:
        return cls(_need_task(cls.name, task), args.rate, args.tau)

    def read(self, timeout: float) -> Reading | None:
        if not self._tick(timeout):
            return None
        self.arm.step(1.0 / self._rate)
        return Reading(time.time(), self.arm.T_world_ee.copy(), wrench=[0.0] * 6, mode="move")

    def command(self, T_world_ee: np.ndarray | None, stamp: float | None = None) -> None:
        self.arm.T_world_target = T_world_ee  # None: stays where it is

    def objects(self) -> dict[str, np.ndarray]:
        return self.arm.objects()

    def outcome(self) -> dict[str, Any]:
        return {"scene": self.task.name, "task_object": self.task.object,
                "joint_position": self.arm.joint_position}


class SimDriver(_Clocked):
    """The Pinocchio simulator (:class:`~sctd_sim.simulation.Simulation`: the arm, its
    CAN joint bus, the task's physics) behind the contract."""

    name = "sim"
    description = "sctd's Pinocchio arm with its CAN joint bus and the task's physics"

    def __init__(self, task: Task, rate: float = 1000.0, trial_seed: int | None = None, arm: Any = None):
        super().__init__(rate)
        self.task, self.trial_seed, self.arm = task, trial_seed, arm
        self.sim: Any = None

    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        super().add_arguments(parser)
        add_arm_arguments(parser)

    @classmethod
    def from_args(cls, args: argparse.Namespace, task: Any) -> SimDriver:
        try:
            arm = arm_from_args(args)
        except ValueError as e:
            raise RobotError(str(e)) from None
        return cls(_need_task(cls.name, task), args.rate, args.trial_seed, arm)

    def connect(self) -> None:
        from .scenes import make_scene
        from .simulation import Simulation, trial_scene

        if self.trial_seed is not None:
            scene, q0 = trial_scene(self.task, self.trial_seed, self.arm)
        else:
            scene, q0 = make_scene(self.task), None
        self.sim = Simulation(scene=scene, q0=q0, rate=self._rate, arm=self.arm)
        super().connect()

    def close(self) -> None:
        if self.sim is not None:
            self.sim.close()
            self.sim = None

    def read(self, timeout: float) -> Reading | None:
        if not self._tick(timeout):
            return None
        sim = self.sim
        sim.step()
        m = sim.state_message()
        return Reading(time.time(), se3.transform_from_pose(m["pose"]), m["q"], m["dq"], m["wrench"],
                       "hold" if sim.arm.controller.holding else "move", gripper=m["gripper"])

    @property
    def has_gripper(self) -> bool:
        """The simulated hand has two fingers (:mod:`sctd_sim.fingers`)."""
        return True

    def grip(self, cmd: GripperCmd) -> None:
        self.sim.scene.grip(cmd)

    def command(self, T_world_ee: np.ndarray | None, stamp: float | None = None) -> None:
        if T_world_ee is None:
            self.sim.arm.controller.hold()
        else:
            self.sim.set_target(se3.pose_from_transform(T_world_ee).tolist(), stamp)

    def objects(self) -> dict[str, np.ndarray]:
        if self.sim is None:
            return {n: b.T_world for n, b in self.task.scene.bodies.items()}
        return {n: se3.transform_from_pose(p) for n, p in self.sim.objects().items()}

    def outcome(self) -> dict[str, Any]:
        return {"scene": self.sim.scene.name, "task_object": self.sim.scene.task_object,
                **self.sim.scene_outcome()}
