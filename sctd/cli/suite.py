"""``sctd suite``: every task x its shipped skills x the competent baseline, one table.

Lockstep trials (simulated time, :mod:`sctd_services.eval.suite`), the same seeds for
every skill of a task. Prints the table; with ``--out DIR`` also writes ``suite.json``
(every figure and trial), ``suite.md`` (the table for the docs) and ``suite.png``
(success, completion times against each task's floor, mode switches and effort). Exit
0 when it ran, 2 for bad flags or a task that does not load.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

from sctd.task import TaskError, find_task, known_tasks
from sctd_services.eval.numerics import numerics
from sctd_services.eval.suite import figure, markdown, rows, run_suite, table
from sctd_services.eval.trial import TaskSpec
from sctd_services.user import DEFAULT_MODEL, USER_MODELS

from ..app.errors import EXIT_OK, fail
from ..app.options import add_arguments
from .eval import _progress_bar


def add_suite_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--task", action="append", default=[], metavar="NAME|FILE",
                   help="a task to run (repeatable; default every task sctd tasks lists)")
    p.add_argument("--trials", type=int, default=20, help="lockstep trials per skill (default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="first trial seed (default %(default)s)")
    p.add_argument("--user-model", action="append", default=[], choices=sorted(USER_MODELS), metavar="NAME",
                   help="how the simulated user learns the device (repeatable: the same trials with each, "
                        f"side by side; {', '.join(f'{k}: {m.about}' for k, m in USER_MODELS.items())}; "
                        f"default {DEFAULT_MODEL})")
    add_arguments(p, TaskSpec, only=("starts",))
    p.add_argument("--jobs", type=int, default=None, help="trials run in parallel (default: CPUs)")
    p.add_argument("--out", metavar="DIR", help="write suite.json, suite.md and suite.png here")
    p.add_argument("--json", action="store_true", help="print one JSON object on stdout, nothing else")


def main_suite(args: argparse.Namespace) -> int:
    if args.trials < 1:
        return fail("suite", "--trials: must be >= 1")
    try:
        refs = args.task or [k.name for k in known_tasks()]
        tasks = [(ref, find_task(ref)) for ref in refs]
    except TaskError as e:
        return fail("suite", f"--task: {e}")
    jobs = args.jobs or os.cpu_count() or 1
    models = list(dict.fromkeys(args.user_model)) or [DEFAULT_MODEL]
    with tempfile.TemporaryDirectory(prefix="sctd-suite-") as work:
        runs = run_suite(tasks, args.trials, args.seed, jobs, Path(work), progress=_progress_bar(),
                         user_models=models, starts=args.starts)
    print(file=sys.stderr)
    table_rows = rows(runs)
    doc = {"trials": args.trials, "seed": args.seed, "tasks": [t.name for _, t in tasks], "rows": table_rows,
           "user_models": models, "starts": args.starts, "numerics": numerics(),
           "results": {run.task.name: run.results for run in runs if run.user_model == models[0]},
           "results_by_user_model": {m: {run.task.name: run.results for run in runs if run.user_model == m}
                                     for m in models}}
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        (out / "suite.json").write_text(json.dumps(doc))
        (out / "suite.md").write_text(markdown(table_rows, paired=args.starts != "own"))
        figure(table_rows).savefig(out / "suite.png", dpi=100)
        print(f"sctd suite: wrote suite.json, suite.md and suite.png in {out}", file=sys.stderr)
    if args.json:
        print(json.dumps(doc))
        return EXIT_OK
    print(f"sctd suite: {len(tasks)} tasks, {args.trials} lockstep trials per skill from seed {args.seed}, "
          f"user model{'s' if len(models) > 1 else ''} {', '.join(models)}, starts {args.starts}; "
          "the baseline is mode-switching teleop with the task's control frame")
    for line in table(table_rows, paired=args.starts != "own"):
        print("  " + line)
    return EXIT_OK
