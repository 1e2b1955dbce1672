"""Evaluations: skills x seeded trials, lockstep or real time, and their figures.

``sctd eval`` is a thin wrapper over :func:`evaluate`. Each skill runs the same trials
(seeds ``seed .. seed + trials - 1``: the same starts for every skill) with the same
simulated user. An unassisted baseline (``skills/teleop.yaml``, object ``world``) runs
with the speed limits of the assisted skill it is compared with, and with its control
frame at the tip of what the hand holds where the task tilts it (:func:`control_frame`):
a competent user of a teleoperated arm, not a naive one.
"""

from __future__ import annotations

import tempfile
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, Future, ProcessPoolExecutor
from contextlib import ExitStack
from dataclasses import asdict, dataclass, replace
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from sctd import se3
from sctd.files import parse_yaml
from sctd.skill import WORLD_OBJECT, Bundle, Limits, Skill, bundle_from_file, load_skill, skill_from_bundle
from sctd.skill.catalog import shipped_folder
from sctd.skill.constraints import SpeedNear
from sctd.task import Task, find_task, load_task, task_for_object
from sctd.task.kinds.tilt import Tilt, Upright
from sctd_services.user import PROFILES, USER_MODELS

from .lockstep import run_trial
from .starts import starts_task
from .trial import TaskSpec, TrialResult

TELEOP = shipped_folder() / "teleop.yaml"  # the unassisted baseline, always the shipped one


@dataclass
class Entry:
    """One skill under evaluation: ``label`` as given (or how the baseline was made),
    ``path`` of the file that runs (a copy with other limits for a baseline)."""

    label: str
    path: Path
    skill: Skill
    baseline_of: str | None = None


def task_of(skills: list[Skill], task: Task | None, ref: str | None = None) -> Task:
    """The task: given (as ``ref``, its name or file on the command line; default its
    name), or the one known task whose task object every skill's object is
    (:func:`sctd.task.task_for_object`)."""
    if task is not None:
        frames = set(task.scene.frames())
        for s in skills:
            if s.object != WORLD_OBJECT and s.object not in frames:
                raise ValueError(f"skill {s.name}: its object {s.object!r} is not in task "
                                 f"{task.name if ref is None else ref} "
                                 f"(its frames: {', '.join(sorted(frames))}); the skill would never see "
                                 "where it is")
        return task
    objects = {s.object for s in skills if s.object != WORLD_OBJECT}
    found = task_for_object(next(iter(objects))) if len(objects) == 1 else None
    if found is None:
        named = ", ".join(sorted(objects)) or "none"
        raise ValueError(f"cannot tell the task from the skills' objects ({named}); pass --task NAME|FILE "
                         "(sctd tasks lists them)")
    return found


def restyled(bundle: Bundle, limits: Limits, control: tuple[str, np.ndarray] | None = None,
             cap: tuple[str, SpeedNear] | None = None) -> Bundle:
    """``bundle`` (a skill and its model files) with other limits; with ``control`` (a
    frame's name and ``T_ee_frame``), a teleoperation skill's control frame: its rotations
    turn about that frame's origin (:func:`control_frame`); with ``cap`` (an object's name
    and a ``speed_near``), that cap near that object (:func:`_capped`)."""
    doc = parse_yaml(bundle.yaml_text, bundle.name)
    doc["limits"] = {"max_linear_speed": limits.max_linear_speed,
                     "max_angular_speed": limits.max_angular_speed}
    if control is not None:
        name, T = control
        doc.setdefault("frames", {})[name] = {"parent": "ee", "pose": se3.pose_from_flat(
            se3.flat_from_transform(T))}
        for state in doc.get("states", {}).values():
            for m in state.get("input_mapping", []):
                if m.get("type") == "linear" and any(a in ROTATIONS for a in m.get("axes", ())):
                    m["frame"] = name
    if cap is not None:
        _capped(doc, cap)
    return Bundle(name=bundle.name, yaml_text=yaml.safe_dump(doc, sort_keys=False), files=bundle.files)


def with_limits(path: Path, limits: Limits, directory: Path,
                control: tuple[str, np.ndarray] | None = None,
                cap: tuple[str, SpeedNear] | None = None) -> Path:
    """A copy of the skill file at ``path`` (and its model files) in ``directory``,
    :func:`restyled`."""
    return write_bundle(restyled(bundle_from_file(path), limits, control, cap), directory)


