"""The simulated arm with its real data path, one 1 kHz cycle per :meth:`SimArm.step`.

Per cycle, in bus order::

    controller (from the joint states decoded last cycle) -> torque
    -> BusMaster encodes SYNC + 7 JointCmd frames -> bus
    -> JointDrives decode, check, saturate / brake -> ArmDynamics step (ABA)
    -> JointDrives encode 7 JointState frames -> bus
    -> BusMaster decodes and checks them -> measured q, dq, tau for the next cycle

so the controller only ever sees what crossed the bus (quantised, possibly late or
lost). The frames of one cycle are handed to ``on_frames`` callbacks as one list
(for a bus mirror or logger), so watching the bus costs one call per cycle.

With ``joint_bus=False`` the cycle skips the frames: the command's and the state's
values are rounded as the frames' signals round them (:class:`~sctd_sim.canbus.BusValues`)
and handed to the same controller and drive ends, which count, time out, brake and
saturate as they do for a clean cycle off the bus. Without faults every cycle on the
bus is clean, so both paths come to the same numbers, bit for bit (tested); the
lockstep trials take this one, for about 40 % less per arm cycle. It has no frames to
watch (``on_frames``) and no faults to inject.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from typing import Any

import can
import numpy as np
import pinocchio as pin

from sctd import se3

from .canbus import (
    BusMaster,
    BusValues,
    FastVirtualBus,
    FaultConfig,
    FaultInjectingBus,
    JointBusCodecs,
    JointDrives,
)
from .controller import CartesianImpedanceController, ImpedanceGains
from .dynamics import ArmDynamics
from .robot import ArmModel, load_arm_model

_channel_ids = itertools.count()

FrameCallback = Callable[[list[can.Message]], None]


class SimArm:
    """Arm, controller, drives and the joint bus between them.

    Parameters
    ----------
    arm : ArmModel, optional
        Default: the shipped URDF.
    q0 : array_like, shape (7,), optional
        Initial posture, rad; default the rest posture.
    rate : float, optional
        Cycle rate, Hz.
    gains : ImpedanceGains, optional
    channel : str, optional
        Virtual bus channel; default a fresh unique name. Any
        ``can.Bus(interface="virtual", channel=channel)`` in this process sees the
        frames.
    bus_factory : callable, optional
        ``bus_factory(channel) -> can.BusABC``, called twice (controller end, drives
        end); default :class:`~sctd_sim.canbus.FastVirtualBus`.
    faults : FaultConfig, optional
        Faults injected on the controller's end of the bus (``tx``: commands,
        ``rx``: joint states), timed on simulated time.
    drive_timeout : float, optional
        Command timeout of the drives, s.
    friction : bool, optional
        Viscous joint friction in the physics.
    joint_bus : bool, optional
        False: the values without the frames (module doc); not with ``faults`` or
        ``bus_factory``.

    Attributes
    ----------
    dynamics : ArmDynamics
    controller : CartesianImpedanceController
    master : BusMaster
    drives : JointDrives
    faults : FaultInjectingBus or None
    t : float
        Simulated time, s.
    """

    def __init__(
        self,
        arm: ArmModel | None = None,
        q0: np.ndarray | None = None,
        rate: float = 1000.0,
        gains: ImpedanceGains | None = None,
        channel: str | None = None,
        bus_factory: Callable[[str], can.BusABC] | None = None,
        faults: FaultConfig | None = None,
        drive_timeout: float = 0.01,
        friction: bool = True,
        joint_bus: bool = True,
    ) -> None:
        if rate <= 0:
            raise ValueError(f"rate: must be positive, got {rate}")
        if not joint_bus and (faults is not None or bus_factory is not None):
            raise ValueError("joint_bus: False has no frames to fault or to put on another bus")
        self.arm = arm or load_arm_model()
        self.rate = float(rate)
        self.dt = 1.0 / self.rate
        self.channel = channel or f"sctd-sim-{next(_channel_ids)}"
        factory = bus_factory or (lambda ch: FastVirtualBus(channel=ch))
        self.codecs = JointBusCodecs(self.arm.nq)
        self.dynamics = ArmDynamics(self.arm, q0, friction=friction)
        # null-space rest posture: where the arm starts (as a real arm is configured)
        self.controller = CartesianImpedanceController(self.arm, gains, q_rest=self.dynamics.q)
        self._buses: list[can.BusABC] = []
        ctrl_bus = factory(self.channel)
        self._buses.append(ctrl_bus)
        drive_bus = factory(self.channel)
        self._buses.append(drive_bus)
        self.faults: FaultInjectingBus | None = None
        if faults is not None:
            self.faults = FaultInjectingBus(ctrl_bus, faults, clock=lambda: self.t)
            self._buses[0] = ctrl_bus = self.faults
        self.master = BusMaster(ctrl_bus, self.codecs, self.dt)
        self.drives = JointDrives(drive_bus, self.codecs, self.arm.tau_max, drive_timeout)
        self.on_frames: list[FrameCallback] = []
        self.joint_bus = joint_bus
        self._values = None if joint_bus else BusValues(self.codecs)
        self.t = 0.0
        self.cycle = 0
        self.enabled = True
        self._closed = False
        # The controller's first measurement is the true initial state (as after the
        # drives' power-up report); from then on everything crosses the bus.
        self.master.q[:] = self.dynamics.q
        self.master.dq[:] = self.dynamics.dq

    def set_posture(self, q: np.ndarray) -> None:
        """Put the arm at rest in posture ``q`` (clipped to its limits) at once, its
        controller holding the pose there: a simulator's known posture between taught
        demonstrations (nothing a real arm does). The controller's next measurement is
        the new state, as at power-up."""
        dyn = self.dynamics
        dyn.q = np.clip(np.asarray(q, dtype=float), self.arm.q_lower, self.arm.q_upper)
        dyn.dq = np.zeros(self.arm.nq)
        self.master.q[:] = dyn.q
        self.master.dq[:] = dyn.dq
        self.controller.hold_at(ee_transform(self.arm, dyn.q))

    # -- one cycle -------------------------------------------------------------------
    def step(self) -> None:
        """Advance one cycle (``1 / rate`` s) along the full data path (without the
        frames when :attr:`joint_bus` is False)."""
        if self._values is not None:
            self._step_values(self._values)
            return
        t, master, drives, dyn = self.t, self.master, self.drives, self.dynamics
        q_meas, dq_meas = master.q, master.dq
        tau_cmd = self.controller.update(q_meas, dq_meas, t)
        frames = master.command_frames(tau_cmd, q_meas, dq_meas, self.enabled, stamp=t)
        sent = master.send(frames)
        drives.receive(t)
        tau, braked = drives.output(t)
        dyn.step(tau, self.dt, braked)
        self.t = t = t + self.dt
        state = drives.state_frames(dyn.q, dyn.dq, dyn.tau_motor, dyn.at_limit, stamp=t)
        drives.send(state)
        master.receive()
        self.cycle += 1
        if self.on_frames:
            batch = (frames if sent else []) + state
            for cb in self.on_frames:
                cb(batch)

    def _step_values(self, values: BusValues) -> None:
        """:meth:`step` without the frames: their values, handed over (module doc)."""
        t, master, drives, dyn = self.t, self.master, self.drives, self.dynamics
        tau_cmd = self.controller.update(master.q, master.dq, t)
        cycle = master.next_cycle()
        modes, taus = values.command(tau_cmd, self.enabled)
        drives.take(t, cycle & 0xF, modes, taus)
        tau, braked = drives.output(t)
        dyn.step(tau, self.dt, braked)
        self.t = t + self.dt
        status = drives.state_status(dyn.at_limit)
        q, dq, tau_meas = values.state(dyn.q, dyn.dq, dyn.tau_motor)
        master.accept(tuple(status), q, dq, tau_meas)
        self.cycle += 1

    def run(self, seconds: float) -> None:
        """Run ``round(seconds * rate)`` cycles."""
        for _ in range(round(seconds * self.rate)):
            self.step()

    # -- commands --------------------------------------------------------------------
    def set_target(self, T_world_ee: np.ndarray, stamp: float | None = None,
                   twist: np.ndarray | None = None) -> None:
        """Give the controller a new ee target (4x4, world); see the controller."""
        self.controller.set_target(T_world_ee, stamp, twist)

    def set_external_wrench(self, wrench: np.ndarray) -> None:
        """External wrench on the ee (world axes, ee origin), shape (6,)."""
        self.dynamics.set_external_wrench(wrench)

    # -- true state (physics) ----------------------------------------------------------
    @property
    def q(self) -> np.ndarray:
        """Joint positions, rad (physics truth)."""
        return self.dynamics.q.copy()

    @property
    def dq(self) -> np.ndarray:
        """Joint velocities, rad/s (physics truth)."""
        return self.dynamics.dq.copy()

    @property
    def tau(self) -> np.ndarray:
        """Applied motor torques, N m."""
        return self.dynamics.tau_motor.copy()

    @property
    def wrench(self) -> np.ndarray:
        """External wrench on the ee, world axes at the ee, shape (6,)."""
        return self.dynamics.wrench_ext.copy()

    @property
    def T_world_ee(self) -> np.ndarray:
        """End-effector pose in world, 4x4 (physics truth)."""
        return self.dynamics.ee_transform().copy()

    @property
    def ee_pose(self) -> np.ndarray:
        """End-effector pose in world as ``[x, y, z, qx, qy, qz, qw]``."""
        return se3.pose_from_transform(self.T_world_ee)

    @property
    def ee_twist(self) -> np.ndarray:
        """End-effector twist ``[v, w]`` in world axes, shape (6,)."""
        return self.dynamics.ee_velocity()

    def link_stats(self) -> dict[str, Any]:
        """Bus counters of both ends, the drives' brake state and injected faults."""
        out: dict[str, Any] = {
            "controller_rx": self.master.stats.as_dict(),
            "drives_rx": self.drives.stats.as_dict(),
            "brake_events": self.drives.brake_events,
            "braked": self.drives.braked.tolist(),
        }
        if self.faults is not None:
            c = self.faults.counts
            out["injected"] = {"dropped": c.dropped, "duplicated": c.duplicated,
                               "corrupted": c.corrupted, "delayed": c.delayed,
                               "refused": c.refused}
        return out

    # -- lifetime --------------------------------------------------------------------
    def close(self) -> None:
        """Shut down the bus endpoints (idempotent)."""
        if self._closed:
            return
        self._closed = True
        for bus in self._buses:
            bus.shutdown()

    def __enter__(self) -> SimArm:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def ee_transform(arm: ArmModel, q: np.ndarray) -> np.ndarray:
    """``T_world_ee`` (4x4) of the arm at joint positions ``q`` (uses a fresh Data)."""
    data = arm.model.createData()
    pin.framesForwardKinematics(arm.model, data, np.asarray(q, dtype=float))
    return data.oMf[arm.ee_frame_id].homogeneous.copy()
