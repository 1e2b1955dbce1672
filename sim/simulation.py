"""The simulator as a service sees it: scene + arm + bus, plain-data in and out.

A service (``sctd sim``) drives it at its rate::

    with Simulation(scene=task, rate=1000) as sim:   # task: a sctd.task.Task
        while running:
            sim.set_target(pose7_world, stamp)      # when a target arrives
            sim.step()
            publish(sim.state_message(), sim.objects(), sim.scene_outcome())

Everything returned is plain Python (lists, floats, bools), ready for msgpack.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import can
import numpy as np

from sctd import se3
from sctd.task import Task

from .arm import SimArm
from .canbus import FaultConfig
from .controller import ImpedanceGains
from .options import SimSettings
from .robot import ArmModel, inverse_kinematics, load_arm_model
from .scenes import Scene, make_scene

RANDOM_SEEDS = 30
"""Pseudo-random postures :func:`start_posture` tries after the arm's own seeds."""


class Simulation:
    """Arm and scene stepped together.

    Parameters
    ----------
    scene : Task or Scene
        A task (:func:`~sctd_sim.scenes.make_scene` builds its scene) or a scene object
        (:class:`~sctd_sim.scenes.EmptyScene` for no objects).
    rate : float, optional
        Cycle rate, Hz.
    q0 : array_like, shape (7,), optional
        Initial posture; default the inverse kinematics of the scene's start pose.
    gains : ImpedanceGains, optional
    channel : str, optional
        Virtual CAN channel of the joint bus (default: unique per instance).
    bus_factory : callable, optional
        See :class:`~sctd_sim.arm.SimArm`.
    faults : FaultConfig, optional
        Bus faults (on the controller's end).
    drive_timeout : float, optional
        Drive command timeout, s.
    arm : ArmModel, optional
        The arm (:func:`~sctd_sim.robot.load_arm_model`); default the shipped one.
    compensate_payload : bool, optional
        Tell the arm's controller the load the hand holds (the bottle as it empties), as
        a real arm is configured; False only to measure what that buys.
    joint_bus : bool, optional
        False: the arm's joint values without the CAN frames, with the same outcome (see
        :class:`~sctd_sim.arm.SimArm`); not with ``faults`` or ``bus_factory``.

    Attributes
    ----------
    arm : SimArm
    scene : Scene
    """

    def __init__(
        self,
        scene: Task | Scene,
        rate: float = SimSettings.rate,
        *,
        q0: np.ndarray | None = None,
        gains: ImpedanceGains | None = None,
        channel: str | None = None,
        bus_factory: Callable[[str], can.BusABC] | None = None,
        faults: FaultConfig | None = None,
        drive_timeout: float = SimSettings.drive_timeout,
        arm: ArmModel | None = None,
        compensate_payload: bool = True,
        joint_bus: bool = True,
    ) -> None:
        self.compensate_payload = compensate_payload
        self.scene: Scene = make_scene(scene) if isinstance(scene, Task) else scene
        model = arm or load_arm_model()
        if q0 is None:
            q0 = start_posture(model, self.scene.start_pose(), getattr(self.scene, "default_start_pose",
                                                                       None))
        self.arm = SimArm(model, q0, rate=rate, gains=gains, channel=channel,
                          bus_factory=bus_factory, faults=faults, drive_timeout=drive_timeout,
                          joint_bus=joint_bus)
        self.q_home = self.arm.dynamics.q.copy()  # the known posture: where the arm started
        self._load: tuple[float, Any] = (-1.0, None)  # the payload the controller was last given
        self._payload()
        self._wrench = np.zeros(6)

    @property
    def t(self) -> float:
        """Simulated time, s."""
        return self.arm.t

    @property
    def dt(self) -> float:
        """Cycle period, s."""
        return self.arm.dt

    @property
    def channel(self) -> str:
        """Virtual CAN channel of the joint bus."""
        return self.arm.channel

    def step(self) -> None:
        """One cycle: scene interaction at the current state, then the arm's cycle."""
        dyn = self.arm.dynamics
        self._wrench = self.scene.step(dyn.ee_transform(), dyn.ee_velocity(), self.arm.dt)
        self._payload()
        self.arm.set_external_wrench(self._wrench)
        self.arm.step()

    def _payload(self) -> None:
        """The arm's load data, as a real arm is configured with the object it holds."""
        payload = self.scene.payload() if self.compensate_payload else None
        # (set again when it changes: as the bottle empties, or a scene's new load)
        if payload is not None and (payload[0] != self._load[0] or payload[1] is not self._load[1]):
            self._load = payload
            self.arm.controller.set_payload(*payload)

    def run(self, seconds: float) -> None:
        """Run ``round(seconds * rate)`` cycles."""
        for _ in range(round(seconds * self.arm.rate)):
            self.step()

    def set_target(self, pose: Any, stamp: float | None = None) -> None:
        """Follow a new ee target ``pose`` (``[x, y, z, qx, qy, qz, qw]``, world).

        ``stamp`` is the sender's time (s); only differences of stamps are used, for
        the target-velocity feed-forward. Non-finite poses, and anything but 7 numbers
        with a quaternion of norm >= 1e-6, are ignored.
        """
        # (checked on floats: numpy's vectorised checks of one pose cost more than the
        # conversion, which takes se3's single-pose path)
        try:
            p = [float(x) for x in pose]
        except (TypeError, ValueError):
            return
        if len(p) != 7 or not all(map(math.isfinite, p)):
            return
        _, _, _, qx, qy, qz, qw = p
        if math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) < 1e-6:
            return
        self.arm.set_target(se3.transform_from_flat(se3.flat_from_pose(p)), stamp)

    def home(self) -> None:
        """The arm back at rest in the posture it started in (:attr:`q_home`), holding
        there: a known posture between taught demonstrations."""
        self.arm.set_posture(self.q_home)

    def state_message(self) -> dict[str, Any]:
        """``pose`` [7], ``q`` [7], ``dq`` [7], ``wrench`` [6] and ``gripper`` (the fingers'
        :class:`~sctd.wire.codec.GripperReading`) (wire contract ``state``).

        ``q`` and ``dq`` are what the controller decoded from the joint bus (as a real
        arm reports its encoders), ``pose`` their forward kinematics; ``wrench`` is the
        external wrench acting on the ee (world axes, at the ee origin). The service
        adds ``seq`` and ``stamp``.
        """
        m = self.arm.master
        T_world_ee, _ = self.arm.controller.kinematics(m.q)  # (what its next update uses)
        return {
            "pose": se3.pose_from_flat(se3.flat_from_transform(T_world_ee)),
            "q": m.q.tolist(),
            "dq": m.dq.tolist(),
            "wrench": self._wrench.tolist(),
            "gripper": self.scene.gripper(),
        }

    def objects(self) -> dict[str, list[float]]:
        """Scene object poses in world, ``{name: [x, y, z, qx, qy, qz, qw]}``."""
        T_world_ee = self.arm.dynamics.ee_transform()
        return {name: se3.pose_from_flat(se3.flat_from_transform(T))
                for name, T in self.scene.objects(T_world_ee).items()}

    def scene_outcome(self) -> dict[str, Any]:
        """Task outcome (see the scene), plus ``t`` and the controller's ``holding``."""
        out = dict(self.scene.outcome())
        out["t"] = self.arm.t
        out["holding"] = self.arm.controller.holding
        return out

    def link_stats(self) -> dict[str, Any]:
        """Joint-bus counters (see :meth:`SimArm.link_stats`)."""
        return self.arm.link_stats()

    def close(self) -> None:
        """Release the bus endpoints."""
        self.arm.close()

    def __enter__(self) -> Simulation:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def trial_scene(task: Task, seed: int, arm: ArmModel | None = None, attempts: int = 50
                ) -> tuple[Scene, np.ndarray]:
    """The scene of evaluation trial ``seed`` and the arm's start posture: the seeded
    random start (:func:`~sctd_sim.scenes.randomize`), drawn again (deterministically)
    while the arm cannot reach it, so every run of trial ``seed`` starts the same."""
    model = arm or load_arm_model()
    for attempt in range(attempts):
        scene = make_scene(task, trial_seed=seed, attempt=attempt)
        try:
            return scene, start_posture(model, scene.start_pose(), getattr(scene, "default_start_pose", None))
        except RuntimeError:
            continue
    raise RuntimeError(f"trial {seed}: no reachable start in {attempts} draws")


