"""Outcomes against the CPU's BLAS kernels: ``sctd bench kernels``.

OpenBLAS picks its kernels by the CPU (SkylakeX where there is AVX-512, Haswell where
there is AVX2, ...), and they round small matrix products differently in the last bits.
A lockstep trial is deterministic on one machine; whether it succeeds on another
depends on whether it sits on a knife's edge, where such a difference grows into
another outcome. This bench runs the same ``sctd suite`` trials twice in child
processes, once with the kernels this CPU picks and once with ``OPENBLAS_CORETYPE``
forcing others (default Haswell, an AVX2 machine's), and compares them trial for trial:
the outcomes that differ (each trial's seed, skill and both outcomes) and how far the
completion times moved. Exit 0 when every outcome is the same, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from typing import Any

from sctd.app.errors import EXIT_FAILED, EXIT_OK, fail
from sctd.task.starts import STARTS

SUITE_TIMEOUT = 4 * 3600.0  # s: a whole suite of many trials on a slow machine


def add_bench_kernels_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--task", action="append", default=[], metavar="NAME|FILE",
                   help="a task to run (repeatable; default every task sctd tasks lists)")
    p.add_argument("--trials", type=int, default=5, help="lockstep trials per skill (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="first trial seed (default %(default)s)")
    p.add_argument("--starts", default="own", choices=STARTS, help="where the hands start (sctd suite's "
                   "--starts; default %(default)s)")
    p.add_argument("--coretype", default="Haswell", metavar="NAME",
                   help="the OpenBLAS kernels of the second run (OPENBLAS_CORETYPE; default %(default)s)")
    p.add_argument("--jobs", type=int, default=None,
                   help="trials run in parallel in each run (default: CPUs)")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout, nothing else")


def _suite(args: argparse.Namespace, coretype: str | None) -> dict[str, Any]:
    """``sctd suite --json`` in a child process with ``OPENBLAS_CORETYPE`` set to
    ``coretype`` (None: unset, the CPU's own choice)."""
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    if coretype is not None:
        env["OPENBLAS_CORETYPE"] = coretype
    argv = [sys.executable, "-m", "sctd.cli.main", "suite", "--json", "--trials", str(args.trials),
            "--seed", str(args.seed), "--starts", args.starts, *(f"--task={t}" for t in args.task)]
    if args.jobs:
        argv += ["--jobs", str(args.jobs)]
    run = subprocess.run(argv, env=env, capture_output=True, text=True, timeout=SUITE_TIMEOUT)
    if run.returncode != 0:
        raise RuntimeError(f"sctd suite (OPENBLAS_CORETYPE={coretype or 'unset'}) exited {run.returncode}: "
                           f"{run.stderr.strip()[-800:]}")
    return json.loads(run.stdout)


def compare(own: dict[str, Any], forced: dict[str, Any]) -> list[dict[str, Any]]:
    """Per task and skill of two suites of the same trials: ``trials``, ``flips`` (each
    trial whose outcome differs: seed, both outcomes) and ``max_time_change_s`` (the
    largest change of a completion time among trials both finished)."""
    out = []
    for task, results in own["results"].items():
        theirs = {r["skill"]: r for r in forced["results"].get(task, [])}
        for r in results:
            other = theirs.get(r["skill"])
            if other is None:
                raise ValueError(f"task {task}: skill {r['skill']} ran with one set of kernels only")
            flips, moved = [], 0.0
            for a, b in zip(r["per_trial"], other["per_trial"], strict=True):
                if a["outcome"] != b["outcome"]:
                    flips.append({"seed": a["seed"], "own": a["outcome"], "forced": b["outcome"]})
                elif a["time_s"] is not None and b["time_s"] is not None:
                    moved = max(moved, abs(a["time_s"] - b["time_s"]))
            out.append({"task": task, "skill": r["name"], "baseline_of": r.get("baseline_of"),
                        "trials": len(r["per_trial"]), "flips": flips, "max_time_change_s": round(moved, 3)})
    return out


def main_bench_kernels(args: argparse.Namespace) -> int:
    if args.trials < 1:
        return fail("bench kernels", "--trials: must be >= 1")
    try:
        own = _suite(args, None)
        forced = _suite(args, args.coretype)
        rows = compare(own, forced)
    except (RuntimeError, ValueError, subprocess.TimeoutExpired) as e:
        return fail("bench kernels", str(e))
    flips = sum(len(r["flips"]) for r in rows)
    doc = {"coretype": args.coretype, "trials": args.trials, "seed": args.seed, "starts": args.starts,
           "numerics": {"own": own.get("numerics"), "forced": forced.get("numerics")},
           "rows": rows, "flips": flips}
    if args.json:
        print(json.dumps(doc))
    else:
        _report(doc)
    return EXIT_OK if flips == 0 else EXIT_FAILED


def _report(doc: dict[str, Any]) -> None:
    n = doc["numerics"]
    print(f"sctd bench kernels: {doc['trials']} lockstep trials per skill from seed {doc['seed']} "
          f"(starts {doc['starts']}), twice")
    for label in ("own", "forced"):
        blas = ", ".join((n.get(label) or {}).get("blas") or ["BLAS unknown"])
        print(f"  {label:<6} kernels: {blas}")
    print(f"  {'task':<16} {'skill':<28} {'trials':>6} {'flips':>5} {'max dt [s]':>10}  outcomes that differ")
    for r in doc["rows"]:
        name = r["skill"] if not r["baseline_of"] else f"baseline ({r['skill']})"
        diff = ", ".join(f"seed {f['seed']}: {f['own']} / {f['forced']}" for f in r["flips"])
        print(f"  {r['task']:<16} {name[:28]:<28} {r['trials']:>6} {len(r['flips']):>5} "
              f"{r['max_time_change_s']:>10.3f}  {diff}")
    total = sum(r["trials"] for r in doc["rows"])
    print(f"  {doc['flips']} of {total} outcomes differ between the two sets of kernels")