def write_bundle(bundle: Bundle, directory: Path) -> Path:
    """``bundle`` as a skill file and its model files in ``directory``; the file's path."""
    directory.mkdir(parents=True, exist_ok=True)
    out = directory / Path(bundle.name).name
    out.write_text(bundle.yaml_text)
    for rel, data in bundle.files.items():
        (directory / rel).parent.mkdir(parents=True, exist_ok=True)
        (directory / rel).write_bytes(data)
    return out


def competent_baseline(teleop: Bundle, ref: Skill, task: Task | None) -> tuple[Bundle, str]:
    """The competent baseline of the assisted skill ``ref`` on ``task``: the
    teleoperation skill ``teleop`` with ``ref``'s speed limits, its ``speed_near`` cap
    near its object (:func:`cap_of`) and the task's control frame
    (:func:`control_frame`), and the label that says so."""
    control = control_frame(task)
    c = cap_of(ref)
    bundle = restyled(teleop, ref.limits, control, None if c is None else (ref.object, c))
    return bundle, baseline_label(ref.name, control, ref.object if c is not None else None)


def baseline_label(ref: str, control: tuple[str, np.ndarray] | None, capped_near: str | None) -> str:
    """``teleop (limits of REF, control frame F, capped near OBJECT)``."""
    at = f", control frame {control[0]}" if control is not None else ""
    near = "" if capped_near is None else f", capped near {capped_near}"
    return f"teleop (limits of {ref}{at}{near})"


ROTATIONS = ("rx", "ry", "rz")


def cap_of(skill: Skill) -> SpeedNear | None:
    """The loosest of a skill's ``speed_near`` caps when every state has one (else the
    hand may be in an uncapped state: None)."""
    caps = []
    for state in skill.states:
        mine = [c for c in state.active_constraints if isinstance(c, SpeedNear)]
        if not mine:
            return None
        caps.append(max(mine, key=lambda c: (c.max_linear_speed, c.max_angular_speed, -c.within)))
    return max(caps, key=lambda c: (c.max_linear_speed, c.max_angular_speed, -c.within)) if caps else None


def _capped(doc: dict[str, Any], cap: tuple[str, SpeedNear]) -> None:
    """A teleoperation skill's document (``doc``, changed in place) measured from the
    object ``cap[0]`` with the ``speed_near`` cap ``cap[1]`` in every state: the
    baseline near a person's face is as slow as the assisted skill there. Its axes are
    then the object's, not the world's: a task object's z is up as the world's, so they
    differ by a turn about the vertical, which the user learns as it learns any axes."""
    obj, c = cap
    doc["object"] = obj
    for state in doc.get("states", {}).values():
        state.setdefault("active_constraints", []).append(c.to_yaml())


def control_frame(task: Task | None) -> tuple[str, np.ndarray] | None:
    """The control frame a skilled user of a teleoperated arm sets at the tool's tip, as
    a JACO's user does: the frame of what the hand holds that the task's intent tilts or
    brings upright (a bottle's opening), so that turning the hand turns about it instead
    of swinging it round the wrist. None when the task tilts nothing the hand holds."""
    if task is None or task.scene.held is None:
        return None
    frames = task.scene.held.frames
    for s in task.intent:  # (a tilt's, an upright's frame: the reach's before it)
        if isinstance(s.action, Tilt | Upright) and s.action.frame() in frames:
            return s.action.frame(), frames[s.action.frame()]
    return None


def entries(paths: list[str], baseline: bool, workdir: Path, task: Task | None = None) -> list[Entry]:
    """The skills to evaluate; a world-object skill (the baseline) gets the first
    assisted skill's limits (its own when none is given) and the task's control frame
    (:func:`control_frame`), and
    ``baseline`` adds one teleop run per assisted skill."""
    given = [Entry(p, Path(p), load_skill(p)) for p in paths]
    assisted = [e for e in given if e.skill.object != WORLD_OBJECT]
    control = control_frame(task)
    out: list[Entry] = []
    for e in given:
        if e.skill.object == WORLD_OBJECT and assisted:
            ref = assisted[0]
            copy = workdir / f"{e.skill.name}-as-{ref.skill.name}"
            p = with_limits(e.path, ref.skill.limits, copy, control)
            e = Entry(e.label, p, load_skill(p), ref.label)
        elif e.skill.object == WORLD_OBJECT and control is not None:  # alone: its own limits
            p = with_limits(e.path, e.skill.limits, workdir / f"{e.skill.name}-competent", control)
            e = Entry(e.label, p, load_skill(p))
        out.append(e)
    if baseline:  # one baseline per set of limits: same limits and caps, same seeds and trials
        done: list = []
        for ref in assisted:
            c = cap_of(ref.skill)
            key = (ref.skill.limits, None if c is None else c.to_yaml())
            if key in done:
                continue
            done.append(key)
            cap = None if c is None else (ref.skill.object, c)
            p = with_limits(TELEOP, ref.skill.limits, workdir / f"teleop-as-{ref.skill.name}", control, cap)
            label = baseline_label(ref.label, control, None if c is None else ref.skill.object)
            out.append(Entry(label, p, load_skill(p), ref.label))
    return out


