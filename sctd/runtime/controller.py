"""The pure part of the runtime tick (the skill and the safety limits): no I/O, no clocks.

:class:`Controller` turns the command the input arbiter chose and the newest state and
object samples into the next target pose, applying the skill (transitions, mappings,
constraints) and the safety limits. :class:`~sctd.runtime.driver.TickDriver` feeds it
(messages in, targets out) for the daemon, the lockstep evaluation and the benches.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import NDArray

from .. import se3
from ..skill import Skill, SkillEngine, StuckDetector
from ..wire.codec import BUTTON_ESCAPE, GripperCmd, GripperReading
from .arbiter import STALE_GRACE, Command
from .safety import grows_offset, limit_step

Array = NDArray[np.float64]


def _setting(default, help: str):
    """A RuntimeConfig field with the help text its ``sctd run`` flag shows."""
    return field(default=default, metadata={"help": help})


@dataclass
class RuntimeConfig:
    """Daemon settings; defaults are the safe ones (SI units). Every field with a help
    text is a ``sctd run`` flag of the same name (``--max-offset`` for ``max_offset``;
    ``--no-stamp-check`` clears ``stamp_check``), derived by :mod:`sctd.app.options`."""

    rate: float = _setting(1000.0, "tick rate, Hz")
    robot: str = _setting("edan", "robot name in the key prefix sctd/<robot>")
    device: str = _setting("*", "input device to follow ('*': newest of any)")
    input_timeout: float = _setting(0.1, "s after which input is stale: zero command (MoveIt Servo's "
                                          "default)")
    stale_grace: float = _setting(STALE_GRACE, "s a push may stay stale (a stalled link) and still take "
                                               "the motion back without the stick centred first (0: never)")
    state_timeout: float = _setting(0.1, "s after which the robot state is stale: no target")
    object_timeout: float = _setting(1.0, "s after which the task object's pose is stale: no target")
    stamp_check: bool = field(default=True, metadata={
        "flag": "--no-stamp-check",
        "help": "judge input, state and object ages by arrival time only (senders with "
                "unsynchronised clocks)"})
    deadband: float = _setting(0.02, "per input axis")
    max_linear_speed: float = _setting(0.25, "m/s at full input (ISO 10218 reduced speed)")
    max_angular_speed: float = _setting(1.0, "rad/s at full input")
    max_offset: float = _setting(0.05, "m between target and measured pose that a step may not "
                                       "grow past")
    max_offset_rotation: float = _setting(0.35, "rad between target and measured pose that a step "
                                                "may not grow past")
    state_jump: float = _setting(0.05, "m between two consecutive states that counts as a "
                                       "discontinuity (fault: no target)")
    state_jump_rotation: float = _setting(0.3, "rad between two consecutive states that counts as "
                                               "a discontinuity")
    reseed_after: float = _setting(0.5, "s of continuous state (and zero input) after a "
                                        "discontinuity before the target is re-seeded at the "
                                        "measured pose")
    status_rate: float = _setting(20.0, "Hz of the status messages")
    stuck_after: float = _setting(5.0, "s of held input without progress towards any of the "
                                       "active state's transitions that count as stuck "
                                       "(status.stuck, counters.stuck; 0: never)")
    # The gripper (sctd.runtime.gripper). sctd run takes their defaults from sctd/app/defaults.yaml
    # (gripper: force, open_hold); these are the same numbers, for what builds a config in code.
    grasp_force: float = _setting(20.0, "N: the force bound of a close the grasp button asks for")
    grasp_open_hold: float = _setting(0.5, "s the grasp button must be held to open a hand that holds "
                                           "something (a tremor cannot drop a cup)")

    @property
    def period(self) -> float:
        return 1.0 / self.rate


@dataclass
class Sample:
    """A decoded message and its arrival time on the receiver's monotonic clock.

    ``F`` is a state's or object's pose as a flat transform (see :mod:`sctd.se3`), in
    world; ``pose`` the object's pose as received (to tell an unchanged pose). A state
    also carries the :class:`~sctd.runtime.safety.StateWatch` verdict on its stream:
    ``epoch`` (discontinuities before it) and ``since`` (arrival of the first state of
    its continuous run), the arm's ``fault`` when it reports one and the gripper's
    reading where it has one. (Input messages have their own slots: :mod:`.arbiter`.)
    """

    seq: int
    stamp: float
    received: float
    F: se3.Flat | None = None
    wrench: list[float] | None = None
    pose: list[float] | None = None
    epoch: int = 0
    since: float = 0.0
    fault: str | None = None
    gripper: GripperReading | None = None


class _Target:
    """A target's world transform, multiplied out only when somebody asks for it: the
    daemon publishes the pose and never needs the matrix. Held as the flat poses of the
    object (world) and of the target (object frame)."""

    __slots__ = ("F_obj", "F_world_obj", "T")

    def __init__(self, F_world_obj: se3.Flat, F_obj: se3.Flat):
        self.F_world_obj, self.F_obj = F_world_obj, F_obj
        self.T: Array | None = None

    def matrix(self) -> Array:
        if self.T is None:
            self.T = se3.transform_from_flat(se3.compose_flat(self.F_world_obj, self.F_obj))
        return self.T


class TickResult:
    """What one tick decided: the mode, the target to publish (``pose`` as
    [x, y, z, qx, qy, qz, qw] and ``T_world_target``; None when nothing is published),
    the FSM state, the input sequence number it followed, and the gripper message to put
    (``gripper``: a new command or a repeat, None for none; :mod:`.gripper`).

    Modes: ``waiting`` (no state or object pose yet) and ``fault`` (the state stream
    jumped or restarted; waiting to re-seed) publish nothing; ``hold`` publishes nothing
    while the state is stale and the unchanged target while only the object pose is;
    ``stopped`` (no valid input: the target stays) and ``running`` publish.
    """

    __slots__ = ("_target", "device", "gripper", "in_seq", "input_ok", "mode", "pose", "seed", "state",
                 "state_changed")

    def __init__(self, mode: str, target: _Target | None, state: str, cmd: Command,
                 state_changed: bool = False, input_ok: bool = False,
                 pose: list[float] | None = None, seed: bool = False):
        self.mode, self._target, self.state = mode, target, state
        self.in_seq, self.device = cmd.in_seq, cmd.device
        self.state_changed, self.input_ok, self.pose = state_changed, input_ok, pose
        self.seed = seed  # the target is the measured pose: a (re-)seed, not a step
        self.gripper: GripperCmd | None = None  # the gripper message to put this tick (the driver's)

    @property
    def T_world_target(self) -> Array | None:
        return None if self._target is None else self._target.matrix()


@dataclass
class Counters:
    nonfinite_input: int = 0
    stale_input: int = 0
    disabled_input: int = 0
    presses: int = 0
    ignored_input: int = 0  # messages of a device that did not own the motion, not at rest
    ignored_presses: int = 0  # presses of a device while another owned the motion
    stops: int = 0  # stop requests (rising edges, any device)
    stale_disarms: int = 0  # pushes that went stale: the device must send a zero first
    input_deferred: int = 0  # drains that stopped at the ingress's input budget
    stale_state: int = 0
    stale_object: int = 0
    nonfinite_output: int = 0
    offset_limited: int = 0
    state_discontinuity: int = 0
    reseeds: int = 0
    transitions: int = 0
    escapes: int = 0
    stuck: int = 0
    swaps: int = 0
    robot_fault_ticks: int = 0  # ticks held because the arm reported a fault
    drops: dict[str, int] = field(default_factory=dict)

    def drop(self, reason: str) -> None:
        self.drops[reason] = self.drops.get(reason, 0) + 1

    def as_dict(self) -> dict[str, int]:
        """The counts (``status.counters``); the drops apart (``status.dropped``)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "drops"}


