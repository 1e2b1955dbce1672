"""A kinematic stand-in robot: follows ``target`` with a first-order lag and publishes
``state`` and the ``objects`` of a task's scene, where its task file puts them (the
same file the Pinocchio simulator builds its scene from). No dynamics; the Pinocchio
simulator replaces it where dynamics matter. Useful for runtime tests and benchmarks,
where it keeps the robot side cheap and deterministic.

    python -m sctd_sim.kinematic --task pour --connect tcp/127.0.0.1:7447
"""

from __future__ import annotations

import argparse
import contextlib
import math
import signal
import sys
import threading
import time
from dataclasses import dataclass, field

import numpy as np
import zenoh

from sctd import se3
from sctd.app.defaults import DefaultsError, defaults
from sctd.app.errors import fail
from sctd.app.options import add_robot_argument
from sctd.task import Task, TaskError, find_task
from sctd.task.kinds.joint import Joint
from sctd.timing import Ticker, set_timer_slack
from sctd.wire import Keys, codec
from sctd.wire.session import add_zenoh_arguments, session_from_args

from .guard import TargetGuard, TargetLimits


@dataclass
class KinematicScene:
    """World poses of the task's bodies, the arm's start pose, the frames the hand
    carries and the joint whose handle it can pull (from the task file)."""

    name: str
    objects: dict[str, np.ndarray]
    T_world_ee0: np.ndarray
    attached: dict[str, np.ndarray] = field(default_factory=dict)  # name -> T_ee_object
    joint: Joint | None = None


def kinematic_scene(t: Task) -> KinematicScene:
    """The scene of task ``t`` as the stand-in robot plays it: the bodies where the
    task file puts them, the hand at the task's start, the held object's frames carried
    by the hand, and the task's first prismatic joint, if any."""
    sc = t.scene
    held = sc.held.frames if sc.held is not None else {}
    joint = next((j for j in sc.joints.values() if j.kind == "prismatic"), None)
    return KinematicScene(t.name, {name: b.T_world.copy() for name, b in sc.bodies.items()},
                          sc.start.T_world.copy(), {name: T.copy() for name, T in held.items()}, joint)


def towards(T_a: np.ndarray, T_b: np.ndarray, s: float) -> np.ndarray:
    """The pose a fraction ``s`` of the way from ``T_a`` to ``T_b`` (4x4): the origin on
    the straight line, the orientation ``R_a exp(s log(R_a^T R_b))``. The stand-in
    robot's own motion, apart from the runtime's step limiting."""
    R_a, R_b = T_a[:3, :3], T_b[:3, :3]
    T = np.eye(4)
    T[:3, :3] = R_a @ se3.matrix_from_rotvec(s * se3.rotvec_from_matrix(R_a.T @ R_b))
    T[:3, 3] = T_a[:3, 3] + s * (T_b[:3, 3] - T_a[:3, 3])
    return T


class KinematicRobot:
    """Per-cycle model: the ee pose relaxes towards the target with time constant tau.

    In a scene with a joint (a drawer) its handle is grasped once the ee is within
    ``grasp_radius`` (default: the joint's grasp radius); from then on the joint slides
    along the handle's x axis with the ee, from 0 to its travel. The handle's published
    frame is its pose with the joint at 0 (it does not move, as in the Pinocchio scene
    and the demonstrations); ``joint_position`` tells how far the joint is.
    """

    def __init__(self, scene: KinematicScene, tau: float = 0.02, grasp_radius: float | None = None):
        self.scene = scene
        self.tau = tau
        joint = scene.joint
        if grasp_radius is None:
            grasp_radius = joint.grasp.radius if joint is not None else 0.0
        self.grasp_radius = grasp_radius
        self.travel = joint.travel if joint is not None else 0.0
        self.T_world_ee = scene.T_world_ee0.copy()
        self.T_world_target: np.ndarray | None = None
        self.grasped = False
        self.joint_position = 0.0
        self._handle0 = scene.objects[joint.handle] if joint is not None else None

    def step(self, dt: float) -> None:
        if self.T_world_target is not None:
            a = 1.0 - math.exp(-dt / self.tau)
            self.T_world_ee = towards(self.T_world_ee, self.T_world_target, a)
        if self._handle0 is not None:
            d = self.T_world_ee[:3, 3] - self._handle0[:3, 3]
            if not self.grasped and np.linalg.norm(d) < self.grasp_radius:
                self.grasped = True
            if self.grasped:
                axis = self._handle0[:3, 0]
                ee_along = float(np.dot(self.T_world_ee[:3, 3] - self._handle0[:3, 3], axis))
                self.joint_position = min(self.travel, max(0.0, ee_along))

    def objects(self) -> dict[str, np.ndarray]:
        out = dict(self.scene.objects)
        for name, T_ee_o in self.scene.attached.items():
            out[name] = self.T_world_ee @ T_ee_o
        return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the kinematic robot's flags to ``p``."""
    p.add_argument("--task", "--scene", dest="task", default=defaults().task, metavar="NAME|FILE",
                   help="the task whose scene to stand in for: the path of a task file, or the name of a "
                        "shipped or registered one; sctd tasks lists them (default %(default)s)")
    add_robot_argument(p)
    p.add_argument("--rate", type=float, default=1000.0, help="state rate, Hz")
    p.add_argument("--object-rate", type=float, default=50.0, help="objects rate, Hz")
    p.add_argument("--tau", type=float, default=0.02, help="tracking time constant, s")
    p.add_argument("--duration", type=float, default=None)
    add_zenoh_arguments(p)