TrialJob = Callable[[str, TaskSpec, int, "str | None", bool, "Path | None"], dict[str, Any]]
"""How one trial runs: ``(skill path, spec, seed, demos dir, keep trajectory, log dir) ->
TrialResult.as_dict()``. :func:`lockstep_job` here; the real-time one, which starts
processes, is the application layer's (:func:`sctd.cli.eval_realtime.realtime_job`)."""


def lockstep_job(path: str, spec: TaskSpec, seed: int, demos_dir: str | None, keep: bool,
                 logdir: Path | None) -> dict[str, Any]:
    """One lockstep trial (in this process, simulated time; ``logdir`` is unused). A
    worker's entry point: ``spec.task`` arrived as a name or file and is resolved here,
    once (:class:`~.trial.TaskSpec`)."""
    demos = read_demo_poses(demos_dir) if demos_dir else None
    task, start_of = starts_task(find_task(spec.task), spec.starts, seed)
    out = run_trial(load_skill(path), spec, seed, demos, task=task).as_dict(with_trajectory=keep)
    return {**out, "start_of": start_of}


@dataclass(frozen=True)
class Shipped:
    """What a lockstep trial reads, carried with it to a worker that has none of this
    machine's files: the skill's packed bundle, the task file's text and the
    demonstrations' poses (the DTW figure's, or None)."""

    bundle: bytes
    task_name: str
    task_text: str
    demos: list[np.ndarray] | None = None

    @classmethod
    def of(cls, path: str | Path, spec: TaskSpec, demos_dir: str | None) -> Shipped:
        """What trials of the skill file ``path`` on ``spec``'s task (its file,
        ``spec.task_file``: :meth:`TaskSpec.of <.trial.TaskSpec.of>`) read."""
        if not spec.task_file:
            raise ValueError(f"task {spec.task}: no task file to ship (make the spec with TaskSpec.of)")
        file = Path(spec.task_file)
        return cls(bundle_from_file(path).pack(), file.stem, file.read_text(),
                   read_demo_poses(demos_dir) if demos_dir else None)


def shipped_job(shipped: Shipped, spec: TaskSpec, seed: int, keep: bool) -> dict[str, Any]:
    """:func:`lockstep_job` from what ``shipped`` carries: the skill from its bundle,
    the task from its text (written to a folder of its own for the trial, read there
    once, removed after)."""
    skill = skill_from_bundle(Bundle.unpack(shipped.bundle))
    with tempfile.TemporaryDirectory(prefix="sctd-trial-") as tmp:
        file = Path(tmp) / f"{shipped.task_name}.yaml"
        file.write_text(shipped.task_text)
        task, start_of = starts_task(load_task(file), spec.starts, seed)
        out = run_trial(skill, replace(spec, task=str(file), task_file=str(file)), seed, shipped.demos,
                        task=task).as_dict(with_trajectory=keep)
        return {**out, "start_of": start_of}


@dataclass(frozen=True)
class Trial:
    """One trial as a pool runs it, ``job(*args)``, with the ``name`` reports use."""

    name: str
    job: Callable[..., dict[str, Any]]
    args: tuple

    def __call__(self) -> dict[str, Any]:
        return self.job(*self.args)


def ships_trials(pool: Executor | None) -> bool:
    """Whether ``pool`` runs trials where this machine's files are not (a cluster's
    executor says so: :class:`sctd_services.eval.cluster.ClusterExecutor`)."""
    return bool(getattr(pool, "ships_trials", False))


