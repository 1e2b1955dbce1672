"""Learning beyond the thesis: which field each phase of a generated task is,
against the thesis' inlier score in the same run; centre and axis errors; automatic
feature frames against given ones; learning times.

``run_field_bench(seeds, n_demos) -> dict`` and ``format_field_bench(result) -> list of
str``, called by ``sctd bench learn``. It prints figures; it asserts nothing. Which
tasks it generates is data: ``bench_learn`` in ``sctd/app/defaults.yaml``
(:mod:`sctd.app.defaults`).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import numpy as np

from sctd_sim import demogen

from ..app.defaults import defaults
from ..learn import (
    LinearIMLearner,
    VectorFieldLearner,
    field_kinds_by_phase,
    learn_linear,
    learn_vector_fields,
    segmentation_accuracy,
)
from ..learn.results import VectorFieldResult
from ..skill.fields import CylinderField, SphereField
from .demos import demo_kind, demos_of

SELECTIONS = ("likelihood", "inliers")


def phase_kinds(ds: demogen.DemoSet, res: VectorFieldResult) -> tuple[str | None, ...]:
    """Per phase of a generated task, the kind of field most of its displacements are
    assigned to (None: all outliers)."""
    return field_kinds_by_phase(res.field_labels, [f.type for f in res.learner.fields_],
                                ds.truth["labels"], len(ds.truth["phases"]))


def _geometry(ds: demogen.DemoSet, res: VectorFieldResult) -> dict[str, float]:
    """A tilt's sphere-centre error (m), the crank's axis angle (deg) and axis-point
    distance from the true axis (m), where the learner found that field."""
    out: dict[str, float] = {}
    fields = res.learner.fields_
    if ds.shape == "tilt":
        true = np.asarray(ds.truth["sphere_centre"])
        errs = [float(np.linalg.norm(f.centre - true)) for f in fields if isinstance(f, SphereField)]
        if errs:
            out["centre_error_m"] = min(errs)
    if ds.shape == "crank":
        axis, point = np.asarray(ds.truth["axis"]), np.asarray(ds.truth["point"])
        cyl = [f for f in fields if isinstance(f, CylinderField)]
        if cyl:
            f = cyl[0]
            out["axis_error_deg"] = float(np.degrees(np.arccos(min(1.0, abs(float(f.axis @ axis))))))
            d = f.point - point
            out["axis_point_error_m"] = float(np.linalg.norm(d - (d @ axis) * axis))
    return out


def run_field_bench(seeds: int = 10, n_demos: int = 10, noise: float = 0.001,
                    outliers: float = 0.05, tasks: Sequence[str] | None = None,
                    tilt: str | None = None) -> dict[str, Any]:
    """Field types by both selections on every task of ``tasks`` (the generator's
    names; default ``bench_learn.fields`` of the defaults) and seed; automatic frames on
    the tilt task ``tilt`` (default ``bench_learn.tilt``)."""
    tasks = defaults().bench_learn.fields if tasks is None else tasks
    out: dict[str, Any] = {"seeds": seeds, "n_demos": n_demos, "tasks": {}}
    for task in tasks:
        kind = demo_kind(task)
        truth = kind.fields
        row: dict[str, Any] = {"truth": list(truth)}
        for sel in SELECTIONS:
            right, geo, times, wrong = 0, [], [], []
            for seed in range(seeds):
                ds = demogen.generate(kind, n_demos, noise=noise, outliers=outliers, seed=seed)
                t = time.perf_counter()
                res = learn_vector_fields(demos_of(ds), learner=VectorFieldLearner(
                    random_state=seed, selection=sel))
                times.append(time.perf_counter() - t)
                kinds = phase_kinds(ds, res)
                if kinds == truth:
                    right += 1
                else:
                    wrong.append({"seed": seed, "found": list(kinds)})
                geo.append(_geometry(ds, res))
            keys = sorted({k for g in geo for k in g})
            row[sel] = {"accuracy": right / seeds, "wrong": wrong, "time_s_max": max(times),
                        **{f"{k}_max": max(g[k] for g in geo if k in g) for k in keys}}
        out["tasks"][task] = row
    out["frames"] = _frames_bench(seeds, n_demos, noise, outliers,
                                  defaults().bench_learn.tilt if tilt is None else tilt)
    return out


def tip_frame(ds: demogen.DemoSet) -> list[float]:
    """The candidate frame ``tip`` the linear learner is given on a tilt's
    demonstrations: the true outlet, ``[x, y, z, qx, qy, qz, qw]`` in the ee frame."""
    return [*ds.truth["tip_offset"], 0.0, 0.0, 0.0, 1.0]


def _frames_bench(seeds: int, n_demos: int, noise: float, outliers: float, tilt: str) -> dict[str, Any]:
    """The linear learner with automatic frames against the given tip frame on the
    tilt task (segmentation accuracy against the generator's phases), and the crank axis
    offset found, over seeds; learning times."""
    acc_auto, acc_given, tip_err, t_auto, crank_err = [], [], [], [], []
    tilted = demo_kind(tilt)
    for seed in range(seeds):
        demos = demogen.generate(tilted, n_demos, noise=noise, outliers=outliers, seed=seed)
        tip = tip_frame(demos)
        t = time.perf_counter()
        auto = learn_linear(demos_of(demos), learner=LinearIMLearner(random_state=seed))
        t_auto.append(time.perf_counter() - t)
        given = learn_linear(demos_of(demos), {"tip": tip}, learner=LinearIMLearner(random_state=seed))
        acc_auto.append(segmentation_accuracy(auto.labels, demos.truth["labels"])[0])
        acc_given.append(segmentation_accuracy(given.labels, demos.truth["labels"])[0])
        spheres = [f for f in auto.found_frames if f.kind == "sphere"]
        tip_err.append(min((float(np.linalg.norm(f.pose[:3] - tip[:3])) for f in spheres), default=np.inf))
        crank = demogen.generate(demogen.SYNTHETIC["crank"], n_demos, noise=noise, outliers=outliers,
                                 seed=seed)
        c = learn_linear(demos_of(crank), learner=LinearIMLearner(random_state=seed))
        axis = [f for f in c.found_frames if f.kind == "cylinder"]
        crank_err.append(min((float(np.linalg.norm(f.pose[:3] - crank.truth["axis_ee_offset"]))
                              for f in axis), default=np.inf))
    return {"segmentation_auto_mean": float(np.mean(acc_auto)), "segmentation_auto_min": min(acc_auto),
            "segmentation_given_mean": float(np.mean(acc_given)), "segmentation_given_min": min(acc_given),
            "tip_offset_error_m_max": max(tip_err), "crank_axis_offset_error_m_max": max(crank_err),
            "linear_auto_time_s_max": max(t_auto)}


def format_field_bench(r: dict[str, Any]) -> list[str]:
    """Report lines of :func:`run_field_bench`."""
    lines = [f"field types over {r['seeds']} seeds ({r['n_demos']} demos each): likelihood "
             "(sctd) vs inliers (the thesis' MSAC score), same demonstrations"]
    for task, row in r["tasks"].items():
        a, b = row["likelihood"], row["inliers"]
        names = {"centre_error_m_max": "sphere centre error", "axis_error_deg_max": "axis error",
                 "axis_point_error_m_max": "axis point error"}
        extra = "; ".join(f"{names[k]} <= {v * 1000:.2f} mm" if k.endswith("_m_max") else
                          f"{names[k]} <= {v:.2f} deg" for k, v in a.items() if k in names)
        lines.append(f"[{'ok ' if a['accuracy'] >= 0.95 else 'MISS'}] {task:<6} "
                     f"{'+'.join(row['truth']):<22} {a['accuracy']:>6.0%} vs thesis {b['accuracy']:>5.0%}"
                     f"  (learning <= {a['time_s_max']:.2f} s){'; ' + extra if extra else ''}")
        for w in a["wrong"][:3]:
            lines.append(f"        seed {w['seed']}: found {'+'.join(str(k) for k in w['found'])}")
    f = r["frames"]
    lines += [
        f"[{'ok ' if f['segmentation_auto_min'] >= 0.95 else 'MISS'}] linear IMs with automatic "
        f"frames: segmentation {f['segmentation_auto_mean']:.4f} (worst seed "
        f"{f['segmentation_auto_min']:.4f}) vs given tip frame {f['segmentation_given_mean']:.4f} "
        f"(worst {f['segmentation_given_min']:.4f})",
        f"      tip found within {f['tip_offset_error_m_max'] * 1000:.1f} mm, crank axis within "
        f"{f['crank_axis_offset_error_m_max'] * 1000:.1f} mm (max over seeds); learning with the "
        f"frame search <= {f['linear_auto_time_s_max']:.2f} s",
    ]
    return lines
