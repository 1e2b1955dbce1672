"""Learning benchmark: segmentation, fit and speed figures on generated demonstrations.

``run_bench(seed=0, n_demos=10) -> dict`` and ``format_bench(result) -> str``; run as
``sctd bench learn [--seed N] [--n-demos N] [--json]``. It prints figures; it asserts
nothing (timings depend on the machine).

- segmentation accuracy of the linear-IM skill against the generator's true phases
  (5 % outliers, 1 mm / 1 mrad noise), per raw displacement;
- whether the tilt's last state is a rotation-only IM in the tip frame;
- the tilt's sphere-centre error and its spread over RANSAC seeds;
- the pull's translation-field direction errors;
- learning time for each skill (warm: scikit-learn already imported; the import
  itself is reported separately);
- alpha-beta swap against GCO's, the C++ reference, when ``gco-wrapper`` is installed
  (:mod:`sctd.bench.gco`; ``--gco-instances N`` segmentation-shaped energies).

The tilt and the pull are the generated tasks ``bench_learn`` of
``sctd/app/defaults.yaml`` names (:mod:`sctd.app.defaults`); the report calls them by
those names (the result's ``tilt`` and ``pull``).
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import numpy as np

from sctd_sim import demogen

from ..app.defaults import defaults
from ..learn import (
    LinearIMLearner,
    VectorFieldLearner,
    learn_linear,
    learn_vector_fields,
    segmentation_accuracy,
)
from ..skill.fields import SphereField, TranslationField
from .demos import demo_kind, demos_of
from .fields import format_field_bench, run_field_bench, tip_frame
from .gco import format_gco_bench, run_gco_bench


def _angle(a, b) -> float:
    a = np.asarray(a) / np.linalg.norm(a)
    b = np.asarray(b) / np.linalg.norm(b)
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


def run_bench(seed: int = 0, n_demos: int = 10, outliers: float = 0.05, noise: float = 0.001,
              n_seeds: int = 5, gco_instances: int = 20, field_seeds: int = 10) -> dict[str, Any]:
    """Run every benchmark; returns plain data (see module doc)."""
    workload = defaults().bench_learn
    out: dict[str, Any] = {"seed": seed, "n_demos": n_demos, "outliers": outliers, "noise": noise,
                           "tilt": workload.tilt, "pull": workload.pull}
    t = time.perf_counter()
    import sklearn.svm  # noqa: F401  (the cold import is not learning time)

    out["sklearn_import_s"] = time.perf_counter() - t
    tilt = demogen.generate(demo_kind(workload.tilt), n_demos, noise=noise, outliers=outliers, seed=seed)
    _bench_linear(tilt, seed, out)
    _bench_vf_tilt(tilt, seed, n_seeds, out)
    pull = demogen.generate(demo_kind(workload.pull), n_demos, noise=noise, outliers=outliers, seed=seed)
    _bench_vf_pull(pull, seed, out)
    out["swap_vs_gco"] = run_gco_bench(gco_instances, seed, (workload.tilt, workload.pull))
    if field_seeds > 0:
        out["fields"] = run_field_bench(field_seeds, n_demos, noise, outliers)
    return out


def _bench_linear(tilt: demogen.DemoSet, seed: int, out: dict[str, Any]) -> None:
    """Linear IMs on the tilt task: accuracy, states, transitions, time."""
    tip = tip_frame(tilt)
    t = time.perf_counter()
    lin = learn_linear(demos_of(tilt), {"tip": tip}, learner=LinearIMLearner(random_state=seed))
    out["linear_time_s"] = time.perf_counter() - t
    acc, per_demo = segmentation_accuracy(lin.labels, tilt.truth["labels"])
    out["segmentation_accuracy"] = acc
    out["segmentation_accuracy_min_demo"] = min(per_demo.values())
    states = lin.learner.states_
    last = states[-1].label
    out["states"] = [st.label.name for st in states]
    out["tilt_state_tip_rotation_only"] = bool(last.frame == "tip" and all(a >= 3 for a in last.axes))
    out["transitions"] = [{"frame": h.frame, "accuracy": h.accuracy, "reachable": h.reachable}
                          for h in lin.learner.transitions_]


def _bench_vf_tilt(tilt: demogen.DemoSet, seed: int, n_seeds: int, out: dict[str, Any]) -> None:
    """Vector fields on the tilt task: sphere centre and its spread over seeds."""
    centre_true = np.asarray(tilt.truth["sphere_centre"])
    centres, times, offsets = [], [], []
    for s in range(seed, seed + n_seeds):
        t = time.perf_counter()
        vf = learn_vector_fields(demos_of(tilt), learner=VectorFieldLearner(random_state=s))
        times.append(time.perf_counter() - t)
        spheres = [f for f in vf.learner.fields_ if isinstance(f, SphereField)]
        if spheres:
            c = min((f.centre for f in spheres), key=lambda c: np.linalg.norm(c - centre_true))
            centres.append(c)
        for cf in vf.learner.candidate_frames_:
            if cf["kind"] == "sphere" and "ee_offset" in cf:
                offsets.append(cf["ee_offset"])
    C = np.array(centres) if centres else np.zeros((0, 3))
    out["tilt_sphere_found"] = f"{len(centres)}/{n_seeds}"
    out["tilt_sphere_centre_error_m"] = float(np.linalg.norm(C - centre_true, axis=1).max()) \
        if len(C) else None
    out["tilt_sphere_centre_spread_m"] = float(np.sqrt(np.mean(np.sum((C - C.mean(axis=0)) ** 2,
                                                                      axis=1)))) if len(C) else None
    out["tilt_sphere_centre_mean"] = C.mean(axis=0).tolist() if len(C) else None
    out["tilt_tip_offset_from_sphere"] = np.mean(offsets, axis=0).tolist() if offsets else None
    out["vf_tilt_time_s"] = float(np.max(times))


def _bench_vf_pull(pull: demogen.DemoSet, seed: int, out: dict[str, Any]) -> None:
    """Vector fields on the pull task: the translation fields' directions."""
    t = time.perf_counter()
    vfd = learn_vector_fields(demos_of(pull), learner=VectorFieldLearner(random_state=seed))
    out["vf_pull_time_s"] = time.perf_counter() - t
    dirs = [f.direction for f in vfd.learner.fields_ if isinstance(f, TranslationField)]
    out["pull_fields"] = [f.type for f in vfd.learner.fields_]
    out["pull_direction_error_deg"] = {
        k: (min(_angle(d, v) for d in dirs) if dirs else None)
        for k, v in pull.truth["directions"].items()}


