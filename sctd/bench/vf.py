"""``sctd bench vf``: a vector-field skill's tick cost against its number of
demonstration points, next to the hand-written pour, in one run.

The learned skill's model files are resized to each ``--points`` count
(:func:`resized_model`: evenly thinned, or densified along each demonstration by
interpolating between its consecutive points, so the fields and the demonstrations'
paths stay the same) and written with the skill into a temporary bundle. Each skill's
tick is then timed in this process (:func:`sctd.bench.latency.tick_histogram`: the
daemon's control step without Zenoh, back to back), the skills taking turns for
``--rounds`` rounds so that a busy machine slows them alike; the rounds' ticks are
pooled. ``--daemon S`` adds the daemon's own figure: ``sctd bench latency`` for S
seconds with the hand-written pour and with the learned skill at ``--daemon-points``.
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from sctd.app.defaults import defaults
from sctd.app.errors import fail
from sctd.bench.latency import run_latency_bench, tick_histogram
from sctd.skill import SkillError, VectorFieldModel, load_skill, vector_field_model_to_bytes
from sctd.skill.catalog import find_skill
from sctd.skill.loader import bundle_from_file
from sctd.timing import Histogram

DEMO_GAP = 0.05  # m: consecutive points farther apart than this belong to different demonstrations


def resized_model(model: VectorFieldModel, n: int) -> VectorFieldModel:
    """``model`` with ``n`` demonstration points: every k-th of them (evenly spaced, in
    their order) for fewer; for more, points interpolated between consecutive points of
    one demonstration (closer than ``DEMO_GAP``), the extra ones spread evenly over those
    segments: positions and responsibilities linearly, orientations by normalised
    linear interpolation in the first one's hemisphere. The fields stay the same."""
    p, q, r = model.points, model.quaternions, model.responsibilities
    if n < 1:
        raise ValueError(f"points: expected at least 1, got {n}")
    if n <= len(p):
        keep = np.unique(np.round(np.linspace(0, len(p) - 1, n)).astype(int))
        return VectorFieldModel(model.fields, p[keep], q[keep], r[keep])
    segments = np.flatnonzero(np.linalg.norm(np.diff(p, axis=0), axis=1) < DEMO_GAP)
    if len(segments) == 0:
        raise ValueError("points: the model has no two consecutive points of one demonstration")
    extra = np.full(len(segments), (n - len(p)) // len(segments))
    extra[: (n - len(p)) % len(segments)] += 1
    rows_p, rows_q, rows_r = [], [], []
    for i in range(len(p)):
        rows_p.append(p[i : i + 1])
        rows_q.append(q[i : i + 1])
        rows_r.append(r[i : i + 1])
        j = np.searchsorted(segments, i)
        if j < len(segments) and segments[j] == i and extra[j]:
            t = (np.arange(1, extra[j] + 1) / (extra[j] + 1))[:, None]
            q1 = q[i + 1] if q[i] @ q[i + 1] >= 0.0 else -q[i + 1]
            qt = (1.0 - t) * q[i] + t * q1
            rows_p.append((1.0 - t) * p[i] + t * p[i + 1])
            rows_q.append(qt / np.linalg.norm(qt, axis=1, keepdims=True))
            rows_r.append((1.0 - t) * r[i] + t * r[i + 1])
    return VectorFieldModel(model.fields, np.concatenate(rows_p), np.concatenate(rows_q),
                            np.concatenate(rows_r))


def resized_skill(skill: str, n: int, folder: Path) -> str:
    """Write ``skill`` (a YAML path) into ``folder`` with every model file it reads
    resized to ``n`` points; the written YAML's path."""
    bundle = bundle_from_file(skill)
    loaded = load_skill(skill)
    models = {rel: m for s in loaded.states for e in s.input_mappings for rel, m in e.models()}
    models |= {rel: m for s in loaded.states for c in s.active_constraints for rel, m in c.models()}
    if not models:
        raise ValueError(f"{skill}: reads no vector-field model")
    folder.mkdir(parents=True, exist_ok=True)
    for rel, m in models.items():
        (folder / rel).parent.mkdir(parents=True, exist_ok=True)
        (folder / rel).write_bytes(vector_field_model_to_bytes(resized_model(m, n), rel))
    out = folder / Path(skill).name
    out.write_text(bundle.yaml_text)
    return str(out)


def measure(skill: str, baseline: str, points: list[int], ticks: int, rounds: int,
            rate: float = 1000.0) -> dict[str, Any]:
    """Per-tick cost (ms; p50, p99, ...) of ``baseline`` and of ``skill`` resized to each
    of ``points``, in this process, in ``rounds`` alternating rounds of ``ticks`` ticks
    each (pooled)."""
    with tempfile.TemporaryDirectory(prefix="sctd-bench-vf-") as tmp:
        paths = {"baseline": baseline}
        paths |= {str(n): resized_skill(skill, n, Path(tmp) / str(n)) for n in points}
        pooled = {name: Histogram() for name in paths}
        for _ in range(rounds):
            for name, path in paths.items():
                pooled[name].merge(tick_histogram(path, rate, ticks))
    base = pooled["baseline"].summary_ms()
    rows = []
    for n in points:
        h = pooled[str(n)].summary_ms()
        rows.append({"points": n, "tick_ms": h,
                     "p99_over_baseline": round(h["p99"] / base["p99"], 3) if base["p99"] else None})
    return {"skill": skill, "baseline": baseline, "baseline_tick_ms": base, "ticks": ticks,
            "rounds": rounds, "rate_hz": rate, "rows": rows}


def measure_daemon(skill: str, baseline: str, points: int, seconds: float,
                   logdir: Path) -> dict[str, Any]:
    """The daemon's per-tick compute (``sctd bench latency``) with ``baseline`` and with
    ``skill`` resized to ``points``, one after the other."""
    vf = resized_skill(skill, points, logdir / f"skill-{points}")
    out: dict[str, dict[str, Any]] = {}
    for name, path in (("baseline", baseline), ("skill", vf)):
        (logdir / name).mkdir(parents=True, exist_ok=True)
        r = run_latency_bench(path, 1000.0, seconds, 500.0, 10, logdir / name)
        out[name] = {"skill": path, "compute_ms": r["compute_ms"], "lateness_ms": r["lateness_ms"],
                     "late_ticks": r["late_ticks"], "ticks": r["ticks"]}
    b, s = out["baseline"]["compute_ms"]["p99"], out["skill"]["compute_ms"]["p99"]
    return {"points": points, "seconds": seconds, **out,
            "p99_over_baseline": round(s / b, 3) if b else None}


def format_report(r: dict[str, Any]) -> str:
    def cells(h: dict) -> str:
        return f"p50 {h['p50']:7.3f}   p99 {h['p99']:7.3f}   p99.9 {h['p999']:7.3f}   max {h['max']:7.3f}"

    lines = [f"sctd bench vf: {r['skill']} resized, next to {r['baseline']}; tick in this process "
             f"(no Zenoh, back to back), {r['rounds']} rounds x {r['ticks']} ticks; ms"]
    lines.append(f"  {'hand-written':>14s}   {cells(r['baseline_tick_ms'])}")
    for row in r["rows"]:
        lines.append(f"  {row['points']:>7d} points   {cells(row['tick_ms'])}   "
                     f"p99 / hand-written {row['p99_over_baseline']:.2f}")
    if len(r["rows"]) > 1:
        a, b = r["rows"][0], r["rows"][-1]
        growth = b["tick_ms"]["p99"] / a["tick_ms"]["p99"] if a["tick_ms"]["p99"] else math.nan
        logs = math.log(b["points"]) / math.log(a["points"]) if a["points"] > 1 else math.nan
        lines.append(f"  p99 at {b['points']} points / at {a['points']}: {growth:.2f} "
                     f"(log ratio {logs:.2f}, point ratio {b['points'] / a['points']:.0f})")
    d = r.get("daemon")
    if d:
        lines.append(f"daemon (sctd bench latency, {d['seconds']:g} s each), tick compute, ms:")
        lines.append(f"  {'hand-written':>14s}   {cells(d['baseline']['compute_ms'])}")
        lines.append(f"  {d['points']:>7d} points   {cells(d['skill']['compute_ms'])}   "
                     f"p99 / hand-written {d['p99_over_baseline']:.2f}")
    return "\n".join(lines)


def _counts(text: str) -> list[int]:
    try:
        out = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated integers, got {text!r}") from None
    if not out or min(out) < 1:
        raise argparse.ArgumentTypeError(f"expected point counts >= 1, got {text!r}")
    return out


def _skill_path(name: str) -> str:
    """The file of a skill named or given by path (argparse type: a bad one is an error
    naming the places searched)."""
    try:
        return str(find_skill(name))
    except SkillError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def add_bench_vf_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``sctd bench vf``."""
    p.add_argument("--skill", default=defaults().learned_skill, type=_skill_path,
                   help="the vector-field skill whose model files are resized: a path or a shipped "
                        "or stored skill's name (default %(default)s)")
    p.add_argument("--baseline", default=defaults().skill, type=_skill_path,
                   help="the hand-written skill timed next to it (default %(default)s)")
    p.add_argument("--points", type=_counts, default=[300, 1000, 5000, 20000],
                   help="demonstration point counts, comma-separated: the skill's model files are "
                        "resized to each (thinned, or densified along the demonstrations; "
                        "docs/vf-tick.md) (default 300,1000,5000,20000)")
    p.add_argument("--ticks", type=int, default=3000, help="ticks per skill and round (default %(default)s)")
    p.add_argument("--rounds", type=int, default=3, help="alternating rounds (default %(default)s)")
    p.add_argument("--daemon", type=float, default=0.0, metavar="SECONDS",
                   help="also run sctd bench latency this long with the baseline and with the skill "
                        "at --daemon-points (default: not)")
    p.add_argument("--daemon-points", type=int, default=5000,
                   help="the skill's point count in the daemon run (default %(default)s)")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def main_bench_vf(args: argparse.Namespace) -> int:
    if args.ticks < 1 or args.rounds < 1:
        return fail("bench vf", "--ticks and --rounds: must be >= 1")
    if args.daemon < 0 or args.daemon_points < 1:
        return fail("bench vf", "--daemon: must be >= 0 s; --daemon-points: >= 1")
    try:
        r = measure(args.skill, args.baseline, args.points, args.ticks, args.rounds)
        if args.daemon:
            with tempfile.TemporaryDirectory(prefix="sctd-bench-vf-") as tmp:
                r["daemon"] = measure_daemon(args.skill, args.baseline, args.daemon_points,
                                             args.daemon, Path(tmp))
    except (ValueError, RuntimeError) as e:  # a skill that does not load (SkillError), no model
        return fail("bench vf", str(e))
    print(json.dumps(r) if args.json else format_report(r))
    return 0
