"""The ``franky`` driver: a Franka FR3 (or Panda) through franky and libfranka's protocol.

franky (``pip install 'sctd[franky]'``) is libfranka for Python; the driver talks to the
arm's control interface (FCI) as any libfranka program does, and so to franky-sim, a
server that speaks the same protocol on 127.0.0.1 (what the tests run against).

- **State**: libfranka's robot state, read at the arm's 1 kHz (the driver waits for
  each new state): the hand pose ``O_T_EE`` (with the end-effector frame set from
  ``--tool`` on the arm, ``set_ee``), ``q``, ``dq``, the estimated external wrench
  ``O_F_ext_hat_K`` and the robot mode. The arm's clock (ms since it booted) is mapped to
  this host's Unix time by the least-delayed offset seen (:class:`ClockMap`).
- **Targets** go into franky's ``CartesianImpedanceTrackingMotion`` (a torque controller
  in libfranka's 1 kHz loop, franky's own): ``set_reference`` with each admitted target.
  It starts at the first target, seeded at the measured pose; the arm's own torque-rate
  limit (``max_delta_tau``), joint-limit repulsion and libfranka's collision reflexes
  stay in force. The stiffness is a flag: the hand sags off the reference by about
  force / stiffness. Each reference carries the targets' twist as feed-forward, in the
  arm's own time (:attr:`ClockMap.pace`: a simulator below real time moves its hand
  faster per simulated second). ``--friction`` has the controller compensate the
  joints' Coulomb friction (franky's friction compensation), which otherwise holds the
  hand a few millimetres off a reference that is still.
- **Faults**: a control exception (a reflex: collision, joint or Cartesian limit, a
  ``communication_constraints_violation``), a lost link (libfranka's UDP timeout, about
  1 s after the arm went silent) and a protocol error raise
  :class:`~sctd.robots.RobotFault`; the motion is over and nothing is commanded until
  :meth:`FrankyDriver.recover` (the arm's automatic error recovery, or a new connection
  after a lost link).
"""

from __future__ import annotations

import argparse
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sctd import se3
from sctd.app.options import add_arguments, from_namespace
from sctd.robots import Reading, RobotDriver, RobotError, RobotFault

Array = np.ndarray
FF_TAU = 0.02  # s: the feed-forward twist's low-pass filter
START_TIMEOUT = 60.0  # s --move-to-start may take
POLL_PERIOD = 0.005  # s between looks at the motion's exception
LOAD_RADIUS = 0.04  # m: the held object's inertia is taken as a solid sphere's of this radius
PACE_WINDOW = 0.5  # s of this host's time over which the arm's pace is measured
PACE_MIN = 0.2  # the slowest pace believed (a stalled arm is the link's fault, not its pace)
# franky-sim's FR3 joint friction (its MuJoCo model's frictionloss, N m): --friction's
# value for trials against franky-sim; a real arm's has to be identified
FRANKY_SIM_FRICTION = (1.137, 1.137, 1.137, 1.137, 0.763, 0.44, 0.248)


def _franky_sim_urdf() -> Path | None:
    """franky-sim's FR3 URDF, where franky-sim is installed (it is the arm there)."""
    try:
        import franky_sim
    except ImportError:
        return None
    return Path(franky_sim.__file__).parent / "assets" / "fr3.urdf"


def _task_load(task: Any) -> tuple[float, Array]:
    """``--load task``: the held object's mass with its contents (kg) and its centre of
    mass in the hand's frame; RobotError without a task or a held object."""
    held = None if task is None else task.scene.held
    if held is None:
        raise RobotError("--load task: needs --task with a held object (the task's scene holds none)"
                         if task is not None else "--load task: needs --task")
    contents = held.contents.mass if held.contents is not None else 0.0
    return held.mass + contents, np.asarray(held.com, dtype=float)


def _joint_flag(text: str) -> Array:
    """Seven comma-separated non-negative numbers, one per joint (ValueError naming what
    is wrong)."""
    try:
        v = np.array([float(x) for x in text.split(",")])
    except ValueError:
        raise ValueError(f"not numbers: {text!r}") from None
    if len(v) != 7:
        raise ValueError(f"needs 7 values, one per joint, got {len(v)}: {text!r}")
    if not (np.all(np.isfinite(v)) and np.all(v >= 0)):
        raise ValueError(f"each value must be finite and at least 0: {text!r}")
    return v


