"""A trial stepped in one process in simulated time (``sctd eval --lockstep``).

The same parts as a real-time trial, called directly instead of over Zenoh: the
Pinocchio simulation with its target guard, the runtime's controller tick (skill
engine and safety limits), the state-continuity and button watches the daemon runs
on its inputs, and the simulated user, all on the simulator's clock. Messages take
no time here, and the robot's state reaches the tick one cycle old, as it would at
best over the wire; the user acts on observations a reaction delay old either way, and
sees them at the rates the simulator service publishes them (objects 50 Hz, the scene's
outcome 10 Hz), so that both ways of running give the user the same information.
"""

from __future__ import annotations

from typing import Any

from sctd import se3
from sctd.runtime.controller import ButtonWatch, Controller, RuntimeConfig, Sample
from sctd.runtime.safety import StateWatch
from sctd.skill import WORLD_OBJECT, Skill
from sctd_services.user import Observation, SimulatedUser
from sctd_sim.guard import TargetGuard, TargetLimits
from sctd_sim.simulation import Simulation, trial_scene

from .trial import TaskSpec, TrialRecorder, TrialResult

USER_RATE = 100.0  # Hz at which the user client publishes (the input bridges' default)
OBJECT_RATE = 50.0  # Hz at which the simulator publishes object poses
SCENE_RATE = 10.0  # Hz at which it publishes the scene's outcome (what the user sees of progress)


def run_trial(skill: Skill, spec: TaskSpec, seed: int, demos: list | None = None,
              keep_series: bool = False) -> TrialResult:
    """One trial of ``skill`` on ``spec.task`` from the seeded start ``seed``."""
    scene, q0 = trial_scene(spec.task, seed)
    sim = Simulation(scene=scene, q0=q0)
    try:
        return _run(sim, skill, spec, seed, demos)
    finally:
        sim.close()


def _run(sim: Simulation, skill: Skill, spec: TaskSpec, seed: int, demos: list | None) -> TrialResult:
    cfg = RuntimeConfig()
    ctl = Controller(skill, cfg)
    user = SimulatedUser(spec.task, spec.axes, spec.profile, seed=seed)
    rec = TrialRecorder(spec.task, seed, user.profile.switch_time, spec.time_limit, spec.stuck_after)
    watch, buttons = StateWatch(cfg.state_jump, cfg.state_jump_rotation), ButtonWatch()
    guard = TargetGuard(TargetLimits(), sim.dt, started=0.0)
    every_user = max(1, round(1.0 / (USER_RATE * sim.dt)))
    every_object = max(1, round(1.0 / (OBJECT_RATE * sim.dt)))
    every_scene = max(1, round(1.0 / (SCENE_RATE * sim.dt)))
    scene: dict[str, Any] = {}
    world = Sample(0, 0.0, 0.0, F=se3.flat_from_pose([0, 0, 0, 0, 0, 0, 1]))
    objects: dict[str, Any] = {}
    obj_sample: Sample | None = None
    inp: Sample | None = None
    u: tuple[float, ...] = (0.0,) * spec.axes
    b: tuple[int, ...] = (0, 1, 0)
    mode = ctl.engine.state
    k, seq = 0, 0
    while True:
        t = sim.t
        m = sim.state_message()
        pose = m["pose"]
        F = se3.flat_from_pose(pose)
        watch.observe(k, F, t)
        state = Sample(k, t, t, F=F, wrench=m["wrench"], epoch=watch.epoch, since=watch.since)
        if k % every_object == 0:
            poses = sim.objects()
            objects = {n: se3.transform_from_pose(p) for n, p in poses.items()}
            if skill.object != WORLD_OBJECT:
                p = poses[skill.object]
                obj_sample = Sample(k, t, t, F=se3.flat_from_pose(p), pose=p)
        if skill.object == WORLD_OBJECT:
            world.received = world.stamp = t
            obj_sample = world
        if k % every_scene == 0:
            scene = sim.scene_outcome()
        if k % every_user == 0:
            obs = Observation(t, se3.transform_from_pose(pose), objects, scene, mode)
            eng = ctl.engine
            membership = None if eng.last_membership is None else eng.last_membership.tolist()
            if rec.add(obs, u, b, eng.last_scale, membership) is not None:
                break
            u, b = user.step(t, obs)
            seq += 1
            inp = Sample(seq, t, t, u=u, buttons=b, presses=buttons.observe(b))
        res = ctl.tick(t, t, inp, state, obj_sample)
        ctl.engine.workspace.refresh()  # the neighbour answers worked out ahead, as the daemon does
        mode = res.state
        if res.pose is not None and guard.admit(res.pose, t, F, not sim.arm.controller.holding):
            sim.set_target(res.pose, t)
        elif res.pose is not None and not sim.arm.controller.holding:
            sim.arm.controller.hold()
        sim.step()
        k += 1
    return rec.result(demos)


def limited(skill: Skill, limits) -> Skill:
    """``skill`` with other speed limits (the baseline runs with the assisted skill's)."""
    from dataclasses import replace

    return replace(skill, limits=limits)

