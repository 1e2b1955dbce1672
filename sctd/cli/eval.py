"""``sctd eval``: how much a skill helps, measured with the simulated user.

The evaluation lives in :mod:`sctd_services.eval`; this is its command line.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import math
import os
import shlex
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

from sctd.skill import SkillError, load_skill
from sctd.skill.catalog import find_skill, find_skill_set
from sctd.task import TaskError, find_task
from sctd_services.eval.cluster import ClusterError, add_scheduler_arguments, executor_from_args
from sctd_services.eval.evaluate import (
    entries,
    evaluate,
    limits_line,
    lockstep_job,
    median_ratio,
    profile_line,
    strip_trajectories,
    table,
    task_of,
)
from sctd_services.eval.goals import SetSpec, evaluate_set, format_set_report, goal_members, tasks_of
from sctd_services.eval.numerics import numerics
from sctd_services.eval.report import write_report
from sctd_services.eval.trial import TaskSpec
from sctd_services.user import PROFILES

from ..app.errors import EXIT_FAILED, fail
from ..app.logs import log_folder
from ..app.options import TASK_HELP, add_arguments
from ..runtime.sets import goal_set
from .eval_realtime import realtime_job

CLIENT_ROLE = "sctd-operator"  # the key pair of a sctd certs folder that sctd eval presents


def add_eval_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--set", metavar="NAME|FILE", dest="skill_set",
                   help="evaluate a skill set's goal inference instead (docs/goals.md): in a room of "
                        "its members' tasks the user goes for one at random per trial; the set, the "
                        "right skill pre-selected and teleoperation, in lockstep (--user defaults to "
                        "pausing)")
    p.add_argument("--skill", action="append", metavar="SKILL",
                   help="a skill to evaluate (repeatable): a path, or the name of a shipped skill "
                        "(pour, pour.yaml; sctd skills lists them); teleop is the unassisted "
                        "baseline and runs with the first assisted skill's speed limits")
    p.add_argument("--task", metavar="NAME|FILE",
                   help=TASK_HELP + " (default: the one whose task object is the skills' object)")
    p.add_argument("--trials", type=int, default=20, help="trials per skill (default %(default)s)")
    p.add_argument("--seed", type=int, default=0,
                   help="first trial seed: trial k starts from the seeded random start seed + k")
    p.add_argument("--user", default=None,
                   help="simulated user profile (steady, noisy, pausing, hesitant; default steady, "
                        "pausing with --set)")
    p.add_argument("--belief", action="append", metavar="KEY=VALUE", default=[],
                   help="with --set: a parameter of the set's belief over its file's (repeatable; beta, "
                        "threshold, floor, escape_factor, rearm_travel, rest_radius, rest_speed; "
                        "docs/goals.md)")
    p.add_argument("--change-of-mind", action="store_true",
                   help="with --set: the user first goes for another task of the room and changes "
                        "its mind once there (the set against teleoperation; docs/goals.md)")
    p.add_argument("--practised", action="store_true",
                   help="with --set: the user did the goal's task once with its skill and once with "
                        "teleoperation before the trials, and knows what the stick does in their modes")
    p.add_argument("--baseline", action="store_true",
                   help="also run the unassisted baseline (skills/teleop.yaml) once per distinct "
                        "set of the assisted skills' speed limits")
    p.add_argument("--demos", metavar="DIR", help="demonstrations to compare trajectories with (DTW)")
    p.add_argument("--lockstep", action="store_true",
                   help="step everything in one process in simulated time (many times faster than "
                        "real time); the default runs real processes over Zenoh at real time")
    add_arguments(p, TaskSpec, only=("user_model", "starts"))
    add_arguments(p, TaskSpec, only=("arm_lag", "joint_bus"))
    p.add_argument("--driver", metavar="NAME", default=None,
                   help="real time only: run the trials on the arm this robot driver serves (sctd robot "
                        "--list; e.g. franky against franky-sim) instead of sctd's simulator, the task's "
                        "scene judged as an observer, the hand moved to each trial's start first")
    p.add_argument("--driver-args", metavar="FLAGS", default="",
                   help="the driver's flags, one string: --driver-args '--host 127.0.0.1 --realtime ignore'")
    p.add_argument("--jobs", type=int, default=None, help="lockstep trials run in parallel (default: CPUs)")
    add_arguments(p, TaskSpec, only=("time_limit",))
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout, nothing else")
    p.add_argument("--report", metavar="DIR", help="write evaluation.json and figures here")
    p.add_argument("--logs", metavar="DIR", help="keep the real-time trials' process logs here")
    add_scheduler_arguments(p, CLIENT_ROLE)


def _check(args: argparse.Namespace) -> str | None:
    """The first problem with the arguments, as ``--flag: problem``, or None."""
    if (args.skill_set is None) == (args.skill is None):
        return "--skill or --set: one of them (skills to evaluate, or a skill set)"
    if args.user is None:
        args.user = "pausing" if args.skill_set else "steady"
    if args.user not in PROFILES:
        return f"--user: unknown profile {args.user!r} (known: {', '.join(PROFILES)})"
    if args.trials < 1:
        return "--trials: must be >= 1"
    if args.time_limit is not None and not (math.isfinite(args.time_limit) and args.time_limit > 0):
        return f"--time-limit: must be a positive number of seconds, got {args.time_limit}"
    if args.jobs is not None and args.jobs < 1:
        return "--jobs: must be >= 1"
    if args.driver is not None and (args.lockstep or args.skill_set is not None):
        return "--driver: real-time trials of --skill only (lockstep trials step sctd's own arm)"
    if args.starts != "own" and (not args.lockstep or args.skill_set is not None):
        return f"--starts {args.starts}: only with --lockstep and --skill (a set's room has its own start)"
    if args.arm_lag and (not args.lockstep or args.skill_set is not None):
        return "--arm-lag: only with --lockstep and --skill (a real-time arm lags as it does)"
    if not (math.isfinite(args.arm_lag) and 0.0 <= args.arm_lag <= 1.0):
        return f"--arm-lag: must be from 0 to 1 s, got {args.arm_lag}"
    if args.joint_bus and not args.lockstep:
        return "--joint-bus: only with --lockstep (real-time trials run the simulator service, on its bus)"
    if args.driver_args and args.driver is None:
        return "--driver-args: only with --driver"
    if args.scheduler is not None and not args.lockstep:
        return "--scheduler: only with --lockstep (real-time trials start local processes)"
    if (args.practised or args.belief or args.change_of_mind) and args.skill_set is None:
        return "--practised, --belief and --change-of-mind: only with --set"
    for kv in args.belief:
        key, eq, value = kv.partition("=")
        try:
            float(value)
        except ValueError:
            eq = ""
        if not eq or not key:
            return f"--belief: {kv!r} is not KEY=NUMBER"
    if args.skill_set is not None and (args.task or args.baseline or args.demos or args.report
                                       or args.scheduler or args.logs):
        return "--set: a set's room is its members' tasks; --task, --baseline, --demos, --report, " \
               "--logs and --scheduler are for --skill"
    if args.task is not None:
        try:
            find_task(args.task)  # its scene, outcome and intent: what a trial needs
        except TaskError as e:
            return f"--task: {e}"
    return None


def _progress_bar() -> Callable[[int, int, str], None]:
    t0 = time.monotonic()

    def progress(done: int, total: int, label: str) -> None:
        n = int(30 * done / total)
        print(f"\r  [{'#' * n}{'.' * (30 - n)}] {done}/{total} trials ({label}) "
              f"{time.monotonic() - t0:.0f} s", end="", file=sys.stderr, flush=True)

    return progress


def _print_table(plain: list[dict[str, Any]], spec: TaskSpec, args: argparse.Namespace) -> None:
    how = "lockstep (simulated time)" if args.lockstep else "real time, over Zenoh"
    if args.arm_lag:
        how += f", the arm {1000 * args.arm_lag:g} ms behind each target"
    print(f"sctd eval: task {spec.task}, {args.trials} trials per skill from seed {args.seed}, {how}")
    print(f"  {profile_line(spec)}")
    print("  speed limits:")
    for r in plain:
        print("  " + limits_line(r))
    for row in table(plain):
        print("  " + row)
    ratios = median_ratio(plain)
    if ratios:
        print("  assisted vs unassisted (median completion time):")
        for line in ratios:
            print("  " + line)
    for r in plain:
        if r["switch_share"]:
            print(f"  {r['skill']}: mode switching took {100 * r['switch_share']:.1f} % of the trials' time "
                  "(Herlant et al. 2016: 17.4 % on a JACO)")
        rtf = r.get("sim_rtf_min")
        if rtf is not None and rtf < 0.95:
            print(f"  {r['skill']}: the simulator kept only {rtf:.2f} of real time in a trial (this machine "
                  "could not run it, the daemon and the user at full rate): its times are not comparable")


def main_eval(args: argparse.Namespace) -> int:
    problem = _check(args)
    if problem:
        return fail("eval", problem)
    if args.skill_set is not None:
        return _evaluate_set(args)
    # the skills' copies with another's limits (a baseline's), removed at the end
    with tempfile.TemporaryDirectory(prefix="sctd-eval-") as work:
        return _evaluate(args, Path(work))


def _evaluate(args: argparse.Namespace, work: Path) -> int:
    try:
        paths = [str(find_skill(k)) for k in args.skill]
        given = find_task(args.task) if args.task is not None else None  # (checked: it loads)
        task = task_of([load_skill(p) for p in paths], given, args.task)
        ents = entries(paths, args.baseline, work, task)
    except (SkillError, ValueError) as e:
        return fail("eval", str(e))
    # the trials' workers find the task as it was named (spec.task: TaskSpec)
    spec = TaskSpec.of(task, args.task, profile=args.user, user_model=args.user_model, starts=args.starts,
                       time_limit=args.time_limit, arm_lag=args.arm_lag, joint_bus=args.joint_bus)
    # lockstep trials are independent and run in parallel; real-time ones, which start
    # processes (the application layer's job), run one at a time
    job = lockstep_job if args.lockstep else realtime_job
    if args.driver is not None:
        job = functools.partial(realtime_job, driver=(args.driver, *shlex.split(args.driver_args)))
    jobs = (args.jobs or os.cpu_count() or 1) if args.lockstep else 1
    logdir = None if args.lockstep else log_folder(args.logs, "sctd-eval-logs-")  # lockstep: none
    try:
        pool = executor_from_args(args, CLIENT_ROLE, lambda r: print(f"\nsctd eval: {r}", file=sys.stderr))
    except ClusterError as e:
        return fail("eval", str(e))
    with pool if pool is not None else contextlib.nullcontext():
        try:
            results = evaluate(ents, spec, args.trials, args.seed, job, jobs, args.demos,
                               keep=bool(args.report), logdir=logdir, progress=_progress_bar(), pool=pool)
        except ClusterError as e:  # the scheduler gave up on a trial: every worker it ran on died
            return fail("eval", str(e), EXIT_FAILED)
    print(file=sys.stderr)
    header = {"task": task.name, "task_file": task.file, "trials": args.trials, "seed": args.seed,
              "user": args.user, "lockstep": args.lockstep, "time_limit": spec.time_limit,
              "arm_lag": args.arm_lag, "joint_bus": args.joint_bus, "numerics": numerics(),
              "robot": {"driver": args.driver or "sctd sim", "args": args.driver_args}}
    if pool is not None:
        header.update(scheduler=args.scheduler, reruns=[asdict(r) for r in pool.reruns])
    if args.report:
        for f in write_report(results, Path(args.report), header):
            print(f"sctd eval: wrote {f}", file=sys.stderr)
    plain = strip_trajectories(results)
    if args.json:
        print(json.dumps({**header, "results": plain}))
    else:
        _print_table(plain, spec, args)
    return 0


def _evaluate_set(args: argparse.Namespace) -> int:
    """``sctd eval --set FILE``: the set's goal inference against the right skill
    pre-selected and teleoperation, in lockstep (:mod:`sctd_services.eval.goals`)."""
    try:
        belief = tuple((k, float(v)) for k, _, v in (kv.partition("=") for kv in args.belief))
        spec = SetSpec(str(find_skill_set(args.skill_set)), profile=args.user, user_model=args.user_model,
                       time_limit=args.time_limit,
                       practice=args.practised, belief=belief, detour=args.change_of_mind)
        tasks_of([m.skill for m in goal_members(spec.set_file)])
        goal_set(spec.skill_set())  # (the belief's parameters checked before any trial)
    except (SkillError, TaskError, ValueError) as e:
        return fail("eval", str(e))
    bar = _progress_bar()
    result = evaluate_set(spec, args.trials, args.seed, args.jobs or os.cpu_count() or 1,
                          progress=lambda done, total: bar(done, total, ", ".join(spec.runs)))
    print(file=sys.stderr)
    if args.json:
        print(json.dumps(result))
    else:
        print(format_set_report(result))
    return 0