def _trials(e: Entry, spec: TaskSpec, seeds: list[int], job: TrialJob, demos: str | None, keep: bool,
            folder: Path | None, ship: bool) -> list[Trial]:
    """The trials of ``e``; shipped (:class:`Shipped`) for a pool on other hosts."""
    if not ship:
        return [Trial(f"{e.skill.name} seed {s}", job, (str(e.path), spec, s, demos, keep, folder))
                for s in seeds]
    if job is not lockstep_job:
        raise ValueError("only lockstep trials run on a cluster (real-time ones start local processes)")
    shipped = Shipped.of(e.path, spec, demos)
    return [Trial(f"{e.skill.name} seed {s}", shipped_job, (shipped, spec, s, keep)) for s in seeds]


def read_demo_poses(directory: str | Path) -> list[np.ndarray]:
    """The demonstrations' poses (n, 7), object frame, for the DTW figure."""
    from sctd.learn.demos import read_demos  # the learner's reader, only with --demos

    return [d.poses for d in read_demos(directory)]


def evaluate(ents: list[Entry], spec: TaskSpec, trials: int, seed: int, job: TrialJob = lockstep_job,
             jobs: int = 1, demos: str | None = None, keep: bool = False, logdir: Path | None = None,
             progress: Callable[[int, int, str], None] | None = None,
             pool: Executor | None = None,
             until: Callable[[list[dict[str, Any]]], bool] | None = None) -> list[dict[str, Any]]:
    """Run every entry's trials; one result map per entry (see :func:`summarise`).

    With ``jobs`` > 1 the trials run in that many spawned processes (lockstep trials are
    independent; real-time ones compete for the CPU and should run one at a time); a
    long-running caller (the learner service) passes its own warm ``pool`` instead, and
    a pool on other hosts (:mod:`.cluster`) gets each trial's skill and task with it.
    ``until(per_trial)``, asked after each trial (in seed order), ends an entry's trials
    early when it returns true: the trials not started are cancelled, and the entry's
    result has ``planned`` (the trials asked for) and ``stopped_early``. With a pool, it
    is also asked before a trial is given to the pool, of the trials so far followed by
    a success for each one under way: a trial it would not need if those succeed is not
    started until they have ended (:func:`_paced`), so the last trials the decision needs
    do not share the CPU with one it will not.
    """
    seeds = list(range(seed, seed + trials))
    total = len(ents) * trials
    done = 0
    results = []
    n = max(1, min(jobs, trials))
    with ExitStack() as stack:
        if pool is None and n > 1:
            pool = stack.enter_context(ProcessPoolExecutor(n, mp_context=get_context("spawn")))
        for e in ents:
            folder = logdir / e.skill.name if logdir else None  # None: the job's own choice
            trials_of = _trials(e, spec, seeds, job, demos, keep, folder, ships_trials(pool))
            per_trial: list[dict[str, Any]] = []
            futures: list[Future] = []
            if pool is not None and until is not None:
                runs = _paced(pool, trials_of, until, per_trial, futures)
            elif pool is not None:
                futures = [pool.submit(t) for t in trials_of]
                runs = (f.result() for f in futures)
            else:
                runs = (t() for t in trials_of)
            stopped = False
            for r in runs:
                per_trial.append(r)
                done += 1
                if progress:
                    progress(done, total, e.label)
                if until is not None and len(per_trial) < trials and until(per_trial):
                    stopped = True
                    for f in futures:
                        f.cancel()  # the ones not started; a running one finishes unheard
                    done += trials - len(per_trial)
                    break
            res = summarise(e, per_trial, spec.limit)
            if until is not None:
                res.update(planned=trials, stopped_early=stopped)
            results.append(res)
    return results


HOPED: dict[str, Any] = {"outcome": "success"}
"""What :func:`_paced` takes a trial under way to come to when it asks ``until``."""


def _paced(pool: Executor, trials: list[Trial], until: Callable[[list[dict[str, Any]]], bool],
           per_trial: list[dict[str, Any]], futures: list[Future]) -> Iterator[dict[str, Any]]:
    """The results of ``trials`` on ``pool``, in seed order, each trial given to the pool
    only while ``until`` would not stop on the trials so far (``per_trial``, which the
    caller extends with each result) followed by a success for each one under way
    (:data:`HOPED`); the futures given go to ``futures`` (for the caller to cancel)."""
    flying: deque[Future] = deque()
    nxt = 0
    while nxt < len(trials) or flying:
        while nxt < len(trials) and (not flying or not until(per_trial + [HOPED] * len(flying))):
            f = pool.submit(trials[nxt])
            flying.append(f)
            futures.append(f)
            nxt += 1
        yield flying.popleft().result()


