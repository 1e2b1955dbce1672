"""A study's report: per condition and task the figures a results table shows, and the
paired comparisons with their correction (``sctd study report``).

The unit of analysis is the participant (:mod:`.stats`): each contributes, per condition
and task, the mean of its measured trials (practice and aborted trials left out):
success rate, completion time (successful trials only; none: missing), mode switches,
effort (the integral of |u|), and the block's raw TLX and SUS score. The table gives
each metric's median and interquartile range over participants, and the pooled
successes over trials.

Comparisons are paired, within a task: each condition against ``teleop`` (``pairs=
"baseline"``, when the plan has it) or every pair (``"all"``). Holm's correction runs
over one family per metric (every comparison of that metric, in every task): a metric
answers its own question (is it faster? is it less workload?), and a reader judging
one metric should not pay for the tests of the others. :func:`build_report` does the
arithmetic on what :func:`collect` read; :func:`markdown` lays it out as a thesis'
results table. Figures are drawn elsewhere (:mod:`.figures`, matplotlib).
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

from .plan import TELEOP, Plan
from .stats import describe, holm, paired_test
from .store import StudyStore, TrialRow


@dataclass(frozen=True)
class Metric:
    key: str
    label: str
    better: str  # "higher" | "lower": which way is better
    digits: int = 1


METRICS = (
    Metric("success_rate", "success rate", "higher", 2),
    Metric("completion_time_s", "completion time [s]", "lower", 1),
    Metric("mode_switches", "mode switches", "lower", 1),
    Metric("effort", "effort (∫‖u‖dt)", "lower", 1),
    Metric("raw_tlx", "raw TLX (0-100)", "lower", 1),
    Metric("sus_score", "SUS (0-100)", "higher", 1),
)


@dataclass
class Collected:
    """What a study folder holds, read: measured rows and block scores per participant,
    the problems met (each skipped), and each participant's progress."""

    plan: Plan
    rows: dict[str, list[TrialRow]] = field(default_factory=dict)
    scores: dict[str, dict[tuple[str, str], dict[str, float]]] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    progress: dict[str, tuple[int, int, int]] = field(default_factory=dict)  # done, total, aborted


def collect(store: StudyStore) -> Collected:
    """Read every participant's folder of ``store`` (tolerating a truncated last row)."""
    out = Collected(store.plan)
    for pid in store.participants():
        t = store.trials(pid)
        out.problems += t.problems
        out.rows[pid] = [r for r in t.rows if not r.practice and not r.aborted]
        out.scores[pid] = {(b["condition"], b["task"]): {"raw_tlx": b["raw_tlx"], "sus_score": b["sus_score"]}
                           for b in store.answers(pid)["blocks"]}
        p = store.progress(pid)
        out.progress[pid] = (p.done, p.total, p.aborted)
    return out


def _mean(xs: Sequence[float | None]) -> float | None:
    v = [x for x in xs if x is not None]
    return sum(v) / len(v) if v else None


def participant_values(c: Collected, pid: str, condition: str, task: str) -> dict[str, float | None]:
    """One participant's values of every metric for a block (None: no data)."""
    rows = [r for r in c.rows.get(pid, []) if r.condition == condition and r.task == task]
    scores = c.scores.get(pid, {}).get((condition, task), {})
    return {"success_rate": _mean([1.0 if r.success else 0.0 for r in rows]),
            "completion_time_s": _mean([r.completion_time_s for r in rows if r.success]),
            "mode_switches": _mean([None if r.mode_switches is None else float(r.mode_switches)
                                    for r in rows]),
            "effort": _mean([r.effort for r in rows]),
            "raw_tlx": scores.get("raw_tlx"), "sus_score": scores.get("sus_score")}


def _pairs(plan: Plan, pairs: str) -> list[tuple[str, str]]:
    names = plan.condition_names
    if pairs == "baseline" and TELEOP in names:
        return [(n, TELEOP) for n in names if n != TELEOP]
    return list(itertools.combinations(names, 2))


def _comparisons(values: dict[str, Any], plan: Plan, pids: list[str], pairs: str,
                 alpha: float) -> list[dict[str, Any]]:
    out = []
    for m in METRICS:
        family = []
        for task in plan.tasks:
            for a, b in _pairs(plan, pairs):
                va = [values[task][a][m.key].get(p) for p in pids]
                vb = [values[task][b][m.key].get(p) for p in pids]
                family.append({"task": task, "metric": m.key, "a": a, "b": b, **paired_test(va, vb, alpha)})
        for comp, adj in zip(family, holm([f["p"] for f in family]), strict=True):
            comp["p_holm"] = adj
            comp["significant"] = adj is not None and adj <= alpha
        out += family
    return out


