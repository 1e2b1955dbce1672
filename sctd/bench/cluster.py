"""The cost of running lockstep trials on a Dask cluster: ``sctd bench cluster``.

The same ``--trials`` short lockstep trials (``--time-limit`` simulated seconds each)
run through :func:`sctd_services.eval.evaluate.evaluate` twice per round: on a pool of
``--workers`` local spawned processes (what ``sctd eval --lockstep --jobs N`` uses) and
on a loopback Dask cluster with as many single-threaded workers
(:func:`sctd_services.eval.cluster.local_cluster`, what ``--scheduler`` reaches). Both
are warmed first (workers started, the simulator imported), so what differs is what a
trial costs on the way: the skill bundle and task file shipped with it, the scheduler's
round trips, the result sent back. Rounds alternate the two and the median round is
reported; the figure is the difference per trial. Both must give the same results (the
trials are deterministic per seed), which the report says.
"""

from __future__ import annotations

import argparse
import json
import statistics
import tempfile
import time
from concurrent.futures import Executor, ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path
from typing import Any

from sctd.app.defaults import defaults
from sctd.app.errors import fail
from sctd.app.options import SKILL_HELP
from sctd.skill.catalog import find_skill
from sctd_services.eval.cluster import ClusterError, connect, local_cluster
from sctd_services.eval.evaluate import entries, evaluate, task_of
from sctd_services.eval.trial import TaskSpec


def _timed(ents: list, spec: TaskSpec, trials: int, seed: int, pool: Executor) -> tuple[float, list]:
    t0 = time.perf_counter()
    [res] = evaluate(ents, spec, trials, seed, pool=pool)
    return time.perf_counter() - t0, res["per_trial"]


def measure(skill: str | None = None, trials: int = 8, workers: int = 2, time_limit: float = 1.0,
            rounds: int = 3, seed: int = 0) -> dict[str, Any]:
    """Wall time of ``trials`` lockstep trials of ``skill`` on local processes and on a
    loopback Dask cluster, ``workers`` of each, over ``rounds`` alternating rounds
    (``skill`` default: the learned skill of ``sctd/app/defaults.yaml``).

    Returns
    -------
    dict
        ``local_s`` and ``cluster_s`` (the median round's wall time, s),
        ``local_ms_per_trial``, ``cluster_ms_per_trial``, ``overhead_ms_per_trial``
        (their difference), ``same_results`` (every round of both gave the same trials).
    """
    with tempfile.TemporaryDirectory(prefix="sctd-bench-cluster-") as work:
        path = str(find_skill(skill or defaults().learned_skill))
        ents = entries([path], False, Path(work))
        spec = TaskSpec.of(task_of([ents[0].skill], None), time_limit=time_limit)
        local_s: list[float] = []
        cluster_s: list[float] = []
        seen: list[list] = []
        with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as local, \
                local_cluster(workers) as address, connect(address) as remote:
            for pool in (local, remote):  # warm: every worker started and has run a trial
                evaluate(ents, spec, workers, seed, pool=pool)
            for _ in range(rounds):
                for pool, times in ((local, local_s), (remote, cluster_s)):
                    wall, per_trial = _timed(ents, spec, trials, seed, pool)
                    times.append(wall)
                    seen.append(per_trial)
    lo, cl = statistics.median(local_s), statistics.median(cluster_s)
    return {"skill": path, "task": spec.task, "trials": trials, "workers": workers,
            "time_limit_s": time_limit, "rounds": rounds, "local_s": round(lo, 3), "cluster_s": round(cl, 3),
            "local_ms_per_trial": round(1e3 * lo / trials, 1),
            "cluster_ms_per_trial": round(1e3 * cl / trials, 1),
            "overhead_ms_per_trial": round(1e3 * (cl - lo) / trials, 1),
            "same_results": all(s == seen[0] for s in seen)}


def format_report(r: dict[str, Any]) -> str:
    return (f"{r['trials']} lockstep trials of {r['skill']} on {r['task']} ({r['time_limit_s']:g} s "
            f"simulated each), {r['workers']} workers, median of {r['rounds']} rounds:\n"
            f"  local processes     {r['local_s']:7.2f} s   {r['local_ms_per_trial']:8.1f} ms per trial\n"
            f"  loopback Dask       {r['cluster_s']:7.2f} s   {r['cluster_ms_per_trial']:8.1f} ms per trial\n"
            f"  cluster overhead    {r['overhead_ms_per_trial']:+8.1f} ms per trial\n"
            f"  same results: {'yes' if r['same_results'] else 'NO'}")


def add_bench_cluster_arguments(p: argparse.ArgumentParser) -> None:
    d = measure.__defaults__ or ()
    skill, trials, workers, time_limit, rounds, _ = d
    p.add_argument("--skill", default=skill or defaults().learned_skill,
                   help=SKILL_HELP + " (default %(default)s)")
    p.add_argument("--trials", type=int, default=trials, help="trials per round (default %(default)s)")
    p.add_argument("--workers", type=int, default=workers,
                   help="local processes, and the cluster's workers (default %(default)s)")
    p.add_argument("--time-limit", type=float, default=time_limit,
                   help="simulated s per trial: short, so the overhead shows (default %(default)s)")
    p.add_argument("--rounds", type=int, default=rounds, help="alternating rounds (default %(default)s)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def main_bench_cluster(args: argparse.Namespace) -> int:
    if min(args.trials, args.workers, args.rounds) < 1 or not args.time_limit > 0:
        return fail("bench cluster", "--trials, --workers, --rounds must be >= 1, --time-limit > 0")
    try:
        r = measure(args.skill, args.trials, args.workers, args.time_limit, args.rounds)
    except (ClusterError, ValueError) as e:
        return fail("bench cluster", str(e))
    print(json.dumps(r) if args.json else format_report(r))
    return 0 if r["same_results"] else 1