# Periods of motion a step may take from the time allowance: a tick late by up to one
# period loses no motion, and ticks run back to back after a stall add at most two.
STEP_ALLOWANCE = 2.0

class Controller:
    """Skill + safety, one tick at a time.

    The target moves only on input, and only within the per-tick bound: ``min(1, |u|)``
    times the maximum speeds times the period, where ``|u|`` is measured on the input
    axes the active state's mappings read. The period is taken from a time allowance:
    the time since the last tick is added to it, up to ``STEP_ALLOWANCE`` periods, and a
    step uses at most a period of it. Ticks that run back to back after a stall (the
    ticker catches up a few before it skips) so step by the time that passed, not a
    period each: over any span of ticks the target moves at most the speed times the
    span plus ``STEP_ALLOWANCE`` periods, on the real clock. Steps that would take the target further than
    ``max_offset`` from the measured pose are refused. Every published target is either
    within that bound of the previous one or, right after a (re-)seed, the measured pose:
    the target is seeded when the first state and object pose arrive, re-seeded when the
    state comes back after going stale (``hold``), and after a discontinuity of the state
    stream (``fault``) once the state has been continuous for ``reseed_after`` s with zero
    input.

    Parameters
    ----------
    skill : Skill
    config : RuntimeConfig
    """

    def __init__(self, skill: Skill, config: RuntimeConfig, engine: SkillEngine | None = None):
        self.config = config
        self.counters = Counters()
        self._target: _Target | None = None
        self.mode = "waiting"
        self._pose: list[float] | None = None
        self._publishing = False  # the last tick published: the next may step from its target
        self._fault = False
        self._epoch = 0  # the state stream's epoch the target belongs to
        self._stale_seq = {"state": -1, "object": -1}
        self._obj_F_src: se3.Flat | None = None  # the object sample's pose the caches are for
        self._obj_F: se3.Flat = se3.FLAT_IDENTITY  # its flat pose (world) and inverse
        self._obj_F_inv: se3.Flat = se3.FLAT_IDENTITY
        self._obj_q: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0)
        self._T_obj_target: se3.Flat | None = None  # the target in the object frame
        self._rot: tuple[float, ...] | None = None  # the target's rotation in the object frame
        self._q_world: tuple[float, ...] = (0.0, 0.0, 0.0, 1.0)
        self._allowance = config.period  # s of motion the next steps may use
        self._last_tick: float | None = None
        self.stuck_detector = StuckDetector(config.stuck_after)
        self._install(skill, now=0.0, keep_state=False, engine=engine)

    @property
    def T_world_target(self) -> Array | None:
        """The current target in the world frame (None until the first state arrives)."""
        return None if self._target is None else self._target.matrix()

    def _install(self, skill: Skill, now: float, keep_state: bool,
                 engine: SkillEngine | None = None) -> None:
        old = getattr(self, "engine", None)
        self.engine = engine if engine is not None else SkillEngine(skill)
        self.skill = skill
        self.objects = frozenset(skill.objects())  # the bodies whose poses the skill needs
        names = [s.name for s in skill.states]
        if keep_state and old is not None and old.state in names:
            self.engine.reset(now, old.state)
        else:
            self.engine.reset(now)
        lim = skill.limits
        self.v_max = min(lim.max_linear_speed, self.config.max_linear_speed)
        self.w_max = min(lim.max_angular_speed, self.config.max_angular_speed)

    def stuck(self, now: float) -> dict[str, object] | None:
        """``status.stuck``: the state the user is stuck in and for how long (s) the held
        input has made no progress, or None."""
        since = self.stuck_detector.since
        if since is None:
            return None
        return {"state": self.engine.state, "since": round(now - since, 3)}

    def swap(self, skill: Skill, now: float, engine: SkillEngine | None = None) -> None:
        """Replace the skill between two ticks; keep the active state if the new skill
        has one of the same name, else start from its start state. Pass an ``engine``
        built off the tick thread (KD-trees take time to build)."""
        self._install(skill, now, keep_state=True, engine=engine)
        self.counters.swaps += 1

    def engage(self, skill: Skill, engine: SkillEngine, now: float) -> None:
        """Run ``skill`` (a skill set's member, or its teleoperation) from its start state
        from the next tick on, with ``engine``; the target stays where it is (in the
        world: it is re-expressed in the new skill's object frame at the next tick)."""
        self._install(skill, now, keep_state=False, engine=engine)
        self.stuck_detector.release()

    @property
    def pose(self) -> list[float] | None:
        """The newest target pose (world), None before the first."""
        return self._pose

    def tick(self, now: float, wall: float, cmd: Command, state: Sample | None,
             obj: Sample | None) -> TickResult:
        """One control step.

        Parameters
        ----------
        now : float
            Monotonic time (s) of this tick; arrival times of samples are on this clock.
        wall : float
            Unix time (s), for the sender-stamp checks (state, objects).
        cmd : Command
            The input this tick follows (:meth:`.arbiter.InputArbiter.select`): already
            zero when stale, disabled, not finite or from no device owning the motion.
        state, obj : Sample or None
            Newest robot state (ee pose in world) and the pose (in world) of the active
            state's object (``engine.object``: the state's own, else the skill's task
            object).
        """
        cfg = self.config
        u, input_ok, pressed = cmd.u, cmd.ok, cmd.pressed
        if self._last_tick is not None:
            self._allowance = min(STEP_ALLOWANCE * cfg.period,
                                  self._allowance + max(0.0, now - self._last_tick))
        self._last_tick = now
        state_ok = self._fresh("state", state, now, wall, cfg.state_timeout)
        obj_ok = self._fresh("object", obj, now, wall, cfg.object_timeout)
        held = self._gate(now, state, state_ok, obj_ok, u, cmd)
        if held is not None:
            self.stuck_detector.release()  # where the hand is is not known or not moving
            return held
        assert state is not None and state.F is not None and obj is not None and obj.F is not None
        # The tick works in the object frame, where the skill is, on flat poses (12
        # floats, see sctd.se3); the target is kept there while the object's pose does
        # not change, so a tick converts one pose (the measured one) in and one (the new
        # target) out.
        if obj.F is not self._obj_F_src:  # a new object sample: re-express the target
            self._object_moved(obj.F)
        F_meas = se3.compose_flat(self._obj_F_inv, state.F)
        seeding = not self._publishing
        if seeding:
            self._seed(F_meas, now)
        force = None if state.wrench is None else self._force_in_object(state.wrench)
        engine = self.engine
        grip = state.gripper
        body = engine.object
        changed = engine.update(F_meas, now, force, pressed, BUTTON_ESCAPE,
                                None if grip is None else grip.grasped)
        if changed:
            self.counters.transitions += 1
            self.counters.escapes += engine.escaped
        # A (re-)seed tick moves nothing: no push, and the stuck watch restarts. Nor does
        # the tick that entered a state in another body's frame: the poses here are in
        # the old one's; the next tick gets the new body's pose and re-expresses the
        # target (a pose in the world, unchanged) in it, or holds while it is stale.
        moves = not seeding and engine.object == body
        self._watch(now, moves and self._move(u, F_meas), F_meas, force)
        self.mode = "running" if input_ok else "stopped"
        return TickResult(self.mode, self._target, self.engine.state, cmd, changed,
                          input_ok, self._pose, seeding)

    def _watch(self, now: float, held: bool, F_meas: se3.Flat, force: Array | None) -> None:
        """Feed the stuck detector: whether the input is held (pushed on the active
        state's axes) and the measured pose's progress towards the state's transitions.
        It only watches; nothing here changes the target."""
        det = self.stuck_detector
        if not held:
            det.release()
            return
        if not det.due(now):
            return
        engine = self.engine
        was = det.episodes
        det.observe(now, engine.index, engine.progress(F_meas, now, force), engine.progress_steps)
        self.counters.stuck += det.episodes - was

    def _gate(self, now: float, state: Sample | None, state_ok: bool, obj_ok: bool,
              u: tuple[float, ...], cmd: Command) -> TickResult | None:
        """The tick's result when it may not step (a stale state or object, a fault not
        yet cleared), else None. A fault clears after ``reseed_after`` s of continuous
        state with zero input and a fresh object; the target then re-seeds."""
        if state_ok and state is not None and state.epoch != self._epoch:
            self._epoch = state.epoch  # the state stream jumped or restarted
            self._fault = self._target is not None
        if state_ok and state is not None and state.fault is not None:
            # The arm says it is faulted (it follows no target): nothing is published,
            # and once it has recovered the target re-seeds only with the input at zero.
            self._fault = self._target is not None
            self.counters.robot_fault_ticks += 1
            return self._quiet("fault", cmd)
        if not state_ok:
            # Stale state: where the robot is is not known, so nothing is published (the
            # robot holds on its own stale-target rule) and the target will resume from
            # the measured pose.
            return self._quiet("fault" if self._fault else "hold" if self._target is not None
                               else "waiting", cmd)
        assert state is not None
        if self._fault:
            if not obj_ok or now - state.since < self.config.reseed_after or any(u):
                return self._quiet("fault", cmd)
            self._fault = False
            self._publishing = False
        if not obj_ok:
            # Stale object pose, fresh state: the target stays where it is in the world
            # (it does not need the object to stay put); without one there is nothing.
            if not self._publishing:
                return self._quiet("hold" if self._target is not None else "waiting", cmd)
            self.mode = "hold"
            return TickResult("hold", self._target, self.engine.state, cmd, pose=self._pose)
        return None

    def _object_moved(self, F: se3.Flat) -> None:
        """A new object sample: its inverse, and the target to re-express in it."""
        self._obj_F_src = self._obj_F = F
        self._obj_F_inv = se3.invert_flat(F)
        self._obj_q = se3.quaternion_from_flat(F)
        self._T_obj_target = None
        self._rot = None

    def _seed(self, F_meas: se3.Flat, now: float) -> None:
        """(Re-)seed: this tick's target is the measured pose, so nothing moves; the
        input moves it from the next tick on."""
        if self._target is not None:
            self.counters.reseeds += 1
        self._rot = None
        self._accept(F_meas)
        self.engine.reset(now, self.engine.state)
        self._publishing = True

    def _force_in_object(self, wrench: list[float]) -> Array:
        """The measured force (world) in the object frame."""
        r = self._obj_F_inv
        fx, fy, fz = wrench[:3]
        return np.array([r[0] * fx + r[1] * fy + r[2] * fz, r[3] * fx + r[4] * fy + r[5] * fz,
                         r[6] * fx + r[7] * fy + r[8] * fz])

    def _move(self, u: tuple[float, ...], F_meas: se3.Flat) -> bool:
        """Step the target by the active mappings' command for ``u``, bounded and refused
        when it would grow the offset to the measured pose past the limit. Returns
        whether the user pushes (``u`` non-zero on the active state's axes), moved or
        not."""
        cfg = self.config
        F_prev = self._T_obj_target
        if F_prev is None:
            assert self._target is not None
            F_prev = self._T_obj_target = se3.compose_flat(
                self._obj_F_inv, se3.flat_from_transform(self._target.matrix()))
        # How far the user pushes: the norm of the axes the active mappings read, clipped
        # to 1 (a diagonal push of a 3-axis stick is one push, not two); steps are
        # bounded by mag * speed * dt, constraint corrections included.
        n = len(u)
        mag = math.sqrt(sum(u[j] * u[j] for j in self.engine.input_axes if j < n))
        if not mag > 0.0:  # zero (or, fail-closed, NaN): no step
            return False
        mag = min(1.0, mag)
        # a whole period when the allowance holds one (to the last bits of a clock that
        # adds periods), else what it holds: a tick that catches up moves as little
        dt = cfg.period if self._allowance >= cfg.period * (1.0 - 1e-6) else self._allowance
        self._allowance = max(0.0, self._allowance - dt)
        F_new = limit_step(F_prev, self.engine.command(F_prev, u, cfg.period),
                           mag * self.v_max * dt, mag * self.w_max * dt)
        if F_new is F_prev:
            return True
        if grows_offset(F_prev, F_new, F_meas, cfg.max_offset, cfg.max_offset_rotation):
            self.counters.offset_limited += 1  # refused: the arm lags or is blocked
        elif not self._accept(F_new):
            self.counters.nonfinite_output += 1  # never publish a non-finite target
        return True

    def _quiet(self, mode: str, cmd: Command) -> TickResult:
        """A tick that publishes nothing; the next target will be a (re-)seed."""
        self.mode = mode
        self._publishing = False
        return TickResult(mode, None, self.engine.state, cmd)

    def _fresh(self, kind: str, sample: Sample | None, now: float, wall: float,
               timeout: float) -> bool:
        """Whether a state or object sample is recent: arrived within ``timeout`` and,
        with the stamp check on, stamped within ``timeout`` of this host's clock."""
        if sample is None:
            return False
        if now - sample.received <= timeout and (
                not self.config.stamp_check or abs(wall - sample.stamp) <= timeout):
            return True
        if sample.seq != self._stale_seq[kind]:
            self._stale_seq[kind] = sample.seq
            if kind == "state":
                self.counters.stale_state += 1
            else:
                self.counters.stale_object += 1
        return False

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
            q = se3.quaternion_from_flat(F)
            F = se3.flat_from_pose((x, y, z, *q))
            rot = F[:9]
            self._rot = rot
            qx, qy, qz, qw = se3.compose_quaternions(self._obj_q, q)
            self._q_world = (qx, qy, qz, qw) if qw >= 0.0 else (-qx, -qy, -qz, -qw)
        o = self._obj_F
        self._pose = [o[0] * x + o[1] * y + o[2] * z + o[9], o[3] * x + o[4] * y + o[5] * z + o[10],
                      o[6] * x + o[7] * y + o[8] * z + o[11], *self._q_world]
        self._T_obj_target = F
        self._target = _Target(o, F)
        return True
