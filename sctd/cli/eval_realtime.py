"""A trial with real processes over Zenoh at real time (the default of ``sctd eval``).

It orchestrates processes, so it lives in the application layer, next to ``sctd demo``:
the evaluation service (:mod:`sctd_services.eval`) is handed :func:`realtime_job` by
``sctd eval`` and never starts a process itself.

Per trial, on a free loopback port held by the evaluator's session: ``sctd sim
--trial-seed N`` (the Pinocchio arm from the seeded start), ``sctd run --skill`` (the
daemon) and the simulated user client (:mod:`sctd_services.simulated_user`, the same
:class:`~sctd_services.user.SimulatedUser` the lockstep trials step). The evaluator
watches what they publish (the hand's state, the objects, the scene, the targets' mode
and the user's input) and feeds the same :class:`~.trial.TrialRecorder`.

A trial is timed by the simulator's clock (the ``t`` of its scene messages), as lockstep
trials are: on a machine too busy for the simulator to keep real time, the task's time is
then what the arm took, not the wall clock's (the report still flags such trials, by the
simulator's real-time factor).
"""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from sctd import se3
from sctd.app.logs import log_folder
from sctd.task import Task, find_task
from sctd.wire import Keys, codec
from sctd.wire.session import session
from sctd_services.eval.evaluate import read_demo_poses
from sctd_services.eval.trial import TaskSpec, TrialRecorder, TrialResult
from sctd_services.simulated_user import task_frames
from sctd_services.user import PROFILES, Observation

from .procs import Child, free_port

WATCH_RATE = 100.0  # Hz at which the evaluator samples what it sees
# The evaluator keeps only the newest state and target, which it reads at WATCH_RATE: Zenoh
# drops the rest of their 1 kHz on arrival (its downsampling, before any Python callback),
# so that watching does not take from the simulator, the daemon and the user the CPU they
# need to keep real time on a small machine.
WATCH_INGRESS = 250.0  # Hz
SCENE_PERIOD = 0.1  # s between the simulator's scene messages (``sctd sim``'s default)


class TrialWatcher:
    def __init__(self, s: zenoh.Session, task: Task):
        k = Keys()
        self.lock = threading.Lock()
        self.T_world_ee: Any = None
        self.objects: dict[str, Any] = {}
        self.scene: dict[str, Any] = {}
        self._scene_at = (0.0, 0.0)  # (simulated t, monotonic arrival) of the newest scene
        self._t_sim = 0.0  # the newest simulated time an observation carried
        self.mode: str | None = None
        self.u: tuple[float, ...] = (0.0, 0.0, 0.0)
        self.buttons: tuple[int, ...] = (0, 1, 0)
        self.status: dict[str, Any] = {}
        self.inputs = 0
        self.subs = [s.declare_subscriber(key, cb) for key, cb in (
            (k.state, self._state), (k.scene, self._scene), (k.target, self._target),
            (k.input("*"), self._input), (k.status, self._status))]
        self.frames = task_frames(task)
        self.subs += [s.declare_subscriber(k.objects(n), self._object) for n in self.frames]

    def _state(self, sample: zenoh.Sample) -> None:
        try:
            self.T_world_ee = se3.transform_from_pose(codec.decode_state(sample.payload.to_bytes()).pose)
        except codec.DecodeError:
            pass

    def _object(self, sample: zenoh.Sample) -> None:
        try:
            pose = codec.decode_object(sample.payload.to_bytes()).pose
        except codec.DecodeError:
            return
        self.objects[str(sample.key_expr).rsplit("/", 1)[-1]] = se3.transform_from_pose(pose)

    def _scene(self, sample: zenoh.Sample) -> None:
        try:
            scene = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        t = scene.get("t")
        if isinstance(t, (int, float)) and not isinstance(t, bool):
            self._scene_at = (float(t), time.monotonic())
        self.scene = scene

    def sim_time(self) -> float:
        """The simulator's time now: its newest scene's ``t`` plus the wall time since it
        arrived (at most a scene period), never going back."""
        t, arrived = self._scene_at
        self._t_sim = max(self._t_sim, t + min(time.monotonic() - arrived, SCENE_PERIOD))
        return self._t_sim

    def _target(self, sample: zenoh.Sample) -> None:
        try:
            self.mode = codec.decode_target(sample.payload.to_bytes())["state"]
        except codec.DecodeError:
            pass

    def _input(self, sample: zenoh.Sample) -> None:
        try:
            m = codec.decode_input(sample.payload.to_bytes())
        except codec.DecodeError:
            return
        self.u, self.buttons = m.u, m.buttons or (0, 1, 0)
        self.inputs += 1

    def _status(self, sample: zenoh.Sample) -> None:
        try:
            self.status = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError:
            pass

    def observation(self) -> Observation | None:
        if (self.T_world_ee is None or self.mode is None or "t" not in self.scene
                or any(n not in self.objects for n in self.frames)):
            return None
        return Observation(self.sim_time(), self.T_world_ee, dict(self.objects), dict(self.scene), self.mode)

    def close(self) -> None:
        for sub in self.subs:
            sub.undeclare()


