"""``sctd bench check``: the learner's check, its operating points and what it costs whoever
waits for it.

**Operating points** (pure, no processes): for true success rates from 0.7 to 1, the
share of skills the check passes and the trials it runs, exactly (dynamic programming
over the truncated sequential test, :meth:`~sctd_services.learner.check.SequentialRule.operating_point`)
and over ``--sequences`` random sequences of trials (seeded), beside the fixed rule the
check replaced (at most one failure in ten trials).

**Request -> swapped skill** (``--end-to-end``, on by default): the simulator (``sctd sim
--task T``), the daemon (``sctd run --skill S``) and the learner (``sctd learner``, a store
of its own) on a private loopback port; the task's shipped demonstrations published to
the learner; then one training request (``--method``, swap on) and the time from sending
it to the daemon's status naming the new skill, with the learner's own timings (train,
check, swap) and the daemon's lateness meanwhile (the median and the largest of its
per-second p99, against a quiet window before the request). Then, the learner stopped and
the simulator and the daemon still running, the **floor** of the check: its trials alone
(:func:`trials_alone`), and of request -> swapped: those plus the training. With
``--baseline`` (a source tree, as ``sctd bench cost`` takes it), the same in that tree's
programs, interleaved.
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import sys
import threading
import time
from contextlib import ExitStack
from math import comb
from pathlib import Path
from typing import Any

import yaml
import zenoh

from sctd_services.learner import NICE
from sctd_services.learner.check import CheckSettings, SequentialRule, simulate

from ..app.defaults import defaults
from ..cli.procs import Child, free_port
from ..cli.teach_loop import candidate_frames
from ..learn.demos import read_demos
from ..skill.catalog import shipped_folder
from ..task import Task, find_task
from ..wire import Keys, client, codec
from ..wire.session import session
from . import run_and_report
from .cost import Tree, source_tree

RATES = (0.7, 0.8, 0.85, 0.9, 0.95, 0.99, 1.0)
GOAL_S = 20.0  # request -> swapped skill, s
BOUNDS = {0.8: ("accept", 0.38), 0.95: ("reject", 0.09)}  # the operating points to keep


def fixed_rule(p: float, trials: int = 10, failures: int = 1) -> float:
    """The chance that at most ``failures`` of ``trials`` trials fail at success rate ``p``."""
    return sum(comb(trials, k) * (1 - p) ** k * p ** (trials - k) for k in range(failures + 1))


def operating_points(sequences: int, seed: int) -> list[dict[str, Any]]:
    rule = SequentialRule.around(CheckSettings().floor, CheckSettings().trials)
    rng = random.Random(seed)
    out = []
    for p in RATES:
        exact, n = rule.operating_point(p)
        sim, n_sim = simulate(rule, p, sequences, rng)
        out.append({"p": p, "accept_exact": round(exact, 4), "trials_exact": round(n, 2),
                    "accept_simulated": round(sim, 4), "trials_simulated": round(n_sim, 2),
                    "accept_fixed_10": round(fixed_rule(p), 4)})
    return out


# --- request -> swap -----------------------------------------------------------------------

class _Watch:
    """The daemon's skill and per-second lateness p99, and the learner's events."""

    def __init__(self) -> None:
        self.skill: str | None = None
        self.seconds: list[tuple[float, float]] = []
        self.events: list[dict[str, Any]] = []
        self._lock = threading.Lock()

    def status(self, sample: zenoh.Sample) -> None:
        m = codec.unpack_map(sample.payload.to_bytes())
        self.skill = m.get("skill")
        try:
            row = (time.monotonic(), float(m["recent_ms"]["lateness"]["p99"]))
        except (KeyError, TypeError, ValueError):
            return
        with self._lock:
            if not self.seconds or row[0] - self.seconds[-1][0] >= 0.95:
                self.seconds.append(row)

    def learner(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self.events.append(codec.unpack_map(sample.payload.to_bytes()))

    def lateness(self, t0: float, t1: float) -> dict[str, float | None]:
        with self._lock:
            xs = [x for t, x in self.seconds if t0 <= t <= t1]
        return {"median": round(statistics.median(xs), 4) if xs else None, "max": max(xs, default=None),
                "seconds": len(xs)}

    def count(self, event: str) -> int:
        with self._lock:
            return sum(1 for e in self.events if e.get("event") == event)


def _until(pred: Any, timeout: float, why: str) -> None:
    end = time.monotonic() + timeout
    while not pred():
        if time.monotonic() > end:
            raise RuntimeError(why)
        time.sleep(0.05)


def _publish_demos(s: zenoh.Session, keys: Keys, found: Task) -> list[str]:
    task, obj = found.name, found.object
    names = []
    for d in read_demos(shipped_folder() / "demos" / task):
        name = Path(d.name).stem
        rows = [[float(t), *map(float, p)] for t, p in zip(d.t, d.poses, strict=True)]
        s.put(keys.demos(task, name), codec.encode_demo(task, name, obj, rows),
              congestion_control=zenoh.CongestionControl.BLOCK)  # as sctd record: none lost in a burst
        names.append(name)
    return names


SHIPPED_RECIPE: dict[str, dict[str, Any]] = {
    "vf": {"vf-models": ["translation", "cylinder", "sphere", "point", "general"], "seed": 0},
    "linear": {"seed": 0}}
"""The hyperparameters the shipped learned skills were made with (skills/README.md), for a
request without ``--param``."""


TRIALS_ALONE = """
import json, os, sys, time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from sctd.task import find_task
from sctd_services.eval.evaluate import entries, evaluate
from sctd_services.eval.trial import TaskSpec
skill, task, trials, seed, jobs, nice = sys.argv[1], sys.argv[2], *map(int, sys.argv[3:7])
os.nice(nice)
found = find_task(task)
ents = entries([skill], baseline=False, workdir=Path(skill).parent)
with ProcessPoolExecutor(jobs, mp_context=get_context("spawn"), initializer=__import__,
                         initargs=("sctd_services.eval.lockstep",)) as pool:
    for f in [pool.submit(time.sleep, 0.5) for _ in range(jobs)]:
        f.result()
    t0 = time.monotonic()
    [res] = evaluate(ents, TaskSpec.of(found), trials, seed, jobs=jobs, pool=pool)
    print(json.dumps({"wall_s": time.monotonic() - t0, "successes": res["successes"]}))
