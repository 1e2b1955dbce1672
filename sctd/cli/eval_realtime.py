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

import time
from pathlib import Path
from typing import Any

from sctd.app.logs import log_folder
from sctd.task import find_task
from sctd.wire import Keys
from sctd.wire.session import session
from sctd_services.eval.evaluate import read_demo_poses
from sctd_services.eval.trial import TaskSpec, TrialRecorder, TrialResult
from sctd_services.eval.watcher import WATCH_INGRESS, WATCH_RATE, TrialWatcher
from sctd_services.user import PROFILES

from .procs import Child, free_port


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
