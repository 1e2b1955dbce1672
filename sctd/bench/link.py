"""``sctd bench link``: what faults of the hosts' links do to a person's task.

Real-time trials of a task's skill and of the unassisted baseline (teleoperation, the
same simulated user and limits) through the namespaced cluster
(:class:`~sctd.deploy.cluster.Cluster`), with the fault proxy on two links: the input
host's (what the person's device sends: ``up``) and the robot host's (the arm's state
to the runtime and its targets back: both directions). The points of the sweep
(:data:`POINTS`): the clean links; a delay of 5, 20 and 50 ms with 20 % jitter on each
link; a stall of 0.2 s and of 2 s on each link, begun ``STALL_AT`` s after the user
started; and, on a plain cluster whose input host's link runs over UDP (Zenoh's
unreliable unicast link; the secured cluster's TLS runs over TCP, which loses nothing),
that link clean (``input-udp``, the losses' reference) and losing 1 % and 5 % of the
datagrams the input host sends, from the user's first push on. Every
trial of a point and condition starts from the same seeds, so the points differ only in
the link.

Per trial (judged on the observer host by :mod:`sctd.bench.linktrial`, as ``sctd eval``
judges one): the outcome, the task's clock, its readings (the spill), the hand's worst
unintended motion (:class:`~sctd.bench.linktrial.Wander`), the daemon's
``stale_disarms`` and how often the simulated user centred the stick because the
status told it to. The table: per task, point and condition, the success rate, the
largest spill, the median completion time of the successful trials, the worst
unintended motion, and where assistance stops helping (:func:`stops_helping`).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sctd.app.defaults import defaults
from sctd.bench import run_and_report
from sctd.deploy.cluster import Cluster, FaultedLink
from sctd.deploy.linkfault import LinkFault
from sctd.deploy.netns import Process, last_json
from sctd.task import Task, find_task

DELAYS_MS = (5.0, 20.0, 50.0)
JITTER = 0.2  # of the delay
STALLS_S = (0.2, 2.0)
LOSSES = (0.01, 0.05)  # of the datagrams the input host sends
STALL_AT = 5.0  # s after the user's program started (the user acts after about 1-2 s)
LINKS = ("input", "robot")
BASELINE = "teleop"  # the unassisted baseline's condition: sctd eval's competent baseline
TRIAL_SLACK = 60.0  # s beyond the task's time limit before a trial's judge is given up


@dataclass(frozen=True)
class Point:
    """One point of the sweep: a fault on ``link`` (``""``: none), a delay (``fault``)
    or a stall of ``stall`` s begun ``STALL_AT`` s into the trial."""

    name: str
    link: str = ""
    fault: LinkFault = field(default_factory=LinkFault)
    stall: float = 0.0
    udp: bool = False  # the input host's link over UDP (a plain cluster: module doc)

    @property
    def kind(self) -> str:
        """What is swept: ``clean``, ``input-udp``, or ``<link>-delay`` / ``-stall`` / ``-loss``."""
        if not self.link:
            return "input-udp" if self.udp else "clean"
        return f"{self.link}-{'loss' if self.udp else 'stall' if self.stall else 'delay'}"


def sweep() -> tuple[Point, ...]:
    """Every point of the sweep, in the order of the table (module doc)."""
    out = [Point("clean")]
    for link in LINKS:
        out += [Point(f"{link}-delay-{ms:g}", link, LinkFault(delay_ms=ms, jitter=JITTER, seed=1))
                for ms in DELAYS_MS]
        out += [Point(f"{link}-stall-{s:g}", link, stall=s) for s in STALLS_S]
    out.append(Point("input-udp", udp=True))  # the reference of the losses: the same link, none lost
    out += [Point(f"input-loss-{100 * x:g}", "input", LinkFault(loss=x, seed=1), udp=True) for x in LOSSES]
    return tuple(out)


POINTS = sweep()
CLEAN = POINTS[0]


def select_points(names: str | None) -> tuple[Point, ...]:
    """The points named in ``names`` (comma-separated, in the sweep's order; None: all);
    ValueError naming an unknown one and the names there are."""
    if names is None:
        return POINTS
    wanted = [n.strip() for n in names.split(",") if n.strip()]
    known = {p.name for p in POINTS}
    bad = [n for n in wanted if n not in known]
    if bad or not wanted:
        raise ValueError(f"--points: unknown {', '.join(bad) or '(none given)'}; the points are "
                         f"{', '.join(p.name for p in POINTS)}")
    return tuple(p for p in POINTS if p.name in wanted)


def spill_of(readings: dict[str, Any]) -> float | None:
    """The contents a trial spilled: the largest of the task's ``*.spilled`` readings
    (None for a task without contents)."""
    got = [float(v) for k, v in readings.items() if k.endswith(".spilled") and not isinstance(v, bool)]
    return max(got) if got else None


def summarise(trials: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (task, point, condition), in the order the trials came: trials,
    successes, the success rate, the largest spill, the median time of the successful
    trials, the worst unintended motion, and the sums of the daemon's stale-disarms and
    of the user's centrings."""
    groups: dict[tuple[str, str, str], list[dict[str, Any]]] = {}
    for t in trials:
        groups.setdefault((t["task"], t["point"], t["condition"]), []).append(t)
    rows = []
    for (task, point, condition), ts in groups.items():
        times = [t["time_s"] for t in ts if t["outcome"] == "success" and t["time_s"] is not None]
        spills = [s for t in ts if (s := spill_of(t.get("readings", {}))) is not None]
        rtfs = [t["sim_rtf"] for t in ts if t.get("sim_rtf") is not None]
        rows.append({"task": task, "point": point, "condition": condition, "trials": len(ts),
                     "successes": sum(t["outcome"] == "success" for t in ts),
                     "success": sum(t["outcome"] == "success" for t in ts) / len(ts),
                     "spill": max(spills) if spills else None,
                     "time_s": round(statistics.median(times), 2) if times else None,
                     "wander_mm": round(1e3 * max(t["wander_m"] for t in ts), 1),
                     "stale_disarms": sum(t.get("stale_disarms", 0) for t in ts),
                     "centred": sum(t.get("centred", 0) for t in ts),
                     "sim_rtf": min(rtfs) if rtfs else None})
    return rows


def helps(assisted: dict[str, Any], baseline: dict[str, Any]) -> bool:
    """Whether assistance helps at a point: it succeeds more often than the baseline,
    or as often and (when both succeeded) faster."""
    if assisted["success"] != baseline["success"]:
        return assisted["success"] > baseline["success"]
    if assisted["time_s"] is None or baseline["time_s"] is None:
        return assisted["success"] > 0 and baseline["time_s"] is None
    return assisted["time_s"] < baseline["time_s"]


def stops_helping(rows: list[dict[str, Any]]) -> dict[str, dict[str, str | None]]:
    """Per task and kind of fault (``input-delay``, ``robot-stall``, ...; ``clean`` and
    ``input-udp`` are kinds of one point each): the first point, in the sweep's order
    (the mildest first), where assistance does not help against the baseline at the
    same point (:func:`helps`), or None where it helps at every point measured. Points
    without both conditions are left out."""
    by = {(r["task"], r["point"], r["condition"]): r for r in rows}
    out: dict[str, dict[str, str | None]] = {}
    for p in POINTS:
        for task in dict.fromkeys(r["task"] for r in rows):
            a, b = by.get((task, p.name, "assisted")), by.get((task, p.name, BASELINE))
            if a is None or b is None:
                continue
            kinds = out.setdefault(task, {})
            kinds.setdefault(p.kind, None)
            if kinds[p.kind] is None and not helps(a, b):
                kinds[p.kind] = p.name
    return out


def format_table(rows: list[dict[str, Any]]) -> list[str]:
    """The sweep as text lines, one per row of :func:`summarise`."""
    head = (f"{'task':8s} {'point':16s} {'condition':9s} {'success':>9s} {'spill':>7s} {'time s':>7s} "
            f"{'wander mm':>9s} {'disarms':>7s} {'centred':>7s} {'rtf':>5s}")
    lines = [head]
    for r in rows:
        spill = "-" if r["spill"] is None else f"{r['spill']:.3f}"
        tm = "-" if r["time_s"] is None else f"{r['time_s']:.1f}"
        rtf = "-" if r["sim_rtf"] is None else f"{r['sim_rtf']:.2f}"
        lines.append(f"{r['task']:8s} {r['point']:16s} {r['condition']:9s} "
                     f"{r['successes']:>4d}/{r['trials']:<4d} {spill:>7s} {tm:>7s} {r['wander_mm']:>9.1f} "
                     f"{r['stale_disarms']:>7d} {r['centred']:>7d} {rtf:>5s}")
    return lines


# -- the record: a sweep of hours, taken up where it stopped ---------------------------------

RECORD_KEYS = ("task", "point", "condition", "skill", "seed", "outcome")


def trial_key(t: dict[str, Any]) -> tuple[str, str, str, int]:
    """What names a trial in a sweep: its task, point, condition and seed."""
    return (t["task"], t["point"], t["condition"], int(t["seed"]))


class Record:
    """The trials of a sweep as JSON lines in a file (``--record``), one appended and
    flushed to the disk as each trial ends, so that a sweep stopped after any trial
    (killed, the machine needed) is taken up again where it stopped: the trials already
    in the file are not run again and count in the table as if just run.

    A line that is not a trial, or a trial of the same task, point, condition and seed
    recorded with another skill than this run's, is refused (:class:`ValueError` naming
    the file, the line and what is wrong) before anything starts."""

    def __init__(self, path: Path | None):
        self.path = path
        self.trials: dict[tuple[str, str, str, int], dict[str, Any]] = {}
        if path is not None and path.exists():
            for n, line in enumerate(path.read_text().splitlines(), 1):
                if line.strip():
                    t = self._read(line, f"{path}: line {n}")
                    self.trials[trial_key(t)] = t

    @staticmethod
    def _read(line: str, where: str) -> dict[str, Any]:
        import json

        try:
            t = json.loads(line)
        except ValueError as e:
            raise ValueError(f"{where}: not JSON ({e})") from None
        if not isinstance(t, dict) or any(k not in t for k in RECORD_KEYS):
            raise ValueError(f"{where}: not a trial of sctd bench link (a map with {', '.join(RECORD_KEYS)})")
        if not isinstance(t["seed"], int) or isinstance(t["seed"], bool):
            raise ValueError(f"{where}: seed must be an integer, got {t['seed']!r}")
        return t

    def check(self, task: str, conditions: list[tuple[str, str]]) -> None:
        """Refuse a file whose trials of ``task`` ran another skill in a condition."""
        names = {c: Path(sk).stem for c, sk in conditions}
        for (tk, _, cond, _), t in self.trials.items():
            if tk == task and cond in names and t["skill"] != names[cond]:
                raise ValueError(f"{self.path}: {task} {cond} was recorded with the skill {t['skill']!r}, "
                                 f"this run's is {names[cond]!r}: give another --record file")

    def get(self, key: tuple[str, str, str, int]) -> dict[str, Any] | None:
        return self.trials.get(key)

    def add(self, trial: dict[str, Any]) -> None:
        import json
        import os

        self.trials[trial_key(trial)] = trial
        if self.path is None:
            return
        with self.path.open("a") as f:
            f.write(json.dumps(trial) + "\n")
            f.flush()
            os.fsync(f.fileno())


def pending(task: str, points: tuple[Point, ...], conditions: list[tuple[str, str]], trials: int, seed: int,
            record: Record) -> list[tuple[Point, str, str, int]]:
    """The (point, condition, skill file, seed) trials of ``task`` that ``record`` does not
    have yet, in the sweep's order."""
    return [(p, cond, sk, seed + k) for p in points for cond, sk in conditions for k in range(trials)
            if record.get((task, p.name, cond, seed + k)) is None]


# -- the trials, through the cluster -------------------------------------------------------

def _set_point(links: dict[str, FaultedLink], point: Point) -> None:
    """The point's delay on its link (the input's ``up``, the robot's both ways), the
    other link clean."""
    clean = LinkFault()
    for name, link in links.items():
        fault = point.fault if name == point.link else clean
        link.set("up", fault)
        link.set("down", fault if name == "robot" else clean)


def _wait_line(p: Process, text: str, seconds: float) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end and p.running():
        if text in p.output():
            return True
        time.sleep(0.05)
    return text in p.output()


def _while_judged(judge: Process, links: dict[str, FaultedLink], point: Point, end: float) -> None:
    """Wait for the judge (until ``end``), starting the point's stall ``STALL_AT`` s after
    the user's program started and its datagram loss when the judge says the user first
    pushed (a Zenoh session opened over a lossy UDP link may never get some of its
    declarations through: docs/multihost.md)."""
    started = time.monotonic()
    stall, loss = point.stall > 0, point.udp and point.link != ""
    while judge.running() and time.monotonic() < end:
        if stall and time.monotonic() - started >= STALL_AT:
            links[point.link].stall(point.stall, "up" if point.link == "input" else "both")
            stall = False
        if loss and '"acting"' in judge.output():
            _set_point(links, point)
            loss = False
        time.sleep(0.05)


def run_trial(c: Cluster, links: dict[str, FaultedLink], point: Point, skill: str,
              seed: int) -> dict[str, Any]:
    """One trial of ``skill`` at ``point`` from ``seed``: the robot, the runtime, the judge
    (observer host) and the simulated user started for it and stopped after it."""
    _set_point(links, CLEAN if point.udp else point)  # a loss begins once the user's session is up
    h, task, tag = c.hosts, c.task, f"{point.name}-{Path(skill).stem}-{seed}"
    limit = task.outcome.time_limit
    procs = [c.start_robot("--trial-seed", str(seed)), c.start_runtime(skill)]
    try:
        judge = h.python("observer", "sctd.bench.linktrial", "--config", str(c.config_on("observer")),
                         "--task", task.name, "--seed", str(seed), log=f"judge-{tag}.log")
        procs.append(judge)
        if not _wait_line(judge, '"ready"', 60):
            raise RuntimeError(f"the trial's judge did not start; see {judge.log_path}")
        user = h.python("input", "sctd_services.simulated_user", "--task", task.name, "--seed", str(seed),
                        "--duration", str(limit + TRIAL_SLACK), "--json", *c.zenoh_args("input"),
                        log=f"user-{tag}.log")
        procs.append(user)
        stalls = links[point.link].counters()["stalls"] if point.stall else 0
        _while_judged(judge, links, point, time.monotonic() + limit * 3 + 90 + TRIAL_SLACK)
        result = last_json(judge.output())
        if result is None or "outcome" not in result:
            raise RuntimeError(f"the trial's judge gave no result; see {judge.log_path}")
        user.stop()
        report = last_json(user.output()) or {}
        if point.stall:
            stalls = links[point.link].counters()["stalls"] - stalls
    finally:
        for p in reversed(procs):
            p.stop()
    return {**{k: result[k] for k in ("seed", "outcome", "reason", "time_s", "readings", "sim_rtf",
                                      "wander_m")},
            "stale_disarms": int(result.get("counters", {}).get("stale_disarms", 0)),
            "centred": int(report.get("centred", 0)), "stalls": stalls}


def conditions_of(task: Task, skill: str | None, baseline: bool, workdir: Path) -> list[tuple[str, str]]:
    """(condition, skill file) pairs: ``assisted`` with ``skill`` (default: the shipped
    skill of the task's object named after the task, else the first of them), then the
    competent baseline ``sctd eval`` runs against it (teleoperation with that skill's
    limits and the task's control frame, written into ``workdir``)."""
    from sctd_services.eval.evaluate import entries
    from sctd_services.eval.suite import skills_for

    if skill is None:
        found = skills_for(task)
        if not found:
            raise RuntimeError(f"{task.name}: no shipped skill for its object {task.object}; give --skill")
        skill = next((s for s in found if Path(s).stem == task.name), found[0])
    got = entries([skill], baseline, workdir, task)
    return [("assisted", str(got[0].path))] + [(BASELINE, str(e.path)) for e in got[1:]]


def _sweep_cluster(task: Task, todo: list[tuple[Point, str, str, int]], logdir: Path, udp: bool,
                   record: Record) -> None:
    """The trials ``todo`` of ``task`` on one cluster, each added to ``record`` as it ends:
    with ``udp`` a plain cluster whose input host's link runs over UDP, else the secured
    one (mutual TLS, the roles policy)."""
    cluster = Cluster(logdir, task=task, secure=False, udp=("input",)) if udp else Cluster(logdir, task=task)
    with cluster as c:
        c.start_router()
        links = {"input": c.fault("input", "router", LinkFault()),
                 "robot": c.fault("robot", "router", LinkFault())}
        try:
            for point, condition, sk, seed in todo:
                r = run_trial(c, links, point, sk, seed)
                record.add({"task": task.name, "point": point.name, "condition": condition,
                            "skill": Path(sk).stem, **r})
                print(f"sctd bench link: {task.name} {point.name} {condition} seed {seed}: "
                      f"{r['outcome']} ({r['reason']}), {r['time_s']} s", file=sys.stderr, flush=True)
        finally:
            c.stop_router()


def run_link_bench(tasks: list[Task], skill: str | None, points: tuple[Point, ...], trials: int, seed: int,
                   logdir: Path, baseline: bool = True, record: Record | None = None) -> dict[str, Any]:
    """The sweep (module doc); progress on stderr, a line per trial. With ``record``, the
    trials it holds are not run again (:class:`Record`)."""
    record = Record(None) if record is None else record
    out: list[dict[str, Any]] = []
    began, reused = time.monotonic(), 0
    for task in tasks:
        conditions = conditions_of(task, skill, baseline, logdir / f"{task.name}-skills")
        try:
            record.check(task.name, conditions)
        except ValueError as e:
            raise RuntimeError(str(e)) from None
        for udp in (False, True):
            these = tuple(p for p in points if p.udp == udp)
            todo = pending(task.name, these, conditions, trials, seed, record)
            reused += len(these) * len(conditions) * trials - len(todo)
            if todo:
                _sweep_cluster(task, todo, logdir / f"{task.name}{'-udp' if udp else ''}", udp, record)
            out += [t for p in these for cond, _ in conditions for k in range(trials)
                    if (t := record.get((task.name, p.name, cond, seed + k))) is not None]
    rows = summarise(out)
    return {"trials": out, "rows": rows, "stops_helping": stops_helping(rows),
            "points": [p.name for p in points], "wall_s": round(time.monotonic() - began, 1),
            "stall_at_s": STALL_AT, "recorded_before": reused}


def print_report(r: dict[str, Any]) -> None:
    before = r.get("recorded_before", 0)
    print(f"sctd bench link: {len(r['trials'])} real-time trials ({len(r['trials']) - before} run now in "
          f"{r['wall_s']:.0f} s, {before} from the record) through the namespaced cluster; wander: the "
          "hand's worst unintended motion (docs/multihost.md)")
    for line in format_table(r["rows"]):
        print("  " + line)
    for task, kinds in r["stops_helping"].items():
        for kind, point in kinds.items():
            print(f"  {task}: {kind}: " + (f"assistance does not help at {point}" if point
                                           else "assistance helps at every point measured"))


def add_bench_link_arguments(p: argparse.ArgumentParser) -> None:
    bl = defaults().bench_learn
    p.add_argument("--task", action="append", default=None, metavar="NAME|FILE",
                   help=f"a task to sweep (repeatable; default {bl.tilt} and {bl.pull})")
    p.add_argument("--skill", default=None,
                   help="the assisted condition's skill (default: the shipped skill named after each task)")
    p.add_argument("--trials", type=int, default=10, help="real-time trials per point and condition "
                                                          "(default %(default)s)")
    p.add_argument("--seed", type=int, default=0, help="the first trial's seed (default %(default)s)")
    p.add_argument("--points", default=None, help="comma-separated points of the sweep (default all: "
                                                  + ", ".join(p.name for p in POINTS) + ")")
    p.add_argument("--no-baseline", action="store_true", help="only the assisted condition")
    p.add_argument("--record", metavar="FILE.jsonl",
                   help="append each trial to this file as it ends, and run none it already has: a "
                        "sweep stopped at any trial is taken up again with the same flags")
    p.add_argument("--figure", metavar="FILE.png",
                   help="draw the sweep here (.png, .svg or .pdf): success, median time and the hand's "
                        "worst unintended motion per point, assisted beside the baseline")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def check_figure_path(path: str | None) -> Path | None:
    """The ``--figure`` file, checked before anything starts (a sweep takes hours): a
    format matplotlib writes, in a folder that exists; ValueError saying which."""
    if path is None:
        return None
    from sctd.bench.linkfigure import FORMATS

    out = Path(path)
    if out.suffix.lower() not in FORMATS:
        raise ValueError(f"--figure {path}: the file must end in {', '.join(FORMATS)}")
    if not out.parent.is_dir():
        raise ValueError(f"--figure {path}: no folder {out.parent}")
    return out


def write_figure(r: dict[str, Any], out: Path) -> None:
    """The sweep's figure (:mod:`sctd.bench.linkfigure`) into ``out``."""
    from sctd.bench.linkfigure import figure

    fig = figure(r["rows"], r["points"], {p.name: p.kind for p in POINTS}, r["stops_helping"])
    fig.savefig(out, dpi=100)
    print(f"sctd bench link: wrote {out}", file=sys.stderr)


def main_bench_link(args: argparse.Namespace) -> int:
    from sctd.app.errors import EXIT_USAGE, fail

    bl = defaults().bench_learn
    try:
        points = select_points(args.points)
        tasks = [find_task(t) for t in (args.task or [bl.tilt, bl.pull])]
        record = Record(None if args.record is None else Path(args.record))
        figure = check_figure_path(args.figure)
    except ValueError as e:  # a bad --points, --record or --figure, a --task that is no task (TaskError)
        return fail("bench link", str(e), EXIT_USAGE)
    if args.trials < 1:
        return fail("bench link", "--trials: at least 1", EXIT_USAGE)

    def run(logdir: Path) -> dict[str, Any]:
        r = run_link_bench(tasks, args.skill, points, args.trials, args.seed, logdir, not args.no_baseline,
                           record)
        if figure is not None:
            write_figure(r, figure)
        return r

    return run_and_report("link", args, run, print_report)