"""
"""The floor of the check (``python -c``, in a tree's own environment): the same trials as
the learner's check, in a warm pool of as many niced processes, timed from the first
trial given to the last one done; no learner, no Zenoh, no training."""


def trials_alone(tree: Tree, found: Task, skill_file: Path, trials: int, seed: int) -> dict[str, Any]:
    """The check's trials of ``skill_file`` run alone (:data:`TRIALS_ALONE`), as the
    learner runs them (its default ``--jobs`` and ``--nice``)."""
    import subprocess

    settings = CheckSettings()
    argv = [sys.executable, "-c", TRIALS_ALONE, str(skill_file), found.name, str(trials), str(seed),
            str(settings.jobs), str(NICE)]
    done = subprocess.run(argv, env=tree.env, cwd=tree.cwd, capture_output=True, text=True, timeout=900)
    if done.returncode != 0:
        raise RuntimeError(f"the check's trials alone failed: {done.stderr[-1000:]}")
    out: dict[str, Any] = json.loads(done.stdout.strip().splitlines()[-1])
    return out


def request_to_swap(tree: Tree, found: Task, skill: str, method: str, params: dict[str, Any], quiet: float,
                    logdir: Path, k: int) -> dict[str, Any]:
    """One end-to-end run of ``tree`` (module doc): its figures, and the floor of its
    check (:func:`trials_alone`, with the simulator and the daemon still running)."""
    keys, hub = Keys(), f"tcp/127.0.0.1:{free_port()}"
    task = found.name  # the child processes and the learner's request name it
    watch = _Watch()
    store = logdir / f"store-{k}"
    with ExitStack() as stack:
        s = stack.enter_context(session(listen=[hub]))
        stack.enter_context(s.declare_subscriber(keys.status, watch.status))
        stack.enter_context(s.declare_subscriber(keys.learner_status, watch.learner))
        children = {}
        for name, args in (("sim", ("sim", "--task", task)), ("run", ("run", "--skill", skill)),
                           ("learner", ("learner", "--store", str(store)))):
            children[name] = stack.enter_context(Child("sctd.cli.main", *args, "--connect", hub, "--listen",
                                                       f"tcp/127.0.0.1:{free_port()}",
                                                       log=logdir / f"{name}-{k}.log", env=tree.env,
                                                       cwd=tree.cwd))
        _until(lambda: watch.skill is not None and watch.count("state") > 0, 90,
               f"the daemon or the learner did not come up; see {logdir}/*-{k}.log")
        names = _publish_demos(s, keys, found)
        _until(lambda: watch.count("stored") + watch.count("duplicate") >= len(names), 60,
               f"the learner did not store the demonstrations; see {logdir}/learner-{k}.log")
        first = watch.skill
        t_quiet = time.monotonic()
        time.sleep(quiet)
        t0 = time.monotonic()
        req: dict[str, Any] = {"task": task, "method": method, "demos": names, "swap": True, "params": params}
        if method == "linear" and (frames := candidate_frames(found)):
            req["frames"] = frames
        got = client.query(s, keys.learner, codec.pack(req), timeout=900, find=10)
        if got is None or not got[0]:
            raise RuntimeError(f"the learner did not train: {got[1].get('error') if got else 'no reply'}")
        reply = got[1]
        if reply.get("swapped"):
            _until(lambda: watch.skill == reply["id"] and watch.skill != first, 30,
                   "the daemon does not name the swapped skill")
        t1 = time.monotonic()
        ev = reply.get("evaluation") or {}
        floor = None
        if ev.get("trials"):
            # without the learner: trials it had started before the check decided would
            # otherwise run on beside the floor's (its trial processes die with it)
            children["learner"].stop()
            [file] = (store / "skills" / reply["id"]).glob("*.yaml")
            floor = trials_alone(tree, found, file, ev["trials"], ev.get("seed", CheckSettings().seed))
    return {"tree": tree.label, "swapped": bool(reply.get("swapped")), "reason": reply.get("reason"),
            "request_to_swap_s": round(t1 - t0, 2), "timings": reply.get("timings", {}),
            "trials": ev.get("trials"), "successes": ev.get("successes"),
            "trials_alone_s": None if floor is None else round(floor["wall_s"], 2),
            "lateness_quiet_ms": watch.lateness(t_quiet, t0), "lateness_check_ms": watch.lateness(t0, t1)}


def run_check_bench(args: argparse.Namespace, logdir: Path) -> dict[str, Any]:
    out: dict[str, Any] = {"sequences": args.sequences, "points": operating_points(args.sequences, args.seed),
                           "runs": [], "task": args.task, "method": args.method}
    if not args.end_to_end:
        return out
    task = find_task(args.task)  # the bench's --task, resolved once
    with ExitStack() as stack:
        trees = [Tree("this", cwd=logdir)]
        if args.baseline:
            trees.insert(0, source_tree(args.baseline, stack))
            out["baseline"] = trees[0].source
        k = 0
        for r in range(args.rounds):
            for tree in (trees if r % 2 == 0 else trees[::-1]):
                run = request_to_swap(tree, task, args.skill, args.method, _params(args), args.quiet,
                                      logdir, k)
                k += 1
                out["runs"].append(run)
                print(_run_line(run), file=sys.stderr, flush=True)
    return out


def _params(args: argparse.Namespace) -> dict[str, Any]:
    if not args.param:
        return dict(SHIPPED_RECIPE[args.method])
    out: dict[str, Any] = {}
    for item in args.param:
        name, _, value = item.partition("=")
        out[name] = yaml.safe_load(value)  # a scalar as sctd train reads it: 0.005, 3, true, intent
    return out


def _run_line(r: dict[str, Any]) -> str:
    t = r["timings"]
    q, c = r["lateness_quiet_ms"], r["lateness_check_ms"]

    def lat(x: dict) -> str:
        return "-" if x["median"] is None else f"{x['median']:.3f} ({x['max']:.3f})"

    alone, train = r.get("trials_alone_s"), t.get("train_s", 0)
    floors = ("", "") if alone is None else (f" (floor {train + alone:5.1f})", f" (floor {alone:5.1f})")
    line = (f"  {r['tree']:<9s} {r['request_to_swap_s']:>7.1f} s{floors[0]}  train {train:5.1f}  "
            f"check {t.get('check_s', 0):5.1f}{floors[1]}  swap {t.get('swap_s', 0):4.1f}   "
            f"{r['successes']}/{r['trials']} trials  {'swapped' if r['swapped'] else 'NOT swapped'}   "
            f"lateness p99 quiet {lat(q)}, during {lat(c)} ms")
    return line if r["swapped"] else f"{line}\n      the learner: {r.get('reason')}"


def print_report(r: dict[str, Any]) -> None:
    print(f"sctd bench check: the learner's sequential check (at most {CheckSettings().trials} trials) "
          f"against at most 1 failure in 10; exact, and over {r['sequences']} simulated sequences")
    print("  true rate   passed: exact  simulated  fixed 10   trials: exact  simulated")
    for p in r["points"]:
        print(f"  {p['p']:>9.2f}   {p['accept_exact']:>13.3f}  {p['accept_simulated']:>9.3f}  "
              f"{p['accept_fixed_10']:>8.3f}   {p['trials_exact']:>13.2f}  {p['trials_simulated']:>9.2f}")
    for p in r["points"]:
        if p["p"] in BOUNDS:
            kind, bound = BOUNDS[p["p"]]
            x = p["accept_simulated"] if kind == "accept" else 1 - p["accept_simulated"]
            print(f"  {kind} at {p['p']:.2f}: {x:.3f} over the simulated sequences (goal <= {bound}): "
                  f"{'met' if x <= bound else 'NOT met'}")
    if r["runs"]:
        print(f"request -> swapped skill ({r['task']}, {r['method']}), with the simulator and the daemon "
              "running; lateness: median (max) of the daemon's per-second p99; floor: the check's trials "
              "alone in a warm pool as the learner's (no learner, no Zenoh), plus the training")
        if r.get("baseline"):
            print(f"  baseline: {r['baseline']}")
        for run in r["runs"]:
            print(_run_line(run))
        mine = [x["request_to_swap_s"] for x in r["runs"] if x["tree"] == "this" and x["swapped"]]
        if mine:
            print(f"  this code: worst {max(mine):.1f} s (goal <= {GOAL_S:g} s): "
                  f"{'met' if max(mine) <= GOAL_S else 'NOT met'}")


def add_check_bench_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--sequences", type=int, default=10_000,
                   help="simulated sequences of trials per success rate (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="of the simulated sequences (default %(default)s)")
    p.add_argument("--end-to-end", action=argparse.BooleanOptionalAction, default=True,
                   help="also time a request to the swapped skill (default on)")
    p.add_argument("--baseline", metavar="DIR|COMMIT",
                   help="another sctd source tree whose learner runs beside this one's (as sctd bench cost)")
    p.add_argument("--task", default=defaults().task, help="(default %(default)s)")
    p.add_argument("--skill", default=defaults().skill, help="the daemon's skill before the swap "
                                                             "(default %(default)s)")
    p.add_argument("--method", choices=["vf", "linear"], default="vf", help="(default %(default)s)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="a hyperparameter of the request, as sctd train --param takes it (default: the "
                        "shipped skill's recipe, skills/README.md)")
    p.add_argument("--rounds", type=int, default=1, help="end-to-end runs per tree (default %(default)s)")
    p.add_argument("--quiet", type=float, default=5.0,
                   help="s of the daemon's lateness before the request (default %(default)s)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def main_check_bench(args: argparse.Namespace) -> int:
    if args.sequences < 1 or args.rounds < 1 or args.quiet < 1:
        from ..app.errors import fail

        return fail("bench check", "--sequences and --rounds must be >= 1, --quiet >= 1")
    return run_and_report("check", args, lambda logdir: run_check_bench(args, logdir), print_report)