def start_posture(arm: ArmModel, T_world_ee: np.ndarray, via: np.ndarray | None = None) -> np.ndarray:
    """Joint positions reaching ``T_world_ee``: IK from the arm's seed postures, then
    from fixed pseudo-random ones; with ``via`` (a nearby pose, such as
    a scene's default start), first by continuation from the posture of ``via`` along
    the straight path to ``T_world_ee``, so that nearby starts get nearby postures.

    The postures tried are the arm's own seeds (:attr:`ArmModel.seeds
    <sctd_sim.robot.ArmModel>`), then :data:`RANDOM_SEEDS` fixed pseudo-random ones in
    the middle 80 % of each joint's range. With seeds tuned for the arm (the shipped
    one), the first posture reached is the start; otherwise, of the postures reached
    from all of them, the one furthest from its joint limits (the smallest distance of a
    joint to a limit, as a fraction of that joint's range, largest).

    Raises
    ------
    RuntimeError
        If the pose is out of reach from every seed (the message gives the pose and the
        arm's URDF and frame).
    """
    if via is not None and not np.allclose(via, T_world_ee):
        q = start_posture(arm, via)
        ok = True
        for s in np.linspace(0.1, 1.0, 10):
            T = via.copy()
            T[:3, 3] = via[:3, 3] + s * (T_world_ee[:3, 3] - via[:3, 3])
            w = se3.rotvec_from_matrix(via[:3, :3].T @ T_world_ee[:3, :3])
            T[:3, :3] = via[:3, :3] @ se3.matrix_from_rotvec(s * w)
            q, ok = inverse_kinematics(arm, T, q_init=q, max_iter=300)
            if not ok:
                break
        if ok:
            return q
    return _posture_from_seeds(arm, T_world_ee)


