"""One evaluation trial: what is recorded, when it ends, and the figures it yields.

The same :class:`TrialRecorder` judges lockstep and real-time trials: it is fed what
the evaluator sees (the hand's pose, the objects, the scene's outcome, the mode, the
user's input) and decides the outcome:

- **success** or **failure** once the task file's ``done`` holds (the scene reports
  it), by its ``success`` (pour: the fill target reached and the bottle no longer
  pouring, without a drop spilled; drawer: opened to the target);
- **failure** as soon as one of the task's ``fail`` rules holds (a spill, the drawer's
  handle lost while pulling it), or at the time limit;
- **stuck**: no progress towards the task's intent for ``stuck_after`` seconds (an
  observer of its own, the same intent code the simulated user runs, watches it).

Completion times use the task's clock (the thesis' clocks, Ch. 5.2, 5.3, in the shipped
files: from the bottle opening within 35 cm of the mug, from the hand within 20 cm of
the handle) to the task done.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sctd import se3
from sctd.task import Task
from sctd.task.judge import holds, readings_of
from sctd.task.model import AllOf
from sctd.task.starts import STARTS
from sctd_services.user import DEFAULT_MODEL, USER_MODELS
from sctd_services.user.agent import REPROBE_AFTER
from sctd_services.user.intent import Observation, TaskIntent

Array = NDArray[np.float64]


@dataclass(frozen=True)
class TaskSpec:
    """What every trial of an evaluation shares: the task, the device's axes, the
    simulated user's profile (a name of :data:`~sctd_services.user.PROFILES`), the
    limits on a trial (s: ``time_limit`` None is the task file's own, which
    :meth:`of` fills in) and, in lockstep, ``arm_lag``: s by which the arm takes each
    target later than the daemon published it (0: at once), an arm that lags as an
    impedance-controlled one does; ``joint_bus``: whether lockstep's arm carries its joint
    values as CAN frames (True) or hands them over rounded as the frames would
    (:class:`~sctd_sim.arm.SimArm`; the same numbers, bit for bit).

    ``task`` is the task's name or file, not a :class:`~sctd.task.Task`: the spec goes
    to trial workers in other processes (spawned, or a cluster's) and on the command
    lines of the processes a real-time trial starts, where a name travels and a task
    object does not; each worker resolves it once, on arrival
    (:func:`~sctd_services.eval.evaluate.lockstep_job`). ``task_file`` is the file it
    was read from, which a pool on other hosts ships (:class:`~.evaluate.Shipped`)."""

    task: str
    axes: int = 3
    profile: str = "steady"
    user_model: str = field(default=DEFAULT_MODEL, metadata={
        "choices": tuple(USER_MODELS),
        "help": "how the simulated user learns the device: plain (pairs each motion with the stick held at "
                "the same moments) or adaptive (learns the input-to-motion delay too; docs/evaluation.md) "
                "(default %(default)s)"})
    starts: str = field(default="own", metadata={
        "choices": STARTS,
        "help": "where each trial's hand starts: own (the task file's start and vary), wide (drawn twice "
                "as far each way), foreign (another task's start in turn, in this task's scene; "
                "docs/evaluation.md) (default %(default)s)"})
    time_limit: float | None = field(default=None, metadata={
        "help": "s per trial (default: the task file's time_limit; with --set, each goal's)"})
    stuck_after: float = 10.0
    arm_lag: float = field(default=0.0, metadata={
        "metavar": "S",
        "help": "with --lockstep: the arm takes each target this many s after the daemon published it "
                "(a delay line), as an arm whose tracking lags (franky's impedance controller on "
                "franky-sim: about 0.05 s): how well a skill and the simulated user hold up on a slower "
                "arm (default 0)"})
    joint_bus: bool = field(default=False, metadata={
        "help": "with --lockstep: carry the arm's joint commands and states as CAN frames, as the simulator "
                "service does; without it, lockstep hands over the values the frames would carry, rounded "
                "as their signals round them: the same outcomes, bit for bit, at less cost per step"})
    task_file: str = ""

    @classmethod
    def of(cls, task: Task, ref: str | None = None, **kwargs: Any) -> TaskSpec:
        """The spec of trials of ``task``, which workers find as ``ref`` (the name or file
        it was found by; default its name); ``time_limit`` None: the task file's own."""
        if kwargs.get("time_limit") is None:
            kwargs["time_limit"] = task.outcome.time_limit
        return cls(task.name if ref is None else ref, task_file=task.file, **kwargs)

    @property
    def limit(self) -> float:
        """The trial's time limit, s (``time_limit``, as :meth:`of` resolves it)."""
        if self.time_limit is None:
            raise ValueError(f"task {self.task}: no time limit (make the spec with TaskSpec.of)")
        return self.time_limit


@dataclass
class TrialResult:
    """What one trial came to (plain data, for JSON)."""

    seed: int
    outcome: str  # success | failure | stuck
    reason: str
    time_s: float | None  # the thesis' clock; None when the task never started or ended
    duration_s: float  # from the trial's start to its end
    readings: dict[str, float | bool]  # at the end, those the task's done, success and fail rules read
    progress: float  # the task's progress reading (the poured fraction, the drawer's opening)
    mode_switches: int
    switch_time_s: float
    effort: float  # integral of |u| over the trial
    stuck_episodes: int
    dtw: float | None = None
    phase_s: dict[str, float] = field(default_factory=dict)  # s spent in each of the intent's steps
    sim_rtf: float | None = None  # real time: simulated / wall time over the trial (None in lockstep)
    # m the hand started outside the skill's region (0 inside; None: the skill states none)
    outside_region: float | None = None
    # the arm's joints (from 1) at a limit over the trial's last second (lockstep; None: not looked at)
    joint_limits: list[int] | None = None
    trajectory: list[list[float]] = field(default_factory=list, repr=False)  # t, T_obj_ee pose
    series: dict[str, list[Any]] = field(default_factory=dict, repr=False)

    def as_dict(self, with_trajectory: bool = False) -> dict[str, Any]:
        d = {k: v for k, v in self.__dict__.items() if k not in ("trajectory", "series")}
        if with_trajectory:
            d["trajectory"] = self.trajectory
            d["series"] = self.series
        return d


class TrialRecorder:
    """Watches a trial and decides when and how it ends.

    Parameters
    ----------
    task : Task
    seed : int
    switch_time : float
        Seconds one mode switch costs the user (charged per press of button 0).
    time_limit, stuck_after : float
        s.
    record_every : float
        s between recorded trajectory samples (50 Hz, as the demonstrations).
    """

    def __init__(self, task: Task, seed: int, switch_time: float, time_limit: float | None = None,
                 stuck_after: float = 10.0, record_every: float = 0.02):
        # what ends the trial, its clock, its progress and the intent its observer judges by
        self.spec = task
        self.seed = seed
        self.switch_time = switch_time
        self.time_limit = self.spec.outcome.time_limit if time_limit is None else time_limit
        self.stuck_after = stuck_after
        self.record_every = record_every
        self.observer = TaskIntent(self.spec)  # judges progress; never steers
        o = self.spec.outcome
        self.judged = readings_of(AllOf((o.done, o.success, *(f.when for f in o.fail))))
        self.t0: float | None = None
        self.t_task: float | None = None
        self.t_end_task: float | None = None
        self.best = math.inf
        self.t_best = 0.0
        self.stuck_episodes = 0
        self._phase = ""
        self.effort = 0.0
        self.switches = 0
        self._last_t: float | None = None
        self._last_button = 0
        self._next_record = 0.0
        self.trajectory: list[list[float]] = []
        self.series: dict[str, list[Any]] = {"t": [], "vf_scale": [], "membership": []}
        self.outcome: str | None = None
        self.reason = ""
        self._scene: dict[str, Any] = {}
        self.phase_s: dict[str, float] = {}
        self._done_part = 0.0  # the most progress (the task's reading) so far
        self._obj_key = b""  # the task object's pose (bytes) _T_obj_world inverts
        self._T_obj_world = np.eye(4)

    def add(self, obs: Observation, u: tuple[float, ...] | list[float], buttons: tuple[int, ...],
            vf_scale: float | None = None, membership: list[float] | None = None) -> str | None:
        """Take one observation (with the input in force); returns the outcome once the
        trial is over (and keeps returning it)."""
        if self.outcome is not None:
            return self.outcome
        t = obs.t
        if self.t0 is None:
            self.t0 = self.t_best = t
        self._account(t, u, buttons)
        self._scene = obs.scene
        T_obj = obs.objects[self.spec.object]
        self._record(t, T_obj, obs.T_world_ee, vf_scale, membership)
        if self.t_task is None and holds(self.spec.outcome.clock, _readings(obs.scene), _positions(obs)):
            self.t_task = t  # the task's clock starts
        return self._progress(obs) or self._outcome(obs, t)

    def _account(self, t: float, u: tuple[float, ...] | list[float], buttons: tuple[int, ...]) -> None:
        """Effort, time per phase and mode switches (presses of button 0) up to ``t``."""
        if self._last_t is not None:
            self.effort += float(np.linalg.norm(u)) * (t - self._last_t)
            if self._phase:
                self.phase_s[self._phase] = self.phase_s.get(self._phase, 0.0) + (t - self._last_t)
        self._last_t = t
        b0 = buttons[0] if buttons else 0
        if b0 and not self._last_button:
            self.switches += 1
        self._last_button = b0

    def _record(self, t: float, T_world_obj: Array, T_world_ee: Array, vf_scale: float | None,
                membership: list[float] | None) -> None:
        """One trajectory and series sample every ``record_every`` s."""
        if t < self._next_record:
            return
        assert self.t0 is not None
        self._next_record = t + self.record_every
        key = T_world_obj.tobytes()  # (the object rarely moves: its inverse is kept)
        if key != self._obj_key:
            self._obj_key, self._T_obj_world = key, se3.invert_transform(T_world_obj)
        T_obj_ee = self._T_obj_world @ T_world_ee
        self.trajectory.append([t - self.t0, *se3.pose_from_transform(T_obj_ee).tolist()])
        self.series["t"].append(t - self.t0)
        self.series["vf_scale"].append(float("nan") if vf_scale is None else vf_scale)
        self.series["membership"].append(membership if membership is not None else [])

    def _progress(self, obs: Observation) -> str | None:
        """Progress as the intent sees it; ends the trial as stuck without any."""
        t = obs.t
        d = self.observer.desire(obs, steer=False)
        if d.close_enough and d.phase == self._phase and t - self.t_best > REPROBE_AFTER:
            # as the user does: a sub-goal as close as the task needs and no closer for a
            # while counts as reached (progress is then measured towards the next one)
            self.observer.settle()
            d = self.observer.desire(obs, steer=False)
        done_part = float(obs.scene.get("progress", 0.0))
        if d.phase != self._phase:  # a new sub-goal: progress is measured towards it
            self._phase, self.best, self.t_best = d.phase, d.error, t
        elif d.error < self.best - 0.005 or done_part > self._done_part + 0.005:
            # closer to the sub-goal, or more of the task done (a user who pours from
            # short of the observer's centre still makes progress)
            self.best, self.t_best = min(self.best, d.error), t
            self._done_part = max(self._done_part, done_part)
        elif t - self.t_best > self.stuck_after:
            self.stuck_episodes += 1
            return self._end("stuck", f"no progress for {self.stuck_after:.0f} s ({d.phase})", t)
        return None

    def _outcome(self, obs: Observation, t: float) -> str | None:
        """The task's outcome (its file's ``done``, ``success`` and ``fail`` rules, on what
        the scene reports), or the time limit; None while it goes on. A task done on the
        tick a fail rule fires is judged by ``success``, with the rule's reason when that
        is a failure."""
        o, scene = self.spec.outcome, obs.scene
        readings, positions = _readings(scene), _positions(obs)
        failed = next((f.reason for f in o.fail if holds(f.when, readings, positions)), None)
        if scene.get("done"):
            if scene.get("success"):
                return self._end("success", o.done_reason, t)
            return self._end("failure", failed or o.done_reason, t)
        if failed is not None:
            return self._end("failure", failed, t)
        assert self.t0 is not None
        if t - self.t0 > self.time_limit:
            return self._end("failure", f"time limit ({self.time_limit:.0f} s)", t)
        return None

    def end(self, reason: str) -> None:
        """End the trial now as a failure for ``reason`` (a person who gave it up, ``sctd
        try``'s abort), at the last observation's time."""
        if self.outcome is None:
            self._end("failure", reason, self._last_t if self._last_t is not None else 0.0)

    def _end(self, outcome: str, reason: str, t: float) -> str:
        self.outcome, self.reason = outcome, reason
        if outcome == "success":
            self.t_end_task = t
        self.t_stop = t
        return outcome

    def result(self, demos: list[Array] | None = None) -> TrialResult:
        scene = self._scene
        progress = scene.get("progress", 0.0)
        time_s = None
        if self.t_task is not None and self.t_end_task is not None:
            time_s = round(self.t_end_task - self.t_task, 3)
        duration = (self.t_stop - self.t0) if self.t0 is not None and self.outcome else 0.0
        res = TrialResult(
            seed=self.seed, outcome=self.outcome or "failure", reason=self.reason or "not finished",
            time_s=time_s, duration_s=round(duration, 3), readings=self._judged_readings(),
            progress=float(progress), mode_switches=self.switches,
            switch_time_s=self.switches * self.switch_time, effort=round(self.effort, 4),
            stuck_episodes=self.stuck_episodes, trajectory=self.trajectory, series=self.series,
            phase_s={k: round(v, 3) for k, v in self.phase_s.items()})
        if demos and self.t_task is not None:
            res.dtw = dtw_to_demos(self._task_part(), demos)
        return res

    def _judged_readings(self) -> dict[str, float | bool]:
        """The readings the task's outcome judges by (:attr:`judged`), as the scene last
        reported them: flags as flags, numbers as floats; one not reported is left out."""
        r = _readings(self._scene)
        return {k: r[k] if isinstance(r[k], bool) else float(r[k]) for k in self.judged if k in r}

    def _task_part(self) -> Array:
        """The recorded poses on the thesis' clock (object frame)."""
        start = (self.t_task or 0.0) - (self.t0 or 0.0)
        end = ((self.t_end_task or self.t_stop) - (self.t0 or 0.0))
        rows = [r[1:] for r in self.trajectory if start <= r[0] <= end]
        return np.asarray(rows) if rows else np.zeros((0, 7))


def _readings(scene: dict[str, Any]) -> dict[str, Any]:
    r = scene.get("readings")
    return r if isinstance(r, dict) else {}


def _positions(obs: Observation) -> dict[str, Array]:
    """World positions of the published frames and of the hand."""
    out = {name: T[:3, 3] for name, T in obs.objects.items()}
    out["hand"] = obs.T_world_ee[:3, 3]
    return out


def dtw_to_demos(poses: Array, demos: list[Array]) -> float | None:
    """Mean over the demonstrations of the DTW cost with the tf-norm (Ch. 5.1) per
    aligned pair of poses (so trials of different lengths compare)."""
    from sctd.learn.demos import dtw

    if len(poses) < 2:
        return None
    costs = []
    for demo in demos:
        cost, path = dtw(poses, demo)
        costs.append(cost / max(1, len(path)))
    return round(float(np.mean(costs)), 5)