def format_bench(r: dict[str, Any]) -> str:
    """Human-readable report of :func:`run_bench`, with its targets."""
    def ok(flag: bool) -> str:
        return "ok " if flag else "MISS"

    err = r["tilt_sphere_centre_error_m"]
    spread = r["tilt_sphere_centre_spread_m"]  # None, as err, when no seed found the sphere
    de = r["pull_direction_error_deg"]
    lines = [
        f"sctd learn benchmark (seed {r['seed']}, {r['n_demos']} demos, "
        f"{r['outliers']:.0%} outliers, {r['noise'] * 1000:.1f} mm noise)",
        f"[{ok(r['segmentation_accuracy'] >= 0.95)}] segmentation accuracy "
        f"{r['segmentation_accuracy']:.4f} (worst demo {r['segmentation_accuracy_min_demo']:.4f})"
        " target >= 0.95",
        f"[{ok(r['tilt_state_tip_rotation_only'])}] {r['tilt']} state rotation-only in tip frame: "
        f"states {r['states']}",
        f"[{ok(err is not None and err <= 0.005)}] {r['tilt']} sphere centre error "
        f"{'-' if err is None else f'{err * 1000:.2f} mm'} (max over seeds, found "
        f"{r['tilt_sphere_found']}), spread {'-' if spread is None else f'{spread * 1000:.3f} mm'}"
        " target <= 5 mm",
        f"      tip offset recovered from the sphere: {np.round(r['tilt_tip_offset_from_sphere'], 4)}"
        if r["tilt_tip_offset_from_sphere"] is not None else "      (no tip offset)",
        f"[{ok(all(v is not None and v <= 5 for v in de.values()))}] {r['pull']} field direction "
        "errors " + ", ".join(f"{k} {'-' if v is None else f'{v:.2f}'} deg" for k, v in de.items())
        + " target <= 5 deg",
        f"[{ok(max(r['linear_time_s'], r['vf_tilt_time_s'], r['vf_pull_time_s']) <= 5)}] "
        f"learning time linear {r['linear_time_s']:.2f} s, vf {r['tilt']} {r['vf_tilt_time_s']:.2f} s, "
        f"vf {r['pull']} {r['vf_pull_time_s']:.2f} s (scikit-learn import "
        f"{r['sklearn_import_s']:.2f} s not included) target <= 5 s",
    ]
    lines += format_gco_bench(r["swap_vs_gco"])
    if "fields" in r:
        lines += format_field_bench(r["fields"])
    return "\n".join(lines)


def add_bench_learn_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``sctd bench learn``."""
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--n-demos", type=int, default=10)
    parser.add_argument("--gco-instances", type=int, default=20,
                        help="energies on which the swap is compared with GCO's (default 20)")
    parser.add_argument("--field-seeds", type=int, default=10,
                        help="seeds of each generated task for the field types and the automatic "
                        "frames (0: skip; default 10)")
    parser.add_argument("--json", action="store_true")
    return parser


def main_bench_learn(args: argparse.Namespace) -> int:
    """Run ``sctd bench learn``: print the figures (or JSON)."""
    r = run_bench(seed=args.seed, n_demos=args.n_demos, gco_instances=args.gco_instances,
                  field_seeds=args.field_seeds)
    print(json.dumps(r, indent=1, default=float) if args.json else format_bench(r))
    return 0
