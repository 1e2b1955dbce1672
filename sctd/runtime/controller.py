"""The pure part of the runtime tick (DESIGN §7 steps 1-6): no I/O, no clocks.

:class:`Controller` turns the newest input, state and object samples into the next
target pose, applying the skill (transitions, mappings, constraints) and the safety
limits. The daemon (:mod:`sctd.runtime.daemon`) feeds it from Zenoh and publishes what
it returns; tests drive it directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from .. import se3
from ..skill import Skill, SkillEngine
from .safety import limit_offset, limit_step, sanitize_input

Array = NDArray[np.float64]


@dataclass
class RuntimeConfig:
    """Daemon settings; defaults are the safe ones (SI units)."""

    rate: float = 1000.0  # Hz
    robot: str = "edan"
    device: str = "*"  # which input/<device> to follow; '*' = newest of any
    input_timeout: float = 0.1  # s (MoveIt Servo's default)
    state_timeout: float = 0.1  # s
    object_timeout: float = 1.0  # s
    stamp_check: bool = True  # also reject input whose sender stamp is older than the timeout
    deadband: float = 0.02  # per input axis
    max_linear_speed: float = 0.25  # m/s (ISO 10218 reduced speed)
    max_angular_speed: float = 1.0  # rad/s
    max_offset: float = 0.05  # m, target vs measured
    max_offset_rotation: float = 0.35  # rad
    status_rate: float = 20.0  # Hz

    @property
    def period(self) -> float:
        return 1.0 / self.rate


@dataclass
class Sample:
    """A decoded message and its arrival time on the receiver's monotonic clock."""

    seq: int
    stamp: float
    received: float
    T: Array | None = None  # pose as a 4x4 transform (state, objects)
    u: tuple[float, ...] = ()
    wrench: list[float] | None = None
    pose: list[float] | None = None  # as received (objects), to tell an unchanged pose


class _Target:
    """A target's world transform, multiplied out only when somebody asks for it: the
    daemon publishes the pose and never needs the matrix. Either the matrix ``T`` or
    the flat poses of the object (world) and the target (object frame)."""

    __slots__ = ("F_obj", "F_world_obj", "T")

    def __init__(self, F_world_obj: se3.Flat | None, F_obj: se3.Flat | None,
                 T: Array | None = None):
        self.F_world_obj, self.F_obj, self.T = F_world_obj, F_obj, T

    def matrix(self) -> Array:
        if self.T is None:
            assert self.F_world_obj is not None and self.F_obj is not None
            self.T = se3.matrix4_from_flat(se3.compose_flat(self.F_world_obj, self.F_obj))
        return self.T


class TickResult:
    """What one tick decided: the mode (waiting | hold | stopped | running), the target
    (``pose`` as [x, y, z, qx, qy, qz, qw] and ``T_world_target``; None while waiting),
    the FSM state, and the input sequence number it followed."""

    __slots__ = ("_target", "in_seq", "input_ok", "mode", "pose", "state", "state_changed")

    def __init__(self, mode: str, target: _Target | None, state: str, in_seq: int,
                 state_changed: bool = False, input_ok: bool = False,
                 pose: list[float] | None = None):
        self.mode, self._target, self.state, self.in_seq = mode, target, state, in_seq
        self.state_changed, self.input_ok, self.pose = state_changed, input_ok, pose

    @property
    def T_world_target(self) -> Array | None:
        return None if self._target is None else self._target.matrix()


@dataclass
class Counters:
    nonfinite_input: int = 0
    stale_input: int = 0
    nonfinite_output: int = 0
    offset_limited: int = 0
    transitions: int = 0
    swaps: int = 0
    drops: dict[str, int] = field(default_factory=dict)

    def drop(self, reason: str) -> None:
        self.drops[reason] = self.drops.get(reason, 0) + 1