def _pose_flag(text: str) -> Array:
    """``x,y,z,qx,qy,qz,qw`` -> 4x4 (ValueError naming what is wrong)."""
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise ValueError(f"not numbers: {text!r}") from None
    if len(v) != 7 or not np.all(np.isfinite(v)):
        raise ValueError(f"expected 7 finite numbers x,y,z,qx,qy,qz,qw, got {text!r}")
    if abs(np.linalg.norm(v[3:]) - 1.0) > 1e-3:
        raise ValueError(f"the quaternion of {text!r} is not a unit quaternion")
    return se3.transform_from_pose(v)


class ClockMap:
    """The arm's clock (s since it booted) to this host's Unix time.

    The offset follows the smallest ``wall - arm`` seen (the state that arrived with the
    least delay) at once, and a larger one by a fraction ``gain`` per state: the two
    clocks' rates differ (a real arm's by parts per million; a simulator slower than real
    time, as franky-sim on two cores at 0.8, by a lot), so the offset must be allowed to
    grow. A stamp is then late by about the link's delay jitter, and one from a slow
    simulator by ``(1 / speed - 1) * period / gain`` (about 5 ms at 0.8). It starts again
    when the arm's clock goes back (the arm rebooted).
    """

    def __init__(self, gain: float = 0.05):
        self.gain = gain
        self.offset: float | None = None
        self._t: float | None = None
        self.pace = 1.0  # the arm's clock's seconds per second of this host's (see below)
        self._anchor: tuple[float, float] | None = None  # (t_arm, wall) a pace window began

    def stamp(self, t_arm: float, wall: float) -> float:
        """The Unix time of the arm's ``t_arm``, received at ``wall``."""
        off = wall - t_arm
        if self.offset is None or self._t is None or t_arm < self._t or off <= self.offset:
            if self._t is not None and t_arm < self._t:
                self._anchor, self.pace = None, 1.0  # the arm restarted
            self.offset = off
        else:
            self.offset += self.gain * (off - self.offset)
        self._t = t_arm
        self._measure_pace(t_arm, wall)
        return t_arm + self.offset

    def _measure_pace(self, t_arm: float, wall: float) -> None:
        """The arm's pace: its clock's advance over this host's, over windows of
        ``PACE_WINDOW`` s, smoothed. 1 for a real arm (to parts per million); a simulator
        below real time runs its physics, and so the arm's motion, at its pace."""
        if self._anchor is None:
            self._anchor = (t_arm, wall)
            return
        t0, w0 = self._anchor
        if wall - w0 < PACE_WINDOW:
            return
        window = min(1.0, max(PACE_MIN, (t_arm - t0) / (wall - w0)))
        self.pace += 0.5 * (window - self.pace)
        self._anchor = (t_arm, wall)


def _flag(default: Any, help: str, **meta: Any) -> Any:
    return field(default=default, metadata={"help": help, **meta})