def _stats(xs: list[float]) -> dict[str, float | None]:
    if not xs:
        return {"mean": None, "std": None, "median": None}
    a = np.asarray(xs, dtype=float)
    return {"mean": round(float(a.mean()), 3), "std": round(float(a.std()), 3),
            "median": round(float(np.median(a)), 3)}


def _readings_mean(per_trial: list[dict[str, Any]]) -> dict[str, float]:
    """The mean over the trials of each number among their ``readings`` (flags left out),
    in the order the first trial names them."""
    names = dict.fromkeys(k for t in per_trial for k, v in t.get("readings", {}).items()
                          if not isinstance(v, bool))
    return {k: round(float(np.mean([t["readings"][k] for t in per_trial if k in t["readings"]])), 5)
            for k in names}


def summarise(e: Entry, per_trial: list[dict[str, Any]], time_limit: float) -> dict[str, Any]:
    """The figures of one skill over its trials (the JSON of ``sctd eval --json``).
    ``time_s_limited_median`` counts every trial that did not succeed at ``time_limit``
    (a censored median: defined even when few or no trials succeed)."""
    n = len(per_trial)
    ok = [t for t in per_trial if t["outcome"] == "success"]
    times = [t["time_s"] for t in ok if t["time_s"] is not None]
    limited = [t["time_s"] if t["outcome"] == "success" and t["time_s"] is not None else time_limit
               for t in per_trial]
    dtws = [t["dtw"] for t in per_trial if t.get("dtw") is not None]
    durations = [t["duration_s"] for t in per_trial]
    switch = [t["switch_time_s"] for t in per_trial]
    share = sum(switch) / sum(durations) if sum(durations) > 0 else 0.0
    return {
        "skill": e.label,
        "name": e.skill.name,
        "id": e.skill.id,
        "baseline_of": e.baseline_of,
        "trials": n,
        "successes": len(ok),
        "success_rate": round(len(ok) / n, 4) if n else 0.0,
        "time_s": _stats(times),
        "time_s_limited_median": round(float(np.median(limited)), 3) if n else None,
        "readings_mean": _readings_mean(per_trial),
        "dtw": {k: v for k, v in _stats(dtws).items() if k != "median"} if dtws else None,
        "mode_switches_mean": round(float(np.mean([t["mode_switches"] for t in per_trial])), 3) if n else 0.0,
        "switch_time_s_mean": round(float(np.mean(switch)), 3) if n else 0.0,
        "switch_share": round(share, 4),
        "effort_mean": round(float(np.mean([t["effort"] for t in per_trial])), 3) if n else 0.0,
        "stuck": sum(1 for t in per_trial if t["outcome"] == "stuck"),
        "sim_rtf_min": min((t["sim_rtf"] for t in per_trial if t.get("sim_rtf") is not None), default=None),
        "limits": asdict(e.skill.limits),
        "per_trial": per_trial,
    }


SPILLED = "spilled"
"""The quantity of held contents' reading of what missed the container (``<held>.spilled``,
docs/tasks.md): the table shows a column of it for a task that reports it."""


def spill_readings(results: list[dict[str, Any]]) -> list[str]:
    """The readings among the results' means that are a spill (:data:`SPILLED`), named as
    the task file names them (``bottle.spilled``)."""
    return list(dict.fromkeys(k for r in results for k in r.get("readings_mean", {})
                              if k.rpartition(".")[2] == SPILLED))


