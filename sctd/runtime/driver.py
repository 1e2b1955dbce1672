"""The tick driver: decoded messages in, the tick's target and events out. Pure: no I/O,
no clocks, no threads; every time is an argument.

One path from messages to targets (docs/architecture.md). The daemon (:mod:`.daemon`) feeds
it from its Zenoh rings; the lockstep evaluation and the benches feed it from the
simulation; so the check that gates a skill runs the code that will run it. A feeder
does, in this order:

1. offer each message as it arrives, in arrival order, with its arrival time
   (:meth:`TickDriver.receive` for bytes off the wire, or :meth:`take_input`,
   :meth:`take_state`, :meth:`take_object` for decoded messages): inputs go to their
   device's slot, with button edges and the ownership rule judged on every message
   (:mod:`.arbiter`); every state goes through the continuity watch
   (:class:`~.safety.StateWatch`); the pose of every object the skill names is kept
   (an unchanged pose keeps its flat transform, so that the controller's object caches
   stay valid), and each tick hands the controller the active state's;
2. at the deadline, :meth:`TickDriver.tick` (the arbiter's command, the newest state
   and object pose, the controller's step, the gripper's command: :mod:`.gripper`);
   publish what it returns (the target, and the gripper message when it has one);
3. after the target is out, :meth:`TickDriver.after_tick` (the work a vector-field tick
   would otherwise do itself, done between ticks).
"""

from __future__ import annotations

from .. import se3
from ..skill import WORLD_OBJECT, Skill, SkillEngine
from ..wire import codec
from ..wire.codec import BUTTON_GRASP
from .arbiter import MAX_DEVICES, Command, InputArbiter
from .controller import Controller, Counters, RuntimeConfig, Sample, TickResult
from .goals import GoalSet
from .gripper import GripperControl
from .safety import StateWatch

_WORLD_F = se3.flat_from_pose([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])