class Controller:
    """Skill + safety, one tick at a time.

    Parameters
    ----------
    skill : Skill
    config : RuntimeConfig
    """

    def __init__(self, skill: Skill, config: RuntimeConfig):
        self.config = config
        self.counters = Counters()
        self._target: _Target | None = None
        self.mode = "waiting"
        self.last_in_seq = -1
        self._pose: list[float] | None = None
        self._obj_T: Array | None = None  # the object sample's transform the caches are for
        self._obj_F: se3.Flat = ()  # its flat pose (world) and inverse
        self._obj_F_inv: se3.Flat = ()
        self._obj_q: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0)
        self._T_obj_target: se3.Flat | None = None  # the target in the object frame
        self._rot: tuple[float, ...] | None = None  # the target's rotation in the object frame
        self._q_world: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0)
        self._install(skill, now=0.0, keep_state=False)

    @property
    def T_world_target(self) -> Array | None:
        """The current target in the world frame (None until the first state arrives)."""
        return None if self._target is None else self._target.matrix()

    def _install(self, skill: Skill, now: float, keep_state: bool,
                 engine: SkillEngine | None = None) -> None:
        old = getattr(self, "engine", None)
        self.engine = engine if engine is not None else SkillEngine(skill)
        self.skill = skill
        names = [s.name for s in skill.states]
        if keep_state and old is not None and old.state in names:
            self.engine.reset(now, old.state)
        else:
            self.engine.reset(now)
        lim = skill.limits
        self.v_max = min(lim.max_linear_speed, self.config.max_linear_speed)
        self.w_max = min(lim.max_angular_speed, self.config.max_angular_speed)

    def swap(self, skill: Skill, now: float, engine: SkillEngine | None = None) -> None:
        """Replace the skill between two ticks; keep the active state if the new skill
        has one of the same name, else start from its start state. Pass an ``engine``
        built off the tick thread (KD-trees take time to build)."""
        self._install(skill, now, keep_state=True, engine=engine)
        self.counters.swaps += 1

    def tick(self, now: float, wall: float, inp: Sample | None, state: Sample | None,
             obj: Sample | None) -> TickResult:
        """One control step.

        Parameters
        ----------
        now : float
            Monotonic time (s) of this tick; arrival times of samples are on this clock.
        wall : float
            Unix time (s), for the sender-stamp check of the input watchdog.
        inp, state, obj : Sample or None
            Newest input, robot state (ee pose in world) and task-object pose (in world).
        """
        cfg = self.config
        dt = cfg.period
        u, input_ok = self._command(now, wall, inp)
        in_seq = inp.seq if inp is not None else -1
        state_ok = state is not None and now - state.received <= cfg.state_timeout
        obj_ok = obj is not None and now - obj.received <= cfg.object_timeout

        if self._target is None:
            if not (state_ok and obj_ok):
                self.mode = "waiting"
                return TickResult("waiting", None, self.engine.state, in_seq)
            assert state is not None and state.T is not None
            self._target = _Target(None, None, state.T.copy())
            self._T_obj_target = None
            self._rot = None
            self._pose = se3.pose_from_matrix4(state.T)
            self.engine.reset(now, self.engine.state)
        if not (state_ok and obj_ok):
            self.mode = "hold"  # stale robot state or object pose: hold the last target
            return TickResult("hold", self._target, self.engine.state, in_seq, pose=self._pose)

        assert state is not None and obj is not None and state.T is not None and obj.T is not None
        # The tick works in the object frame, where the skill is, on flat poses (12
        # floats, see sctd.se3); the target is kept there while the object's pose does
        # not change, so a tick converts one pose (the measured one) in and one (the new
        # target) out.
        if obj.T is not self._obj_T:  # a new object sample: re-express the target
            self._obj_T = obj.T
            F = self._obj_F = se3.flat_from_matrix4(obj.T)
            self._obj_F_inv = se3.invert_flat(F)
            self._obj_q = se3.quaternion_from_rows(*F[:9])
            self._T_obj_target = None
            self._rot = None
        F_obj_world = self._obj_F_inv
        F_meas = se3.compose_flat(F_obj_world, se3.flat_from_matrix4(state.T))
        force = None
        if state.wrench is not None:
            r = F_obj_world
            fx, fy, fz = state.wrench[:3]
            force = np.array([r[0] * fx + r[1] * fy + r[2] * fz, r[3] * fx + r[4] * fy + r[5] * fz,
                              r[6] * fx + r[7] * fy + r[8] * fz])
        changed = self.engine.update(F_meas, now, force)
        if changed:
            self.counters.transitions += 1

        F_prev = self._T_obj_target
        if F_prev is None:
            F_prev = self._T_obj_target = se3.compose_flat(
                F_obj_world, se3.flat_from_matrix4(self._target.matrix()))
        # How far the user pushes: the input's norm, clipped to 1 (a diagonal push of a
        # 3-axis stick is one push, not two); steps are bounded by mag * speed * dt.
        mag = min(1.0, math.hypot(*u))
        F_new = F_prev
        if mag > 0.0:
            F_new = limit_step(F_prev, self.engine.command_flat(F_prev, u, dt),
                               mag * self.v_max * dt, mag * self.w_max * dt)
        limited = limit_offset(F_new, F_meas, cfg.max_offset, cfg.max_offset_rotation)
        if limited is not F_new:
            self.counters.offset_limited += 1
            F_new = limited
        if F_new is not F_prev and not self._accept(F_new):
            self.counters.nonfinite_output += 1  # never publish a non-finite target
        self.mode = "running" if input_ok else "stopped"
        return TickResult(self.mode, self._target, self.engine.state, in_seq, changed,
                          input_ok, self._pose)

    def _accept(self, F: se3.Flat) -> bool:
        """Make the flat object-frame pose F the target, or refuse it (False) when it is
        not finite.

        The orientation is re-orthonormalised through its unit quaternion whenever it
        changed, so that millions of composed steps cannot drift off SO(3); a step that
        only translates keeps the previous (already orthonormal) orientation exactly,
        and with it the previous world quaternion. The published pose: world quaternion
        = object's * target's, world position = object's rotation times the target's
        position plus the object's position.
        """
        if not math.isfinite(sum(F)):  # NaN and inf propagate through the sum
            return False
        rot: tuple[float, ...] = F[:9]
        x, y, z = F[9], F[10], F[11]
        if rot != self._rot:
            q = se3.quaternion_from_rows(*rot)
            rot = se3.rows_from_quaternion(*q)
            F = (*rot, x, y, z)
            self._rot = rot
            qx, qy, qz, qw = se3.compose_quaternions(self._obj_q, q)
            self._q_world = (qx, qy, qz, qw) if qw >= 0.0 else (-qx, -qy, -qz, -qw)
        o = self._obj_F
        self._pose = [o[0] * x + o[1] * y + o[2] * z + o[9], o[3] * x + o[4] * y + o[5] * z + o[10],
                      o[6] * x + o[7] * y + o[8] * z + o[11], *self._q_world]
        self._T_obj_target = F
        self._target = _Target(o, F)
        return True

    def _command(self, now: float, wall: float, inp: Sample | None) -> tuple[tuple[float, ...], bool]:
        """The user command this tick: zero when missing, stale or not finite."""
        cfg = self.config
        if inp is None:
            return (0.0, 0.0, 0.0), False
        stale = now - inp.received > cfg.input_timeout or (
            cfg.stamp_check and abs(wall - inp.stamp) > cfg.input_timeout
        )
        if stale:
            if inp.seq != self.last_in_seq:
                self.counters.stale_input += 1
                self.last_in_seq = inp.seq
            return (0.0,) * len(inp.u), False
        u, ok = sanitize_input(inp.u, cfg.deadband)
        if not ok and inp.seq != self.last_in_seq:
            self.counters.nonfinite_input += 1
        self.last_in_seq = inp.seq
        return u, ok