def table(results: list[dict[str, Any]]) -> list[str]:
    """Rows like the thesis' Tables 5.1-5.4, with a column of the mean spill for a task
    whose held contents report one (headed by its reading's name)."""

    def pm(d: dict | None, digits: int = 2) -> str:
        if not d or d.get("mean") is None:
            return "-"
        return f"{d['mean']:.{digits}f} +- {d['std']:.{digits}f}"

    def spills(r: dict[str, Any]) -> str:
        means = r.get("readings_mean", {})
        return "".join(f"  {'-' if k not in means else f'{means[k]:.3f}':>{max(6, len(k))}}" for k in spill)

    spill = spill_readings(results)
    w = max(12, *(len(r["skill"]) for r in results))
    head = (f"{'skill':<{w}}  {'success':>9}  {'time [s] (median)':>22}"
            + "".join(f"  {k:>6}" for k in spill) + f"  {'DTW':>15}  "
            f"{'switches (s)':>13}  {'effort':>7}  {'stuck':>5}")
    rows = [head, "-" * len(head)]
    for r in results:
        t = r["time_s"]
        time_cell = "-" if t["mean"] is None else f"{pm(t)} ({t['median']:.2f})"
        rows.append(f"{r['skill']:<{w}}  {r['successes']:>4}/{r['trials']:<4}  {time_cell:>22}"
                    f"{spills(r)}  {pm(r['dtw'], 3):>15}  "
                    f"{r['mode_switches_mean']:>5.1f} ({r['switch_time_s_mean']:>4.1f})  "
                    f"{r['effort_mean']:>7.2f}  {r['stuck']:>5}")
    return rows


def profile_line(spec: TaskSpec) -> str:
    p = PROFILES[spec.profile]
    return (f"user {p.name}: reaction delay {p.reaction_delay} s, update every {p.update_period} s, "
            f"noise {p.noise_constant} + {p.noise_gain} |u|, dead zone {p.dead_zone}, "
            f"mode switch {p.switch_time} s; learning the device {spec.user_model} "
            f"({USER_MODELS[spec.user_model].about})")


def limits_line(r: dict[str, Any]) -> str:
    lim = r["limits"]
    of = f" (the limits of {r['baseline_of']})" if r.get("baseline_of") else ""
    return f"  {r['skill']}: {lim['max_linear_speed']} m/s, {lim['max_angular_speed']} rad/s{of}"


def cap_in(path: str) -> SpeedNear | None:
    """:func:`cap_of` the skill file at ``path`` (None when it is gone: a result read
    back after its work folder)."""
    try:
        return cap_of(load_skill(path))
    except (OSError, ValueError):
        return None


def result_cap(r: dict[str, Any]) -> SpeedNear | None:
    """The ``speed_near`` cap a result ran with: its skill's, or for a baseline the cap
    of the skill it was made for (:func:`entries` gives it that skill's; its own copy is
    in a work folder that may be gone)."""
    return cap_in(r.get("baseline_of") or r["skill"])


def baseline_for(ref: dict[str, Any], results: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The baseline among ``results`` that ran with the speed limits and the
    ``speed_near`` cap of the result ``ref`` (:func:`entries` makes one per such set)."""
    cap = result_cap(ref)
    text = None if cap is None else cap.to_yaml()
    for b in results:
        if b.get("baseline_of") and b["limits"] == ref["limits"]:
            c = result_cap(b)
            if (None if c is None else c.to_yaml()) == text:
                return b
    return None


def median_ratio(results: list[dict[str, Any]]) -> list[str]:
    """Each assisted skill's median time against the baseline's with the same limits
    (:func:`baseline_for`):
    over successful trials, and with every other trial counted at the time limit."""
    out = []
    for ref in results:
        if ref.get("baseline_of") or ref["name"] == "teleop":
            continue
        b = baseline_for(ref, results)
        if b is None:
            continue
        a, u = ref["time_s"]["median"], b["time_s"]["median"]
        both = (f"{a:.2f} s vs {u:.2f} s ({a / u:.2f} of the baseline's)" if a is not None and u is not None
                else f"{'-' if a is None else f'{a:.2f} s'} vs {'-' if u is None else f'{u:.2f} s'}")
        al, ul = ref["time_s_limited_median"], b["time_s_limited_median"]
        out.append(f"  {ref['skill']}: successful trials {both}; failures at the limit "
                   f"{al:.2f} s vs {ul:.2f} s ({al / ul:.2f}); {ref['successes']}/{ref['trials']} "
                   f"vs {b['successes']}/{b['trials']} succeeded")
    return out


def strip_trajectories(results: list[dict[str, Any]]) -> list[dict[str, Any]]:
    return [{**r, "per_trial": [{k: v for k, v in t.items() if k not in ("trajectory", "series")}
                                for t in r["per_trial"]]} for r in results]


__all__ = [
    "Entry",
    "Shipped",
    "TaskSpec",
    "Trial",
    "TrialResult",
    "baseline_for",
    "cap_in",
    "cap_of",
    "control_frame",
    "entries",
    "evaluate",
    "result_cap",
    "summarise",
    "table",
    "task_of",
    "with_limits",
]