def build_report(c: Collected, pairs: str = "baseline", alpha: float = 0.05) -> dict[str, Any]:
    """The report's document (``--json``; ``docs/study.md``)."""
    plan, pids = c.plan, sorted(c.rows)
    values: dict[str, Any] = {}
    tables: dict[str, Any] = {}
    for task in plan.tasks:
        values[task], tables[task] = {}, {}
        for cond in plan.condition_names:
            per = {p: participant_values(c, p, cond, task) for p in pids}
            values[task][cond] = {m.key: {p: per[p][m.key] for p in pids} for m in METRICS}
            rows = [r for p in pids for r in c.rows[p] if r.condition == cond and r.task == task]
            tables[task][cond] = {"trials": len(rows), "successes": sum(bool(r.success) for r in rows),
                                  "participants": sum(any(r.condition == cond and r.task == task
                                                          for r in c.rows[p]) for p in pids),
                                  **{m.key: describe(list(values[task][cond][m.key].values()))
                                     for m in METRICS}}
    mode = "baseline" if pairs == "baseline" and TELEOP in plan.condition_names else "all"
    return {"v": 1, "title": plan.title, "conditions": plan.condition_names, "tasks": list(plan.tasks),
            "participants_planned": len(plan.participants), "participants": pids,
            "progress": {p: {"done": d, "total": t, "aborted": a} for p, (d, t, a) in c.progress.items()},
            "problems": c.problems, "plan_warnings": list(plan.warnings),
            "metrics": [{"key": m.key, "label": m.label, "better": m.better} for m in METRICS],
            "tables": tables, "per_participant": values,
            "comparisons": _comparisons(values, plan, pids, mode, alpha),
            "statistics": {"pairs": mode, "alpha": alpha, "test": "Wilcoxon signed-rank, two-sided, on "
                           "per-participant means (scipy.stats.wilcoxon, zero_method='wilcox')",
                           "effect_size": "matched-pairs rank-biserial r = (T+ - T-)/(T+ + T-), "
                                          "of the differences first minus second",
                           "correction": "Holm 1979, one family per metric (all its comparisons, all tasks)"}}


def _fmt(x: float | None, digits: int = 1) -> str:
    return "–" if x is None else f"{x:.{digits}f}"


def _cell(d: dict[str, Any], digits: int) -> str:
    if d["n"] == 0:
        return "–"
    if d["n"] == 1:
        return _fmt(d["median"], digits)
    return f"{_fmt(d['median'], digits)} [{_fmt(d['q1'], digits)}, {_fmt(d['q3'], digits)}]"


def _task_table(r: dict[str, Any], task: str) -> list[str]:
    head = ["condition", "successes", *(f"{m.label} {'↑' if m.better == 'higher' else '↓'}" for m in METRICS)]
    lines = ["| " + " | ".join(head) + " |", "|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|"]
    for cond in r["conditions"]:
        t = r["tables"][task][cond]
        cells = [cond, f"{t['successes']}/{t['trials']}", *(_cell(t[m.key], m.digits) for m in METRICS)]
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _comparison_table(r: dict[str, Any], task: str) -> list[str]:
    comps = [c for c in r["comparisons"] if c["task"] == task]
    if not comps:
        return []
    labels = {m.key: m.label for m in METRICS}
    lines = ["| comparison | metric | n | median diff. | W | p | p (Holm) | r | note |",
             "|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for c in comps:
        sig = " *" if c["significant"] else ""
        lines.append(f"| {c['a']} vs {c['b']} | {labels[c['metric']]} | {c['n']} | "
                     f"{_fmt(c['median_difference'], 2)} | {_fmt(c['statistic'], 1)} | {_fmt(c['p'], 3)} | "
                     f"{_fmt(c['p_holm'], 3)}{sig} | {_fmt(c['r_rank_biserial'], 2)} | {c['note']} |")
    return lines


def markdown(r: dict[str, Any]) -> str:
    """The report as markdown: one results table per task (rows: conditions; columns:
    metrics, median [Q1, Q3] over participants; ↑/↓: which way is better), then its
    comparisons, then how the numbers were made."""
    n, planned = len(r["participants"]), r["participants_planned"]
    out = [f"# {r['title']}: results", "",
           f"{n} of {planned} planned participants have data ({', '.join(r['participants']) or 'none'}); "
           "values are medians [Q1, Q3] over participants of each participant's mean over its measured "
           "trials (completion time: successful trials only).", ""]
    unfinished = [f"{p} {v['done']}/{v['total']}" for p, v in r["progress"].items() if v["done"] < v["total"]]
    if unfinished:
        out += [f"Unfinished participants (trials done/planned): {', '.join(unfinished)}.", ""]
    out += [f"**Warning (plan):** {w}" for w in r["plan_warnings"]] + [""] * bool(r["plan_warnings"])
    out += [f"**Data problem (skipped):** {p}" for p in r["problems"]] + [""] * bool(r["problems"])
    for task in r["tasks"]:
        out += [f"## Task {task}", "", *_task_table(r, task), ""]
        comp = _comparison_table(r, task)
        if comp:
            baseline = r["statistics"]["pairs"] == "baseline"
            which = "each condition against teleop" if baseline else "every pair"
            out += [f"Paired comparisons ({which}; * Holm-adjusted p <= {r['statistics']['alpha']:g}):",
                    "", *comp, ""]
    s = r["statistics"]
    out += ["## Statistics", "", f"- test: {s['test']}", f"- effect size: {s['effect_size']}",
            f"- correction: {s['correction']}",
            "- W is scipy's statistic (the smaller of the two rank sums); a test with fewer than two pairs, "
            "or no pair that differs, is not made, and one that cannot reach alpha with so few pairs says "
            "so (underpowered).", ""]
    return "\n".join(out)