@dataclass(frozen=True)
class FrankyOptions:
    """The franky driver's settings as ``sctd robot franky`` takes them: each field is the
    flag of the same name (:mod:`sctd.app.options`), poses and per-joint values as the
    text given (:meth:`FrankyDriver.from_options` parses and checks them)."""

    host: str | None = _flag(None, "the arm's FCI address (franky-sim prints its own); needed to serve")
    tool: str | None = _flag(None, "the task's hand frame in the arm's nominal end effector (the flange "
                                   "and the hand Desk is configured with), set on the arm at every "
                                   "connection (set_ee, NE_T_EE; default: identity, the nominal end "
                                   "effector)", metavar="x,y,z,qx,qy,qz,qw")
    base: str | None = _flag(None, "the arm's base in the task's world (default: the world is the base)",
                             metavar="x,y,z,qx,qy,qz,qw")
    stiffness: float = _flag(2000.0, "translational stiffness of the tracking controller, N/m")
    rotational_stiffness: float = _flag(150.0, "rotational stiffness, N m/rad")
    realtime: str = _flag("enforce", "libfranka's real-time check: enforce (a real arm: a PREEMPT_RT "
                                     "kernel) or ignore (franky-sim, a laptop)",
                          choices=("enforce", "ignore"))
    start_dynamics: float = _flag(0.1, "with --move-to-start: the fraction of the arm's velocity, "
                                       "acceleration and jerk limits the move takes")
    urdf: str | None = _flag(None, "the arm's URDF, for --move-to-start's joint posture (default: "
                                   "franky-sim's FR3 where franky-sim is installed)", metavar="FILE")
    ee_frame: str = _flag("fr3_hand_tcp", "the URDF's frame of the arm's nominal end effector",
                          metavar="NAME")
    posture_stiffness: float = _flag(5.0, "N m/rad of the tracking controller's nullspace pull towards "
                                          "the start posture (with --move-to-start)")
    friction: str | None = _flag(None, "each joint's Coulomb friction, N m, that the tracking controller "
                                       "compensates (franky's friction compensation, capped at these "
                                       "values); identify your arm's before using it (franky-sim's FR3: "
                                       f"{','.join(f'{x:g}' for x in FRANKY_SIM_FRICTION)}; default: none)",
                                 metavar="N_M,... (7)")
    friction_viscous: str | None = _flag(None, "each joint's viscous friction, N m s/rad, compensated "
                                               "with --friction (default: none)", metavar="N_M_S,... (7)")
    load: str = _flag("none", "the payload set on the arm (libfranka's set_load) at each connection: "
                              "task: --task's held object, its mass with its contents and its centre of "
                              "mass (a real arm holding it needs it for its gravity and collision "
                              "models); none: no payload, set so whatever an earlier program set goes "
                              "(franky-sim holds no object, and a load set there would lift the hand)",
                      choices=("none", "task"))
    gripper: bool = _flag(False, "drive the arm's Franka Hand too (franky's Gripper): commands from "
                                 "sctd/<robot>/gripper, its width and grasp in every state")
    connect_timeout: float = _flag(5.0, "s to wait for the arm's answer when connecting")
    collision_torque: float = _flag(20.0, "joint torque threshold of the arm's collision reflex, N m")
    collision_force: float = _flag(30.0, "Cartesian force threshold of the collision reflex, N")


