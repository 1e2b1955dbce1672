"""A trial stepped in one process in simulated time (``sctd eval --lockstep``).

The same parts as a real-time trial, called directly instead of over Zenoh: the
Pinocchio simulation with its target guard (its arm's joint values handed over as the
CAN frames would carry them, bit for bit, unless the spec's ``joint_bus`` asks for the
frames themselves), the runtime's tick driver (the daemon's own
path from messages to targets: input arbitration, the state-continuity watch, the skill
engine and the safety limits), and the simulated user, all on the simulator's clock. Messages take
no time here, and the robot's state reaches the tick one cycle old, as it would at
best over the wire; the user acts on observations a reaction delay old either way, and
sees them at the rates the simulator service publishes them (objects 50 Hz, the scene's
outcome 10 Hz), so that both ways of running give the user the same information.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from sctd import se3
from sctd.runtime.controller import RuntimeConfig, TickResult
from sctd.runtime.driver import TickDriver
from sctd.runtime.goals import GoalSet
from sctd.skill import Skill
from sctd.task import Task
from sctd.wire import codec
from sctd_services.user import Observation, SetUser, SimulatedUser
from sctd_services.user.agent import Device
from sctd_sim.guard import TargetGuard, TargetLimits
from sctd_sim.simulation import Simulation, trial_scene

from .trial import TaskSpec, TrialRecorder, TrialResult

USER_RATE = 100.0  # Hz at which the user client publishes (the input bridges' default)
OBJECT_RATE = 50.0  # Hz at which the simulator publishes object poses
SCENE_RATE = 10.0  # Hz at which it publishes the scene's outcome (what the user sees of progress)
USER_DEVICE = "user"  # the simulated user's device name (input/<name>)


def run_trial(skill: Skill, spec: TaskSpec, seed: int, demos: list | None = None,
              keep_series: bool = False, *, task: Task,
              known: Mapping[str, Device] | None = None, detour: Task | None = None) -> TrialResult:
    """One trial of ``skill`` on ``task`` (``spec.task`` resolved, or a composed room whose
    first part is the user's goal) from the seeded start ``seed``; ``known``: what a practised
    user knows of the device (:class:`~sctd_services.user.SimulatedUser`); ``detour``:
    the room as the task the user goes for first, before changing their mind
    (:class:`~sctd_services.user.SetUser`)."""
    if detour is None:
        return practise(skill, spec, seed, demos, task=task, known=known)[0]
    scene, q0 = trial_scene(task, seed)
    sim = Simulation(scene=scene, q0=q0, joint_bus=spec.joint_bus)
    try:
        return _run(sim, TickDriver(skill, RuntimeConfig()), task, spec, seed, demos,
                    set_user(task, spec, seed, known, detour))
    finally:
        sim.close()


def practise(skill: Skill, spec: TaskSpec, seed: int, demos: list | None = None, *, task: Task,
             known: Mapping[str, Device] | None = None) -> tuple[TrialResult, dict[str, Device]]:
    """:func:`run_trial`, and what its user learned of the device by the end: a model per
    mode (the skill's state names) it used."""
    scene, q0 = trial_scene(task, seed)
    outside = outside_region(skill, scene)
    sim = Simulation(scene=scene, q0=q0, joint_bus=spec.joint_bus)
    user = SimulatedUser(task, spec.axes, spec.profile, seed=seed, known=known, model=spec.user_model)
    try:
        result = _run(sim, TickDriver(skill, RuntimeConfig()), task, spec, seed, demos, user)
    finally:
        sim.close()
    result.outside_region = outside
    return result, user.models


def outside_region(skill: Skill, scene: Any) -> float | None:
    """How far (m) the hand starts outside ``skill``'s region (:mod:`sctd.skill.region`;
    0 inside), with the scene's bodies where they start; None when the skill states no
    region or the scene has no such body."""
    region = skill.region
    if region is None:
        return None
    T_ee = scene.start_pose()
    T_body = scene.objects(T_ee).get(region.frame)
    if T_body is None:
        return None
    p = T_body[:3, :3].T @ (T_ee[:3, 3] - T_body[:3, 3])
    return round(region.outside_by(p.tolist()), 4)


def set_user(task: Task, spec: TaskSpec, seed: int, known: Mapping[str, Device] | None = None,
             detour: Task | None = None) -> SetUser:
    """The person of a trial in a room of several tasks (:class:`~sctd_services.user.SetUser`):
    going for ``task``'s goal, or first for ``detour``'s."""
    user = SimulatedUser(task, spec.axes, spec.profile, seed=seed, known=known, model=spec.user_model)
    if detour is None:
        return SetUser(user, task.object)
    first = SimulatedUser(detour, spec.axes, spec.profile, seed=seed + 1, model=spec.user_model)
    return SetUser(user, task.object, first, detour.object)


def run_set_trial(goals: GoalSet, task: Task, spec: TaskSpec, seed: int,
                  known: Mapping[str, Device] | None = None,
                  detour: Task | None = None) -> tuple[TrialResult, SetWatch]:
    """One trial of a skill set (:mod:`sctd.runtime.goals`) in the composed room ``task``
    (its first part is the user's goal) from the seeded start ``seed``: the user does
    not know about the inference and escapes a skill it did not want
    (:class:`~sctd_services.user.SetUser`); ``known``: what a practised user knows of the
    device, by the modes the display shows (``skill:state``, :meth:`SetWatch.shown`);
    ``detour``: the room as the task the user goes for first. Returns the trial's result
    and what the set did (:class:`SetWatch`)."""
    scene, q0 = trial_scene(task, seed)
    sim = Simulation(scene=scene, q0=q0, joint_bus=spec.joint_bus)
    watch = SetWatch(goals, task.object)
    user = set_user(task, spec, seed, known, detour)
    try:
        driver = TickDriver(None, RuntimeConfig(), goals=goals)
        res = _run(sim, driver, task, spec, seed, None, user, watch)
        watch.changed_at = user.changed_at
        return res, watch
    finally:
        sim.close()


class SetWatch:
    """What a skill set did in a trial: every change of the running skill (time, from,
    to), the belief over time (``belief``: ``t`` and each member's column, sampled every
    ``BELIEF_EVERY`` s as ``status.goals.belief`` has it; a member that is no candidate
    reads None), what the user was shown (the engaged skill's task object), and when the
    user changed their mind (``changed_at``, None: never)."""

    BELIEF_EVERY = 0.1

    def __init__(self, goals: GoalSet, goal_object: str):
        self.goals = goals
        self.goal_object = goal_object
        self.changes: list[tuple[float, str, str]] = []
        self.changed_at: float | None = None
        self.belief: dict[str, list[float | None]] = {"t": [], **{m.name: [] for m in goals.members}}
        self._next_sample = 0.0
        self._running = goals.running[0].name

    def tick(self, t: float) -> None:
        name = self.goals.running[0].name
        if name != self._running:
            self.changes.append((t, self._running, name))
            self._running = name
        if t >= self._next_sample:
            self._next_sample = t + self.BELIEF_EVERY
            b = self.goals.status()["belief"]
            self.belief["t"].append(round(t, 3))
            for m in self.goals.members:
                self.belief[m.name].append(b.get(m.name))

    def shown(self) -> tuple[str | None, str]:
        """The engaged skill's task object (None in teleoperation) and the mode the
        display shows: the skill and its state (states of different skills may share a
        name, a person tells them apart by the skill)."""
        skill, engine = self.goals.running
        engaged = None if self.goals.engaged is None else skill.object
        return engaged, f"{skill.name}:{engine.state}"


def _run(sim: Simulation, driver: TickDriver, task: Task, spec: TaskSpec, seed: int, demos: list | None,
         user: SimulatedUser | SetUser, watch: SetWatch | None = None) -> TrialResult:
    feed = Feed(driver, sim.scene.grip)
    drv = feed.driver
    rec = TrialRecorder(task, seed, user.profile.switch_time, spec.time_limit, spec.stuck_after)
    guard = TargetGuard(TargetLimits(), sim.dt, started=0.0)
    every_user = max(1, round(1.0 / (USER_RATE * sim.dt)))
    every_object = max(1, round(1.0 / (OBJECT_RATE * sim.dt)))
    every_scene = max(1, round(1.0 / (SCENE_RATE * sim.dt)))
    scene: dict[str, Any] = {}
    objects: dict[str, Any] = {}
    limits = JointLimits(sim.arm.arm.q_lower, sim.arm.arm.q_upper)
    u, b = (0.0,) * spec.axes, (0, 1, 0)
    mode = drv.engine.state
    engaged: str | None = None
    if watch is not None:
        engaged, mode = watch.shown()
    k, seq = 0, 0
    # spec.arm_lag: the targets reach the arm through a delay line of that many ticks
    late: deque[list[float] | None] | None = deque() if spec.arm_lag > 0 else None
    lag_ticks = round(spec.arm_lag / sim.dt)
    while True:
        t = sim.t
        m = sim.state_message()
        pose = m["pose"]
        feed.state(k, t, m)
        if k % every_object == 0:
            poses = sim.objects()
            objects = {n: se3.transform_from_pose(p) for n, p in poses.items()}
            feed.objects(k, t, poses)
        if k % every_scene == 0:
            scene = sim.scene_outcome()
        if k % every_user == 0:
            limits.look(sim.arm.dynamics.q, t)
            eng = drv.engine
            obs = Observation(t, se3.transform_from_pose(pose), objects, scene, mode,
                              eng.leads_to() is not None)
            membership = None if eng.last_membership is None else eng.last_membership.tolist()
            if rec.add(obs, u, b, eng.last_scale, membership) is not None:
                break
            u, b = user.step(t, obs) if isinstance(user, SimulatedUser) else user.step(t, obs, engaged)
            seq += 1
            feed.input(USER_DEVICE, seq, t, u, b)
        res = feed.tick(t)
        mode = res.state
        if watch is not None:
            watch.tick(t)
            engaged, mode = watch.shown()
        F = drv.state.F if drv.state is not None else None
        assert F is not None
        pose = res.pose
        if late is not None:
            late.append(pose)
            pose = late.popleft() if len(late) > lag_ticks else None
        _hand_over(sim, guard, pose, t, F)
        sim.step()
        k += 1
    return limits.noted(rec.result(demos))


class JointLimits:
    """Which of the arm's joints sit at a limit (within ``EPS`` rad of it), looked at
    the user's rate: the joints that did over the trial's last ``LAST`` seconds, where a
    trial that ended stuck or out of time ends (the arm cannot go on that way, whatever
    commands it)."""

    EPS = 1e-3  # rad
    LAST = 1.0  # s

    def __init__(self, lower: Any, upper: Any):
        self.lower, self.upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        self.since: dict[int, float] = {}  # joint (from 1) -> when it came to its limit
        self.t = 0.0

    def look(self, q: Any, t: float) -> None:
        at = np.flatnonzero((q - self.lower < self.EPS) | (self.upper - q < self.EPS)) + 1
        self.since = {j: self.since.get(j, t) for j in at.tolist()}
        self.t = t

    def noted(self, result: TrialResult) -> TrialResult:
        """``result`` with :meth:`at_the_end` as its ``joint_limits``."""
        result.joint_limits = self.at_the_end()
        return result

    def at_the_end(self) -> list[int]:
        """The joints that sat at a limit throughout the last :attr:`LAST` seconds."""
        return sorted(j for j, t0 in self.since.items() if self.t - t0 >= self.LAST)


def _hand_over(sim: Simulation, guard: TargetGuard, pose: list[float] | None, t: float, F: Any) -> None:
    """The tick's target to the arm, through the simulator's target guard: a target it
    refuses holds the arm (``pose`` None: nothing reaches the arm this tick)."""
    if pose is not None and guard.admit(pose, t, F, not sim.arm.controller.holding):
        sim.set_target(pose, t)
    elif pose is not None and not sim.arm.controller.holding:
        sim.arm.controller.hold()


class Feed:
    """What lockstep hands the tick driver (the daemon's drain without the wire): each
    message with its arrival time, then the tick and its between-ticks work. Messages
    take no time here: they arrive at the simulated time they are sent."""

    def __init__(self, driver: TickDriver, grip: Callable[[codec.GripperCmd], object] | None = None):
        self.driver = driver
        self.grip = grip  # the fingers: a tick's gripper message reaches them at once

    def state(self, seq: int, t: float, m: dict[str, Any]) -> None:
        """The simulator's state (:meth:`Simulation.state_message`)."""
        self.driver.take_state(state_msg(seq, t, m), t)

    def objects(self, seq: int, t: float, poses: dict[str, list[float]]) -> None:
        """The simulator's object poses (:meth:`Simulation.objects`)."""
        for name, p in poses.items():
            self.driver.take_object(name, codec.ObjectMsg(seq, t, p), t)

    def input(self, device: str, seq: int, t: float, u: tuple[float, ...], buttons: tuple[int, ...],
              stop: bool = False) -> None:
        """One input device's message."""
        self.driver.take_input(device, input_msg(seq, t, u, buttons, stop), t)

    def tick(self, t: float) -> TickResult:
        res = self.driver.tick(t, t)
        self.driver.after_tick()
        if res.gripper is not None and self.grip is not None:
            self.grip(res.gripper)
        return res


def state_msg(seq: int, t: float, m: dict[str, Any]) -> codec.StateMsg:
    """The simulator's state (:meth:`Simulation.state_message`) as the runtime decodes it
    off the wire (``q`` and ``dq`` are not read by the tick)."""
    return codec.StateMsg(seq, t, m["pose"], m["wrench"], gripper=m.get("gripper"))


def input_msg(seq: int, t: float, u: tuple[float, ...], buttons: tuple[int, ...],
              stop: bool = False) -> codec.InputMsg:
    """An input message as the runtime decodes it off the wire."""
    return codec.InputMsg(seq, t, tuple(float(x) for x in u), tuple(int(x) for x in buttons), stop)


def limited(skill: Skill, limits) -> Skill:
    """``skill`` with other speed limits (the baseline runs with the assisted skill's)."""
    from dataclasses import replace

    return replace(skill, limits=limits)