def robot_command(spec: TaskSpec, seed: int, driver: tuple[str, ...] | None) -> list[str]:
    """The arm of a trial as ``sctd`` arguments: ``sctd sim`` from the seeded start, or
    with ``driver`` (a driver's name and its flags) ``sctd robot NAME`` with the task's
    scene as an observer, moved to the trial's start first (docs/robots.md)."""
    if driver is None:
        return ["sim", "--task", spec.task, "--trial-seed", str(seed)]
    name, *flags = driver
    return ["robot", name, "--task", spec.task, "--trial-seed", str(seed), "--move-to-start", *flags]


def run_trial(skill_path: str | Path, spec: TaskSpec, seed: int, demos: list | None = None,
              logdir: Path | None = None, startup: float = 90.0,
              driver: tuple[str, ...] | None = None) -> TrialResult:
    """One real-time trial of the skill file ``skill_path`` from the seeded start, on the
    Pinocchio arm or, with ``driver``, on the arm that robot driver serves. ``spec.task``
    arrived as a name or file (a trial job's, :func:`realtime_job`) and is resolved here,
    once; the processes the trial starts get it as that name or file, on their command
    lines."""
    task = find_task(spec.task)
    logdir = log_folder(logdir, "sctd-eval-")
    hub = f"tcp/127.0.0.1:{free_port()}"
    profile = PROFILES[spec.profile]
    rec = TrialRecorder(task, seed, profile.switch_time, spec.time_limit, spec.stuck_after)

    def ep() -> str:
        return f"tcp/127.0.0.1:{free_port()}"

    keys = Keys()
    first: tuple[float, float] | None = None  # (wall, simulated) at the trial's start
    last: tuple[float, float] | None = None  # (wall, simulated) at its end
    with session(listen=[hub], rate_limits=[(keys.state, WATCH_INGRESS), (keys.target, WATCH_INGRESS)]) as s:
        w = TrialWatcher(s, task)
        try:
            with Child("sctd.cli.main", *robot_command(spec, seed, driver),
                       "--connect", hub, "--listen", ep(), log=logdir / f"sim-{seed}.log") as sim, \
                    Child("sctd.cli.main", "run", "--skill", str(skill_path), "--connect", hub,
                          "--listen", ep(), log=logdir / f"daemon-{seed}.log") as daemon:
                end = time.monotonic() + startup
                while w.observation() is None:  # the daemon publishes targets
                    if time.monotonic() > end or not (sim.running() and daemon.running()):
                        raise RuntimeError(f"trial {seed}: no targets within {startup:.0f} s; see {logdir}")
                    time.sleep(0.05)
                with Child("sctd_services.simulated_user", "--task", spec.task, "--seed", str(seed),
                           "--profile", spec.profile, "--user-model", spec.user_model,
                           "--axes", str(spec.axes),
                           "--duration", str(rec.time_limit + 30), "--connect", hub, "--listen", ep(),
                           log=logdir / f"user-{seed}.log"):
                    period = 1.0 / WATCH_RATE
                    while True:
                        time.sleep(period)
                        obs = w.observation()
                        if obs is None or w.inputs == 0:  # the trial starts with the user
                            continue
                        last = (time.monotonic(), obs.t)
                        first = first or last
                        st = w.status
                        if rec.add(obs, w.u, w.buttons, st.get("vf_scale")) is not None:
                            break
        finally:
            w.close()
    res = rec.result(demos)
    if first is not None and last is not None and last[0] - first[0] > 1.0:
        # how well the simulator kept real time
        res.sim_rtf = round((last[1] - first[1]) / (last[0] - first[0]), 3)
    return res


def realtime_job(path: str, spec: TaskSpec, seed: int, demos_dir: str | None, keep: bool,
                 logdir: Path | None, driver: tuple[str, ...] | None = None) -> dict[str, Any]:
    """One real-time trial as :func:`sctd_services.eval.evaluate.evaluate` runs it (with
    ``driver`` bound by ``sctd eval --driver``)."""
    demos = read_demo_poses(demos_dir) if demos_dir else None
    return run_trial(path, spec, seed, demos, logdir, driver=driver).as_dict(with_trajectory=keep)