class TickDriver:
    """The runtime's tick between messages and targets (module doc).

    Parameters
    ----------
    skill : Skill
    config : RuntimeConfig
    max_devices : int
        Input device names tracked at once (:mod:`.arbiter`).
    goals : GoalSet, optional
        A skill set (:mod:`.goals`): ``skill`` is then ignored; the set's teleoperation
        runs until a member engages.
    gripper_start : int
        The run's first gripper command number (:mod:`.gripper`; the daemon's is its
        start time in ms, so that a restarted daemon's commands are new to the robot).
    """

    def __init__(self, skill: Skill | None, config: RuntimeConfig, max_devices: int = MAX_DEVICES,
                 goals: GoalSet | None = None, gripper_start: int = 0):
        self.config = config
        self.goals = goals
        engine = None
        if goals is not None:
            skill, engine = goals.running
        assert skill is not None, "a skill or a skill set"
        self.controller = Controller(skill, config, engine)
        self.counters: Counters = self.controller.counters
        self.inputs = InputArbiter(config.input_timeout, config.deadband, config.stamp_check,
                                   self.counters, max_devices, stale_grace=config.stale_grace)
        self.watch = StateWatch(config.state_jump, config.state_jump_rotation)
        self.state: Sample | None = None
        self.objects: dict[str, Sample] = {}
        self._world = Sample(0, 0.0, 0.0, F=_WORLD_F)
        self.target_seq = 0  # targets published so far
        self.gripper = GripperControl(config.grasp_force, config.grasp_open_hold, gripper_start)

    @property
    def skill(self) -> Skill:
        return self.controller.skill

    @property
    def engine(self) -> SkillEngine:
        return self.controller.engine

    # --- messages, as they arrive ---------------------------------------------------------

    def receive(self, kind: str, name: str, data: bytes, now: float) -> None:
        """One message off the wire: ``kind`` ``input`` (``name``: the device), ``state``
        or ``object`` (``name``: the object). Decoded and validated here; a malformed one
        is dropped and counted as ``<kind>_<reason>`` (``status.dropped``)."""
        try:
            if kind == "input":
                self.take_input(name, codec.decode_input(data), now)
            elif kind == "state":
                self.take_state(codec.decode_state(data), now)
            else:
                self.take_object(name, codec.decode_object(data), now)
        except codec.DecodeError as e:
            self.counters.drop(f"{kind}_{e.reason}")

    def take_input(self, device: str, m: codec.InputMsg, now: float) -> None:
        """An input message from ``device`` (:meth:`.arbiter.InputArbiter.offer`)."""
        self.inputs.offer(device, m, now)

    def take_state(self, m: codec.StateMsg, now: float) -> None:
        """A robot state: judged for continuity, kept as the newest."""
        if m.wrench_nonfinite:
            self.counters.drop("state_nonfinite_wrench")
        F = se3.flat_from_pose(m.pose)
        if self.watch.observe(m.seq, F, now):
            self.counters.state_discontinuity += 1
        if m.gripper_invalid:
            self.counters.drop("state_bad_gripper")
        self.state = Sample(m.seq, m.stamp, now, F=F, wrench=m.wrench, epoch=self.watch.epoch,
                            since=self.watch.since, fault=m.fault, gripper=m.gripper)
        self.gripper.observe(m.gripper, now)

    def take_object(self, name: str, m: codec.ObjectMsg, now: float) -> None:
        """An object's pose; kept when the active skill names it (its task object or a
        state's own ``object``; a skill set: any member's)."""
        if name not in self.controller.objects and (self.goals is None or name not in self.goals.objects):
            return
        prev = self.objects.get(name)
        # An unchanged pose keeps its flat transform (the same tuple): the controller's
        # object-frame caches stay valid for a still object.
        F = prev.F if prev is not None and prev.pose == m.pose else se3.flat_from_pose(m.pose)
        self.objects[name] = Sample(m.seq, m.stamp, now, F=F, pose=m.pose)

    # --- the tick -------------------------------------------------------------------------

    def region(self) -> dict[str, object] | None:
        """``status.region``: where the hand's origin is against the running skill's
        region (:mod:`sctd.skill.region`): ``inside``, ``outside_by`` (m), the region's
        ``frame``, ``centre`` and ``half_extents`` (in that frame); None when the skill
        states no region or the hand or that body has not been seen."""
        region = self.controller.skill.region
        if region is None or self.state is None:
            return None
        body = self.objects.get(region.frame)
        if body is None or body.F is None or self.state.F is None:
            return None
        F, h = body.F, self.state.F
        d = (h[9] - F[9], h[10] - F[10], h[11] - F[11])
        p = (F[0] * d[0] + F[3] * d[1] + F[6] * d[2], F[1] * d[0] + F[4] * d[1] + F[7] * d[2],
             F[2] * d[0] + F[5] * d[1] + F[8] * d[2])  # R^T d: the hand in the body's frame
        out = region.outside_by(p)
        return {"inside": out == 0.0, "outside_by": round(out, 4), "frame": region.frame,
                "centre": list(region.centre), "half_extents": list(region.half_extents)}

    def object_sample(self, now: float, wall: float) -> Sample | None:
        """The active state's object as the tick sees it (its own ``object``, else the
        skill's; the world is always there and always fresh)."""
        obj = self.controller.engine.object
        if obj == WORLD_OBJECT:
            self._world.received, self._world.stamp = now, wall
            return self._world
        return self.objects.get(obj)

    def tick(self, now: float, wall: float) -> TickResult:
        """One control step at the deadline ``now`` (monotonic, the arrival times' clock)
        and ``wall`` (Unix time, for the sender-stamp checks). When the result has a
        ``pose``, it is target number :attr:`target_seq`."""
        cmd = self.inputs.select(now, wall)
        if self.goals is None:
            res = self.controller.tick(now, wall, cmd, self.state, self.object_sample(now, wall))
        else:
            res = self._tick_set(self.goals, now, wall, cmd)
        if res.pose is not None:
            self.target_seq += 1
        res.gripper = self._grip(now, wall, cmd, res.mode)
        return res

    def _grip(self, now: float, wall: float, cmd: Command, mode: str) -> codec.GripperCmd | None:
        """The gripper's step (:mod:`.gripper`): this tick's grasp presses, the action of a
        state a transition entered, the newest state's reading when it is fresh."""
        state = self.state
        grasped = None
        if state is not None and state.gripper is not None \
                and self._fresh(state, now, wall, self.config.state_timeout):
            grasped = state.gripper.grasped
        inputs = self.inputs
        return self.gripper.step(
            now, wall, cmd.grasps, self.controller.engine.take_entry_action(), self.controller.skill.id,
            grasped, lambda device: inputs.holding(device, BUTTON_GRASP, now, wall), self.counters.stops,
            mode == "fault")

    def _tick_set(self, goals: GoalSet, now: float, wall: float, cmd) -> TickResult:
        """A skill set's tick: the set sees the fresh objects and may change the running
        skill (only at a tick whose input is at rest), then the controller steps, then
        the set learns from the target's step."""
        goals.see({n: s.F for n, s in self.objects.items()
                   if s.F is not None and self._fresh(s, now, wall, self.config.object_timeout)})
        state = self.state
        fresh_state = state is not None and self._fresh(state, now, wall, self.config.state_timeout)
        cmd, changed = goals.decide(cmd, state.F if fresh_state and state is not None else None,
                                    self.inputs.at_rest(), now)
        ctl = self.controller
        if changed:
            skill, engine = goals.running
            ctl.engage(skill, engine, now)
        before = ctl.pose
        res = ctl.tick(now, wall, cmd, state, self.object_sample(now, wall))
        goals.observe(None if res.seed else before, res.pose)
        return res

    def _fresh(self, s: Sample, now: float, wall: float, timeout: float) -> bool:
        """Whether a sample is fresh by the controller's rule (arrival and, with the
        stamp check on, the sender's stamp)."""
        return now - s.received <= timeout and (not self.config.stamp_check or abs(wall - s.stamp) <= timeout)

    def after_tick(self) -> None:
        """Between ticks, after the target is out: the neighbour answers the next
        vector-field tick would work out, worked out now (its own result is unchanged)."""
        self.controller.engine.workspace.refresh()

    def swap(self, skill: Skill, now: float, engine: SkillEngine | None = None) -> None:
        """Replace the skill between two ticks (:meth:`.controller.Controller.swap`);
        object poses the new skill does not use are forgotten."""
        self.controller.swap(skill, now, engine)
        names = skill.objects()
        for name in [n for n in self.objects if n not in names
                     and (self.goals is None or n not in self.goals.objects)]:
            del self.objects[name]

    def swap_member(self, name: str, skill: Skill, now: float, engine: SkillEngine | None = None) -> None:
        """A skill set's swap (:meth:`.goals.GoalSet.replace`): ``skill`` takes member
        ``name``'s place; when that member is engaged, the running skill is swapped as
        :meth:`swap` does (the active state kept where the new skill has it), else the
        set's next engagement of it runs the new one. Object poses no member and not the
        running skill use are forgotten."""
        goals = self.goals
        if goals is None:
            raise ValueError("not a skill set: a swap replaces the skill")
        if goals.replace(name, skill, engine):
            self.controller.swap(skill, now, goals.engines[goals.index(skill.name)])
        else:
            self.counters.swaps += 1
        names = self.controller.skill.objects()
        for n in [n for n in self.objects if n not in names and n not in goals.objects]:
            del self.objects[n]