def main(argv: list[str] | None = None) -> int:
    """``python -m sctd_sim.kinematic``: follow targets until SIGINT/SIGTERM or
    ``--duration``."""
    p = argparse.ArgumentParser(prog="sctd-kinematic", description=__doc__.split("\n\n")[0])
    try:
        add_arguments(p)  # --task's default is in sctd/app/defaults.yaml
    except DefaultsError as e:
        return fail("kinematic", str(e))
    args = p.parse_args(argv)
    keys = Keys(args.robot)
    try:
        robot = KinematicRobot(kinematic_scene(find_task(args.task)), tau=args.tau)
    except TaskError as e:
        return fail("kinematic", f"--task: {e}")
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *a: stop.set())
    signal.signal(signal.SIGTERM, lambda *a: stop.set())
    with session_from_args(args) as session, contextlib.ExitStack() as stack:
        sub = stack.enter_context(session.declare_subscriber(keys.target, zenoh.handlers.RingChannel(1)))
        pub_state = stack.enter_context(session.declare_publisher(
            keys.state, express=True, congestion_control=zenoh.CongestionControl.DROP))
        pubs = {n: stack.enter_context(session.declare_publisher(keys.objects(n)))
                for n in robot.objects()}
        _follow(robot, sub, pub_state, pubs, args, stop)
    return 0


def _follow(robot: KinematicRobot, sub: zenoh.Subscriber, pub_state: zenoh.Publisher,
            pubs: dict[str, zenoh.Publisher], args: argparse.Namespace, stop: threading.Event) -> None:
    """The fixed-rate loop: take the newest target, step, publish state (and objects)."""
    set_timer_slack(1)
    period = 1.0 / args.rate
    every = max(1, round(args.rate / args.object_rate))
    ticker = Ticker(period, spin=0.0)
    guard = TargetGuard(TargetLimits(), period, time.time())  # as the Pinocchio sim's arm
    end = None if args.duration is None else time.monotonic() + args.duration
    seq = 0
    while not stop.is_set():
        now, _ = ticker.wait()
        if end is not None and now > end:
            break
        s = sub.try_recv()
        if s is not None:
            _take_target(robot, guard, s.payload.to_bytes())
        robot.step(period)
        wall = time.time()
        pose = se3.pose_from_transform(robot.T_world_ee).tolist()
        pub_state.put(codec.encode_state(seq, wall, pose, wrench=[0.0] * 6))
        if seq % every == 0:
            for name, T in robot.objects().items():
                pubs[name].put(codec.encode_object(seq, wall, se3.pose_from_transform(T).tolist()))
        seq += 1


def _take_target(robot: KinematicRobot, guard: TargetGuard, payload: bytes) -> None:
    """Follow a target the guard admits; refused, stay where the arm is; undecodable,
    ignore it."""
    try:
        msg = codec.decode_target(payload)
    except codec.DecodeError:
        return
    F_measured = se3.flat_from_transform(robot.T_world_ee)
    if guard.admit(msg["pose"], msg["stamp"], F_measured, robot.T_world_target is not None):
        robot.T_world_target = se3.transform_from_pose(msg["pose"])
    else:
        robot.T_world_target = None  # refused: stay where it is


if __name__ == "__main__":
    sys.exit(main())