class FrankyDriver(RobotDriver):
    """See the module doc. Its settings and flags: :class:`FrankyOptions`."""

    name = "franky"
    description = "a Franka FR3 or Panda through franky and libfranka's protocol (franky-sim too)"

    def __init__(self, host: str, *, tool: Array | None = None, base: Array | None = None,
                 stiffness: float = FrankyOptions.stiffness,
                 rotational_stiffness: float = FrankyOptions.rotational_stiffness,
                 realtime: str = FrankyOptions.realtime,
                 collision_torque: float = FrankyOptions.collision_torque,
                 collision_force: float = FrankyOptions.collision_force,
                 connect_timeout: float = FrankyOptions.connect_timeout,
                 start_dynamics: float = FrankyOptions.start_dynamics, urdf: Path | None = None,
                 ee_frame: str = FrankyOptions.ee_frame,
                 posture_stiffness: float = FrankyOptions.posture_stiffness,
                 friction: Array | None = None, friction_viscous: Array | None = None, gripper: bool = False,
                 load: tuple[float, Array] | None = None):
        self.host = host
        self.load = load  # (kg, centre of mass in the task's hand frame) set with set_load
        self.load_set: dict[str, Any] | None = None  # the payload set (set_load), for health
        self._arm_load: float | None = None  # the payload the arm's state reported, kg
        self.use_gripper = gripper
        self.hand: Any = None  # the FrankyHand, with --gripper, once connected
        # joint friction the tracking controller compensates (N m, N m s/rad; None: none)
        self.friction, self.friction_viscous = friction, friction_viscous
        self.urdf, self.ee_frame, self.posture_stiffness = urdf, ee_frame, posture_stiffness
        self.posture: Array | None = None  # the joint posture the nullspace holds (from --move-to-start)
        self.start_dynamics = start_dynamics
        self.connect_timeout = connect_timeout
        self.T_ne_ee = np.eye(4) if tool is None else tool  # NE_T_EE: the task's ee in the nominal EE
        self.T_world_base = np.eye(4) if base is None else base
        self.T_base_world = se3.invert_transform(self.T_world_base)
        self._base_identity = bool(np.array_equal(self.T_world_base, np.eye(4)))
        self.stiffness, self.rotational_stiffness = stiffness, rotational_stiffness
        self.realtime = realtime
        self.collision = (collision_torque, collision_force)
        self.robot: Any = None
        self.motion: Any = None
        self.fault: RobotFault | None = None
        self.clock = ClockMap()
        self._t_last = -1.0
        self._next_due = 0.0
        self._poll_due = 0.0  # when poll_motion is due next
        self._last_ref: tuple[Array, float | None] | None = None  # the last target and its stamp
        self._twist = np.zeros(6)  # the feed-forward twist (base frame), filtered
        self.counts = {"states": 0, "repeats": 0, "references": 0, "motions": 0, "connections": 0}

    # -- flags -------------------------------------------------------------------------
    @classmethod
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        add_arguments(parser, FrankyOptions, show_default=True)

    @classmethod
    def from_args(cls, args: argparse.Namespace, task: Any) -> FrankyDriver:
        return cls.from_options(from_namespace(FrankyOptions, args), task)

    @classmethod
    def from_options(cls, o: FrankyOptions, task: Any) -> FrankyDriver:
        """The driver of checked options (the poses and per-joint values parsed);
        RobotError naming the flag otherwise."""
        if not o.host:
            raise RobotError("--host: the arm's FCI address is needed (franky-sim prints its own)")
        poses = {}  # the flags of poses and of per-joint values, parsed
        for flag, parse in (("tool", _pose_flag), ("base", _pose_flag), ("friction", _joint_flag),
                            ("friction_viscous", _joint_flag)):
            text = getattr(o, flag)
            try:
                poses[flag] = None if text is None else parse(text)
            except ValueError as e:
                raise RobotError(f"--{flag.replace('_', '-')}: {e}") from None
        if poses["friction_viscous"] is not None and poses["friction"] is None:
            raise RobotError("--friction-viscous: needs --friction (the Coulomb part)")
        for flag in ("stiffness", "rotational_stiffness", "collision_torque", "collision_force",
                     "connect_timeout", "start_dynamics", "posture_stiffness"):
            v = getattr(o, flag)
            if not (np.isfinite(v) and v > 0):
                raise RobotError(f"--{flag.replace('_', '-')}: must be positive, got {v}")
        return cls(o.host, tool=poses["tool"], base=poses["base"], stiffness=o.stiffness,
                   rotational_stiffness=o.rotational_stiffness, realtime=o.realtime,
                   collision_torque=o.collision_torque, collision_force=o.collision_force,
                   connect_timeout=o.connect_timeout, start_dynamics=min(1.0, o.start_dynamics),
                   urdf=Path(o.urdf) if o.urdf else None, ee_frame=o.ee_frame,
                   posture_stiffness=o.posture_stiffness, friction=poses["friction"],
                   friction_viscous=poses["friction_viscous"], gripper=o.gripper,
                   load=_task_load(task) if o.load == "task" else None)

    @property
    def rate(self) -> float:
        return 1000.0

    # -- the link ----------------------------------------------------------------------
    def connect(self) -> None:
        import franky

        cfg = franky.RealtimeConfig.Enforce if self.realtime == "enforce" else franky.RealtimeConfig.Ignore
        robot = self._open(lambda: franky.Robot(self.host, realtime_config=cfg))
        try:
            robot.set_collision_behavior(self.collision[0], self.collision[1])
            # absolute, so that it is the same whatever an earlier program left set
            robot.set_ee(self.T_ne_ee.flatten(order="F").tolist())
            self._set_load(robot)  # absolute too: the arm keeps what an earlier program set
        except (franky.NetworkException, franky.CommandException, franky.ProtocolException) as e:
            raise RobotError(f"{self.host}: setting up the arm: {type(e).__name__}: {e}") from None
        self.robot, self.motion, self.fault = robot, None, None
        self._t_last, self._arm_load = -1.0, None
        self.counts["connections"] += 1
        if self.use_gripper and self.hand is None:
            from .franky_gripper import FrankyHand

            self.hand = FrankyHand(self._open(lambda: franky.Gripper(self.host)))

    def _set_load(self, robot: Any) -> None:
        """The held object as the arm's payload (``--load task``), else none: its centre
        of mass from the task's hand frame to the flange (``F_T_NE`` from Desk's end
        effector, then ``--tool``), its inertia that of a solid sphere of
        ``LOAD_RADIUS``."""
        mass, com_ee = self.load if self.load is not None else (0.0, np.zeros(3))
        F_T_ee = np.asarray(robot.state.F_T_NE.matrix) @ self.T_ne_ee
        com_F = (F_T_ee @ np.r_[com_ee, 1.0])[:3] if mass > 0 else np.zeros(3)
        inertia = np.eye(3) * 0.4 * mass * LOAD_RADIUS**2
        robot.set_load(mass, com_F.tolist(), inertia.flatten(order="F").tolist())
        self.load_set = {"mass": mass, "com_flange": [round(float(x), 6) for x in com_F]}

    def _open(self, make: Any) -> Any:
        """``make()`` (franky.Robot) in a thread of its own, given ``connect_timeout`` s:
        libfranka waits for as long as a peer keeps the socket open without a valid
        reply, and a hostile or confused server on the arm's port must be an error, not a
        hang. (A thread left waiting on such a peer ends with the process.)"""
        import franky

        box: dict[str, Any] = {}

        def attempt() -> None:
            try:
                box["robot"] = make()
            except Exception as e:  # handed to the caller below
                box["error"] = e

        t = threading.Thread(target=attempt, name="franky-connect", daemon=True)
        t.start()
        t.join(self.connect_timeout)
        if t.is_alive():
            raise RobotError(f"{self.host}: no answer in libfranka's protocol within "
                             f"{self.connect_timeout:g} s "
                             "(a Franka arm's FCI answers at once: is this its address, is FCI active?)")
        e = box.get("error")
        if isinstance(e, franky.RealtimeException):
            raise RobotError(f"{e} (--realtime ignore runs without a real-time kernel, as against "
                             "franky-sim)")
        if e is not None:
            raise RobotError(f"{self.host}: {type(e).__name__}: {e}")
        return box["robot"]

    @property
    def has_gripper(self) -> bool:
        return self.use_gripper

    def grip(self, cmd: Any) -> None:
        if self.hand is None:
            raise RobotError(f"{self.host}: the gripper is not connected")
        self.hand.submit(cmd)

    def close(self) -> None:
        hand, self.hand = self.hand, None
        if hand is not None:
            hand.close()  # the fingers stay as they are: whatever is held stays held
        robot, self.robot = self.robot, None
        if robot is None:
            return
        if self.motion is not None and self.fault is None:
            import franky

            try:  # ramp the torque down and let the arm come to rest (no preemption)
                robot.move(franky.TorqueStopMotion(), asynchronous=True)
                robot.join_motion(timeout=2.0)
            except Exception:  # closing anyway: the arm stops when we go
                pass
        self.motion = None

    # -- state -------------------------------------------------------------------------
    def read(self, timeout: float) -> Reading | None:
        if self.robot is None or (self.fault is not None and self.fault.kind == "connection"):
            time.sleep(timeout)
            return None
        end = time.monotonic() + timeout
        while True:
            st = self._state()
            t = st.time.to_sec()
            if t != self._t_last:
                break
            self.counts["repeats"] += 1
            now = time.monotonic()
            if now > end:
                return None
            # In a motion the state is the newest one: the next is due a period after
            # the last new one arrived (sooner when the arm's clock ran ahead).
            time.sleep(min(max(self._next_due - now, 0.0002), end - now))
        self._next_due = time.monotonic() + 0.00095
        self._t_last = t
        self.counts["states"] += 1
        return self._reading(st, t)

    def _state(self) -> Any:
        """The newest state; the motion's exception (a reflex, a lost link) as a fault."""
        import franky

        try:
            now = time.monotonic()
            if self.motion is not None and self.fault is None and now >= self._poll_due:
                # (about 0.13 ms a call: at most every POLL_PERIOD, which bounds how late
                # a fault is noticed; the arm itself stopped at once)
                self._poll_due = now + POLL_PERIOD
                self.robot.poll_motion()
            return self.robot.state
        except franky.ControlException as e:
            raise self._fault("reflex" if "reflex" in str(e).lower() else "control", e) from None
        except franky.NetworkException as e:
            raise self._fault("connection", e) from None
        except (franky.ProtocolException, franky.IncompatibleVersionException) as e:
            raise self._fault("protocol", e) from None

    def _fault(self, kind: str, e: Exception) -> RobotFault:
        self.motion = None  # the motion is over: libfranka stopped it
        self.fault = RobotFault(kind, f"{type(e).__name__}: {e}")
        return self.fault

    def _reading(self, st: Any, t: float) -> Reading:
        self._arm_load = st.m_load  # (a float attribute: health reads it without the link)
        T_base_ee = st.O_T_EE.matrix
        T_world_ee = T_base_ee if self._base_identity else self.T_world_base @ T_base_ee
        w = st.O_F_ext_hat_K
        if not self._base_identity:
            R = self.T_world_base[:3, :3]
            w = np.concatenate([R @ w[:3], R @ w[3:]])
        return Reading(self.clock.stamp(t, time.time()), T_world_ee, st.q.tolist(), st.dq.tolist(),
                       w.tolist(), st.robot_mode.name.lower(), self.hand.reading if self.hand else None)

    # -- targets -----------------------------------------------------------------------
    def command(self, T_world_ee: Array | None, stamp: float | None = None) -> None:
        import franky

        if self.robot is None or self.fault is not None:
            return
        if T_world_ee is None:
            if self.motion is None:
                return  # not following: the arm holds on its own
            T_base_ee = np.asarray(self.robot.current_pose.end_effector_pose.matrix)
            twist = np.zeros(6)
            self._last_ref = None
        else:
            T_base_ee = self.T_base_world @ T_world_ee
            twist = self._feed_forward(T_base_ee, stamp)
        ref = franky.CartesianReference(target=franky.Affine(T_base_ee),
                                        target_twist=franky.Twist(twist[:3], twist[3:]))
        try:
            if self.motion is None:
                self._start_motion(ref)
            else:
                self.motion.set_reference(ref)
        except franky.ControlException as e:
            raise self._fault("control", e) from None
        except franky.NetworkException as e:
            raise self._fault("connection", e) from None
        self.counts["references"] += 1

    def _feed_forward(self, T_base_ee: Array, stamp: float | None) -> Array:
        """The reference's twist (base frame) from the last two targets' stamps, low-pass
        filtered (time constant ``FF_TAU``): the tracking controller's damping then acts on
        the twist error, and a hand that follows a moving target does not trail it by
        damping * speed / stiffness. Zero for a first target or a hold."""
        last, self._last_ref = self._last_ref, (T_base_ee, stamp)
        if last is None or stamp is None or last[1] is None or not stamp > last[1]:
            self._twist[:] = 0.0 if last is None else self._twist
            return self._twist.copy()
        # the targets' twist in the arm's own time, which is the controller's: a
        # simulator below real time has to move its hand faster per simulated second
        T0, dt = last[0], (stamp - last[1]) * self.clock.pace
        raw = np.empty(6)
        raw[:3] = (T_base_ee[:3, 3] - T0[:3, 3]) / dt
        raw[3:] = np.array(se3.rotvec_from_matrix3(T_base_ee[:3, :3] @ T0[:3, :3].T)) / dt
        a = dt / (FF_TAU + dt)
        self._twist += a * (raw - self._twist)
        return self._twist.copy()

    def _start_motion(self, ref: Any) -> None:
        import franky

        posture = None if self.posture is None else franky.PostureTask(self.posture.tolist(),
                                                                       self.posture_stiffness)
        friction = None
        if self.friction is not None:
            viscous = np.zeros(7) if self.friction_viscous is None else self.friction_viscous
            friction = franky.FrictionCompensationParams(coulomb=self.friction.tolist(),
                                                         viscous=viscous.tolist(),
                                                         max_torque=self.friction.tolist())
        m = franky.CartesianImpedanceTrackingMotion(translational_stiffness=self.stiffness,
                                                    rotational_stiffness=self.rotational_stiffness,
                                                    posture_task=posture, friction=friction)
        m.set_reference(ref)
        self.robot.move(m, asynchronous=True)
        self.motion = m
        self.counts["motions"] += 1

    def move_to(self, T_world_ee: Array) -> None:
        """The hand to the pose in joint space: the posture is the inverse kinematics of
        the arm's model (``--urdf``, ``--ee-frame``) furthest from the joint limits, and
        franky's ``JointMotion`` (Ruckig: the arm's velocity, acceleration and jerk limits,
        scaled by ``--start-dynamics``) takes the arm there. (A Cartesian move would keep
        whatever elbow and wrist the arm had, and can end at a joint limit.) The tracking
        controller's nullspace then holds the arm near that posture."""
        import franky

        if self.robot is None or self.fault is not None:
            raise RobotError("not connected, or faulted: recover first")
        q = self._start_posture(T_world_ee)
        try:
            self.robot.move(franky.JointMotion(q.tolist(), relative_dynamics_factor=self.start_dynamics),
                            asynchronous=True)
            end = time.monotonic() + START_TIMEOUT
            while not self.robot.join_motion(timeout=0.1):  # bounded: an arm that never
                if time.monotonic() > end:  # arrives (a limit, a planner that stalls) is an error
                    self.robot.stop()
                    raise RobotError(f"the arm did not reach the start within {START_TIMEOUT:.0f} s; "
                                     f"it stopped at {self._where()}")
        except (franky.ControlException, franky.InvalidMotionTypeException, RuntimeError) as e:
            # (franky's planner reports an invalid goal as a RuntimeError)
            raise RobotError(f"moving to the start {se3.pose_from_transform(T_world_ee).round(4).tolist()}: "
                             f"{type(e).__name__}: {e}") from None
        except franky.NetworkException as e:
            raise self._fault("connection", e) from None
        self.posture = q
        self._t_last = -1.0

    def _start_posture(self, T_world_ee: Array) -> Array:
        """The joint posture of the hand at ``T_world_ee`` furthest from the limits."""
        from sctd_sim.robot import ArmModelError, load_arm_model
        from sctd_sim.simulation import start_posture

        urdf = self.urdf or _franky_sim_urdf()
        if urdf is None:
            raise RobotError("--move-to-start needs the arm's model: --urdf FILE (Franka's "
                             "franka_description has the FR3's) and --ee-frame (its hand's TCP frame)")
        try:
            arm = load_arm_model(urdf, ee_frame=self.ee_frame)
        except ArmModelError as e:
            raise RobotError(f"--urdf: {e}") from None
        T_base_tcp = self.T_base_world @ T_world_ee @ se3.invert_transform(self.T_ne_ee)
        try:
            return start_posture(arm, T_base_tcp)
        except RuntimeError as e:
            raise RobotError(f"the start is out of the arm's reach ({e}): check --base and --tool") from None

    def _where(self) -> list[float]:
        T = self.T_world_base @ np.asarray(self.robot.current_pose.end_effector_pose.matrix)
        return [round(x, 4) for x in se3.pose_from_transform(T).tolist()]

    # -- recovery ----------------------------------------------------------------------
    def recover(self) -> None:
        import franky

        fault = self.fault
        if fault is None:
            return
        if fault.kind == "connection" or self.robot is None:
            self.robot = None
            self.connect()
            return
        try:
            ok = self.robot.recover_from_errors()
        except (franky.NetworkException, franky.CommandException) as e:
            raise RobotError(f"the arm's automatic error recovery: {type(e).__name__}: {e}") from None
        if not ok:
            raise RobotError("the arm's automatic error recovery did not succeed: check the arm (its "
                             "user stop, Desk) and try again")
        self.fault, self.motion, self._t_last, self._last_ref = None, None, -1.0, None

    def health(self) -> dict[str, Any]:
        return {**self.counts, "host": self.host, "clock_offset": self.clock.offset,
                "arm_pace": round(self.clock.pace, 3), "load": self.load_set,
                # the payload the arm's own state reported last (libfranka's m_load), set or
                # not (from the newest reading: health never waits on the link)
                "arm_load_kg": self._arm_load,
                **(self.hand.health() if self.hand else {})}
