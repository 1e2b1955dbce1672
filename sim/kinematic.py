"""A kinematic stand-in robot: follows ``target`` with a first-order lag and publishes
``state`` and the scene's ``objects``. No dynamics; the Pinocchio simulator replaces it
where dynamics matter. Useful for runtime tests and benchmarks, where it keeps the
robot side cheap and deterministic.

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
from sctd.app.options import add_robot_argument
from sctd.timing import Ticker, set_timer_slack
from sctd.wire import Keys, codec
from sctd.wire.session import add_zenoh_arguments, session_from_args

from .guard import TargetGuard, TargetLimits


@dataclass
class KinematicScene:
    """World poses of the task objects and the arm's start pose."""

    name: str
    objects: dict[str, np.ndarray]
    T_world_ee0: np.ndarray
    attached: dict[str, np.ndarray] = field(default_factory=dict)  # name -> T_ee_object


def kinematic_scene(name: str) -> KinematicScene:
    """The pour and drawer scenes of the shipped skills (see skills/*.yaml).

    Task-object frames have z up and x pointing towards the robot (the generated
    demonstrations and the Pinocchio scenes use the same convention); the hand starts
    with its x axis towards the object.
    """
    yaw180 = se3.quaternion_from_rotvec([0, 0, math.pi])
    if name == "pour":
        return KinematicScene(
            "pour",
            {"mug": se3.transform_from_pose([0.60, 0.0, 0.78, *yaw180])},
            se3.transform_from_pose([0.35, 0.10, 0.90, 0, 0, 0, 1]),
            attached={"bottle_tip": se3.transform_from_pose([0, 0, 0.12, 0, 0, 0, 1])},
        )
    if name == "drawer":
        # Handle x axis points out of the drawer, towards the robot (world -x).
        return KinematicScene(
            "drawer",
            {"drawer_handle": se3.transform_from_pose([0.70, 0.0, 0.80, *yaw180])},
            se3.transform_from_pose([0.50, 0.15, 0.90, 0, 0, 0, 1]),
        )
    raise ValueError(f"unknown scene {name!r} (pour, drawer)")


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

    In the drawer scene the handle is grasped once the ee is within ``grasp_radius``;
    from then on the drawer slides along the handle's x axis with the ee (0 to 0.4 m).
    ``drawer_handle`` is the handle's pose with the drawer closed (it does not move, as
    in the Pinocchio scene and the demonstrations); ``drawer_open`` tells how far it is.
    """

    def __init__(self, scene: KinematicScene, tau: float = 0.02, grasp_radius: float = 0.02):
        self.scene = scene
        self.tau = tau
        self.grasp_radius = grasp_radius
        self.T_world_ee = scene.T_world_ee0.copy()
        self.T_world_target: np.ndarray | None = None
        self.grasped = False
        self.drawer_open = 0.0
        self._handle0 = scene.objects.get("drawer_handle")

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
                self.drawer_open = min(0.4, max(0.0, ee_along))

    def objects(self) -> dict[str, np.ndarray]:
        out = dict(self.scene.objects)
        for name, T_ee_o in self.scene.attached.items():
            out[name] = self.T_world_ee @ T_ee_o
        return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Add the kinematic robot's flags to ``p``."""
    p.add_argument("--task", "--scene", dest="task", default="pour", choices=("pour", "drawer"),
                   help="the stand-in geometry of the shipped skill of that name (default %(default)s)")
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
    add_arguments(p)
    args = p.parse_args(argv)
    keys = Keys(args.robot)
    robot = KinematicRobot(kinematic_scene(args.task), tau=args.tau)
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