def _posture_from_seeds(arm: ArmModel, T_world_ee: np.ndarray) -> np.ndarray:
    """:func:`start_posture` without ``via``: IK from every seed (see there)."""
    rng = np.random.default_rng(0)  # fixed: the same start posture every run
    # the pseudo-random seeds lie in the middle 80 % of each joint's range
    middle = 0.5 * (arm.q_lower + arm.q_upper)
    low, high = middle + 0.8 * (arm.q_lower - middle), middle + 0.8 * (arm.q_upper - middle)
    seeds = [*arm.seeds, *(rng.uniform(low, high) for _ in range(RANDOM_SEEDS))]
    span = arm.q_upper - arm.q_lower
    best, best_margin = None, -np.inf
    for seed in seeds:
        q, ok = inverse_kinematics(arm, T_world_ee, q_init=seed, max_iter=300)
        if ok and arm.seeds_tuned:
            return q
        margin = float(np.min(np.minimum(q - arm.q_lower, arm.q_upper - q) / span)) if ok else -np.inf
        if margin > best_margin:
            best, best_margin = q, margin
    if best is not None:
        return best
    pose = ", ".join(f"{x:.3f}" for x in se3.pose_from_transform(T_world_ee))
    raise RuntimeError(f"the start pose [{pose}] (x, y, z, qx, qy, qz, qw in the world) is out of reach "
                       f"of the arm of {arm.urdf_path.name} (frame {arm.ee_frame!r}): inverse "
                       f"kinematics from {len(seeds)} postures did not reach it")
