"""``sctd study plan|run|report``: a user study of shared control (``docs/study.md``).

- ``plan``: participants x conditions x tasks, counterbalanced by a balanced Latin
  square, with practice and measured trials and their seeds, written as a YAML file an
  ethics application can attach (:mod:`sctd_services.study.plan`);
- ``run --participant ID``: the runner for people (:mod:`.study_run`): a browser page
  leads the participant through the plan, an experimenter's page watches, pauses and
  stops; ``run --simulated N``: fill a study folder with N simulated participants
  (lockstep trials, synthetic questionnaire answers) to try the analysis;
- ``report``: per condition and task the results table, paired Wilcoxon tests with
  Holm's correction, box plots (:mod:`sctd_services.study.report`).

Exit 0 when done, 2 for bad flags, an unknown skill or task, a participant not in the
plan, a folder that is not a study's or that another runner holds.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from sctd.task import Task, TaskError, find_task
from sctd_services.study.errors import StudyError
from sctd_services.study.plan import Plan, plan_from_yaml

from ..app.errors import EXIT_OK, EXIT_USAGE, fail
from .tryout import add_page_arguments


def add_study_arguments(p: argparse.ArgumentParser) -> None:
    sub = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    plan = sub.add_parser("plan", help="write a study's plan: participants x conditions x tasks, "
                                       "counterbalanced (balanced Latin square), with seeds",
                          description="write a study's plan (docs/study.md)")
    plan.add_argument("--participants", type=int, required=True, metavar="N", help="number of participants")
    plan.add_argument("--condition", action="append", required=True, metavar="SKILL|SET|teleop",
                      help="a condition (repeatable): a skill as --skill takes it (sctd skills), a skill set "
                           "(set:NAME or its name), or teleop, the competent teleoperation baseline")
    plan.add_argument("--task", action="append", required=True, metavar="NAME|FILE",
                      help="a task (repeatable; sctd tasks lists them)")
    plan.add_argument("--practice", type=int, default=1, metavar="K",
                      help="practice trials per block, not analysed (default %(default)s)")
    plan.add_argument("--trials", type=int, default=3, metavar="M",
                      help="measured trials per block (default %(default)s)")
    plan.add_argument("--seed", type=int, default=0, help="first trial seed (default %(default)s)")
    plan.add_argument("--title", default="sctd user study", help="the study's title (default %(default)s)")
    plan.add_argument("--out", metavar="FILE", help="write the plan here (default: print it)")
    run = sub.add_parser("run", help="run a study's plan with a participant (a browser page on 127.0.0.1), "
                                     "or fill the folder with simulated participants (--simulated N)",
                         description="run a study's plan: --participant ID leads that participant through "
                                     "it on a browser page (docs/study.md, 'Running a study with people'); "
                                     "--simulated N fills the folder with simulated participants")
    who = run.add_mutually_exclusive_group(required=True)
    who.add_argument("--participant", metavar="ID",
                     help="the participant's pseudonym in the plan (P03): serve the study page for them, "
                          "from where their folder stands")
    who.add_argument("--simulated", type=int, metavar="N",
                     help="simulate the plan's first N participants (lockstep trials, synthetic answers)")
    run.add_argument("--plan", required=True, metavar="FILE", help="the plan (sctd study plan)")
    run.add_argument("--out", required=True, metavar="DIR", help="the study folder (made, or resumed)")
    run.add_argument("--port", type=int, default=0,
                     help="with --participant: the pages' port on 127.0.0.1 (default 0: a free one; the URLs "
                          "go to stderr)")
    run.add_argument("--no-view", action="store_true",
                     help="with --participant: no live 3D view on the page (the arm seen otherwise)")
    add_page_arguments(run)
    report = sub.add_parser("report", help="results table, paired tests and figures of a study folder",
                            description="the report of a study folder (docs/study.md)")
    report.add_argument("dir", metavar="DIR", help="the study folder")
    report.add_argument("--plan", metavar="FILE", help="the plan (default: DIR/plan.yaml)")
    report.add_argument("--out", metavar="DIR", help="write report.md, report.json and the figures here")
    report.add_argument("--pairs", choices=("baseline", "all"), default="baseline",
                        help="compare each condition with teleop, or every pair (default %(default)s; all "
                             "when the plan has no teleop)")
    report.add_argument("--alpha", type=float, default=0.05,
                        help="family-wise error rate (default %(default)s)")
    report.add_argument("--json", action="store_true", help="print one JSON object on stdout, nothing else")


def main_study(args: argparse.Namespace) -> int:
    actions = {"plan": main_plan, "run": main_run, "report": main_report}
    try:
        return actions[args.action](args)
    except StudyError as e:
        return fail(f"study {args.action}", str(e))


def _read_plan(path: str) -> Plan:
    p = Path(path)
    if not p.is_file():
        raise StudyError(f"{path}: no such plan file")
    return plan_from_yaml(p.read_text(encoding="utf-8"), path)


def _tasks(names: list[str] | tuple[str, ...], where: str) -> dict[str, Task]:
    """The tasks ``names`` name (``sctd tasks``); a StudyError naming ``where``."""
    out = {}
    for name in names:
        try:
            out[name] = find_task(name)
        except TaskError as e:
            raise StudyError(f"{where}: {e}") from None
    return out


def main_plan(args: argparse.Namespace) -> int:
    from sctd_services.study.conditions import check_fits, resolve_condition
    from sctd_services.study.plan import make_plan, plan_to_yaml
    from sctd_services.study.store import write_atomic

    dup = next((c for i, c in enumerate(args.condition) if c in args.condition[:i]), None)
    if dup is not None:
        raise StudyError(f"--condition: {dup} is given twice (each condition once)")
    conditions = [resolve_condition(c) for c in args.condition]
    check_fits(conditions, list(_tasks(args.task, "--task").items()))
    plan = make_plan(conditions, args.task, args.participants, args.practice, args.trials, args.seed,
                     args.title)
    text = plan_to_yaml(plan)
    for w in plan.warnings:
        print(f"sctd study plan: warning: {w}", file=sys.stderr)
    if args.out is None:
        sys.stdout.write(text)
        return EXIT_OK
    write_atomic(Path(args.out), text)
    print(f"sctd study plan: wrote {args.out}: {len(plan.participants)} participants, {len(plan.conditions)} "
          f"conditions, {len(plan.tasks)} task(s), {len(plan.sequences)} sequences", file=sys.stderr)
    return EXIT_OK


def main_run(args: argparse.Namespace) -> int:
    if not 0 <= args.port <= 65535:
        return fail("study run", f"--port: not a TCP port: {args.port}", EXIT_USAGE)
    plan = _read_plan(args.plan)
    if args.participant is not None:
        from .study_run import check_participant, main_run_people

        check_participant(plan, args.participant)
        return main_run_people(args, plan, _tasks(plan.tasks, f"{args.plan}: tasks"))
    from sctd_services.study.simulate import simulate_study
    from sctd_services.study.store import StudyStore

    if not 1 <= args.simulated <= len(plan.participants):
        raise StudyError(f"--simulated: {args.simulated}: the plan has {len(plan.participants)} participants")
    tasks = _tasks(plan.tasks, f"{args.plan}: tasks")
    store = StudyStore.create(args.out, plan)

    def progress(pid: str, done: int, total: int) -> None:
        print(f"\rsctd study run: {pid} trial {done}/{total}", end="", file=sys.stderr, flush=True)

    ids = simulate_study(store, args.simulated, tasks, progress)
    print(f"\nsctd study run: {', '.join(ids)} simulated in {args.out} (synthetic answers)", file=sys.stderr)
    return EXIT_OK


def main_report(args: argparse.Namespace) -> int:
    from sctd_services.study.report import build_report, collect, markdown
    from sctd_services.study.store import StudyStore, write_atomic

    plan = _read_plan(args.plan) if args.plan else None
    store = StudyStore.open(args.dir, plan)
    report = build_report(collect(store), args.pairs, args.alpha)
    text = markdown(report)
    for problem in report["problems"]:
        print(f"sctd study report: warning: {problem}", file=sys.stderr)
    if args.out:
        from sctd_services.study.figures import write_figures

        out = Path(args.out)
        write_atomic(out / "report.md", text)
        write_atomic(out / "report.json", json.dumps(report, indent=1))
        figures = write_figures(report, out)
        print(f"sctd study report: wrote report.md, report.json and {len(figures)} figures in {out}",
              file=sys.stderr)
    if args.json:
        print(json.dumps(report))
    elif not args.out:
        print(text)
    return EXIT_OK
