"""Demonstrations -> learned results -> skill files (Algorithms 1 and 4 end to end).

:func:`learn_linear` and :func:`learn_vector_fields` are pure (arrays in, result
objects out); :func:`run_learn` adds the edges: reading the demonstration folder,
writing the skill and the report. Hyperparameter defaults are the thesis' (Ch. 5.2).
"""

from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass, field
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from .. import se3
from .demos import Demo, read_demos, smooth_poses, spike_mask, subsample_by_distance
from .linear import LinearIMLearner
from .vf import VectorFieldLearner

Array = NDArray[np.float64]


@dataclass
class LearnParams:
    """Every hyperparameter of ``sctd learn`` (thesis values, Ch. 5.2, where it has one)."""

    # preprocessing
    spacing: float = 0.02  # tf-norm sample spacing for linear IMs (m)
    vf_spacing: float = 0.015  # position sample spacing for vector fields (m)
    smooth: int = 5  # moving-average window (samples); 1 disables
    despike: bool = True  # drop isolated gross outliers (Hampel filter)
    # linear IMs (Ch. 4.1)
    alpha: float = 0.4
    beta: float = 0.01
    smoothness: float = 0.005  # lambda
    radius: float = 0.04
    max_n: int = 10
    C: float = 1000.0
    cut: str = "swap"  # swap | expansion
    min_segment: int = 3
    axis_support: float = 0.08
    margin: float = 0.005
    dtw_align: bool = False  # DTW-aligned displacements of different demos as neighbours
    # vector fields (Ch. 4.2)
    n_fields: int = 2  # n_R
    em_iterations: int = 5
    angle_sphere: float = 15.0
    angle_translation: float = 25.0
    angle_cylinder: float = 20.0
    max_radius: float = 0.3
    chance_weight: float = 0.5
    # vector-field skill execution parameters (Listing 4.2)
    min_v: float = 0.1
    max_d: float = 0.15
    k_s: float = 0.5
    vf_max_n: int = 5
    vf_combine: str = "intent"  # intent: membership given the command too (weighted: eq. 4.32)
    vf_rotation_weight: float = 0.1  # m/rad: neighbour orientation by pose (0: by position, the thesis)
    vf_motion: str = "rigid"  # rigid: rotational fields turn the hand (translate: the thesis')
    # skill
    object: str = "object"
    max_linear_speed: float = 0.10
    max_angular_speed: float = 0.50
    seed: int = 0


@dataclass
class Prepared:
    """One preprocessed demonstration: ``keep`` indexes raw rows, ``poses`` (k, 7)."""

    name: str
    n_raw: int
    keep: NDArray[np.int64]
    poses: Array


@dataclass
class LinearResult:
    params: LearnParams
    frames: dict[str, Array]  # name -> pose [7] (T_ee_frame)
    prepared: list[Prepared]
    learner: LinearIMLearner
    labels: dict[str, list[int]]  # demo -> state index per raw displacement
    timings: dict[str, float] = field(default_factory=dict)


@dataclass
class VectorFieldResult:
    params: LearnParams
    prepared: list[Prepared]
    learner: VectorFieldLearner
    labels: dict[str, list[int]]  # demo -> state index (0: one state) per raw displacement
    field_labels: dict[str, list[int]]  # demo -> field index (-1 outlier) per raw displacement
    timings: dict[str, float] = field(default_factory=dict)


def preprocess(demos: list[Demo], params: LearnParams, spacing: float,
               translation_only: bool) -> list[Prepared]:
    """Despike, smooth and subsample every demonstration by distance."""
    out = []
    for d in demos:
        idx = np.arange(len(d.t))
        if params.despike:
            idx = np.flatnonzero(spike_mask(d.poses))
        P = smooth_poses(d.poses[idx], params.smooth)
        k = subsample_by_distance(P, spacing, params.alpha, translation_only=translation_only)
        out.append(Prepared(d.name, len(d.t), idx[k], P[k]))
    return out


def raw_labels(prep: Prepared, labels: NDArray[np.int64]) -> list[int]:
    """Per raw displacement (row i -> i + 1) the label of the subsampled displacement
    that spans it."""
    i = np.arange(prep.n_raw - 1)
    j = np.clip(np.searchsorted(prep.keep, i, side="right") - 1, 0, len(labels) - 1)
    return [int(x) for x in np.asarray(labels)[j]]


def learn_linear(demos: list[Demo], frames: dict[str, Any] | None, params: LearnParams,
                 progress=None) -> LinearResult:
    """Linear IMs (Ch. 4.1, Algorithm 1) from demonstrations.

    Parameters
    ----------
    demos : list of Demo
    frames : dict of name -> pose [x, y, z, qx, qy, qz, qw] (T_ee_frame), optional
        Candidate feature frames besides ``ee``.
    params : LearnParams
    progress : callable(str), optional
    """
    t0 = time.perf_counter()
    frames = {k: np.asarray(v, dtype=float) for k, v in (frames or {}).items()}
    prepared = preprocess(demos, params, params.spacing, translation_only=False)
    if progress:
        progress("preprocess")
    t1 = time.perf_counter()
    learner = LinearIMLearner(alpha=params.alpha, beta=params.beta, smoothness=params.smoothness,
                              radius=params.radius, max_n=params.max_n, C=params.C,
                              method=params.cut, min_segment=params.min_segment,
                              axis_support=params.axis_support, margin=params.margin,
                              dtw_align=params.dtw_align, random_state=params.seed)
    learner.fit([se3.transform_from_pose(p.poses) for p in prepared],
                {k: se3.transform_from_pose(v) for k, v in frames.items()}, progress=progress)
    labels = {p.name: raw_labels(p, s) for p, s in zip(prepared, learner.state_labels_, strict=True)}
    timings = {"preprocess": t1 - t0, **learner.timings_, "total": time.perf_counter() - t0}
    return LinearResult(params, frames, prepared, learner, labels, timings)


def learn_vector_fields(demos: list[Demo], params: LearnParams, progress=None) -> VectorFieldResult:
    """Vector fields (Ch. 4.2, Algorithm 4) from demonstrations (ee positions)."""
    t0 = time.perf_counter()
    prepared = preprocess(demos, params, params.vf_spacing, translation_only=True)
    if progress:
        progress("preprocess")
    t1 = time.perf_counter()
    learner = VectorFieldLearner(
        n_fields=params.n_fields, em_iterations=params.em_iterations,
        angles={"sphere": params.angle_sphere, "translation": params.angle_translation,
                "cylinder": params.angle_cylinder},
        max_radius=params.max_radius, chance_weight=params.chance_weight,
        random_state=params.seed)
    learner.fit([p.poses[:, :3] for p in prepared], [p.poses[:, 3:] for p in prepared],
                progress=progress)
    labels, field_labels = {}, {}
    for k, p in enumerate(prepared):
        sel = learner.demo_index_ == k
        per = np.full(max(1, len(p.keep) - 1), -1, dtype=np.int64)
        per[learner.sample_index_[sel]] = learner.assignment_[sel]
        field_labels[p.name] = raw_labels(p, per)
        labels[p.name] = [0] * (p.n_raw - 1)
    timings = {"preprocess": t1 - t0, **learner.timings_, "total": time.perf_counter() - t0}
    return VectorFieldResult(params, prepared, learner, labels, field_labels, timings)


class Progress:
    """A one-line progress indicator on stderr (no tqdm dependency)."""

    def __init__(self, stages: list[str], stream: TextIO | None = None, enabled: bool = True):
        self.stages = stages
        self.stream = stream or sys.stderr
        self.enabled = enabled
        self.done = 0
        self.t0 = time.perf_counter()

    def __call__(self, name: str) -> None:
        self.done = min(len(self.stages), self.done + 1)
        if not self.enabled:
            return
        width = 20
        fill = int(width * self.done / max(1, len(self.stages)))
        self.stream.write(f"\r[{'#' * fill}{'.' * (width - fill)}] {self.done}/{len(self.stages)} "
                          f"{name:<14} {time.perf_counter() - self.t0:5.1f}s")
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


LINEAR_STAGES = ["preprocess", "costs", "segmentation", "states", "transitions", "export"]
VF_STAGES = ["preprocess", "ransac", "em", "export"]


def params_from_args(args: Any) -> LearnParams:
    """LearnParams from an argparse namespace (attributes named like the fields)."""
    p = LearnParams()
    for k in asdict(p):
        if hasattr(args, k) and getattr(args, k) is not None:
            setattr(p, k, getattr(args, k))
    return p


def parse_frame(text: str) -> tuple[str, Array]:
    """``NAME=x,y,z,qx,qy,qz,qw`` -> (name, pose [7]); the quaternion must be unit."""
    name, sep, rest = text.partition("=")
    if not sep or not name:
        raise ValueError(f"--frame {text!r}: expected NAME=x,y,z,qx,qy,qz,qw")
    try:
        vals = [float(x) for x in rest.split(",")]
    except ValueError:
        raise ValueError(f"--frame {text!r}: values must be numbers") from None
    if len(vals) != 7 or not all(np.isfinite(vals)):
        raise ValueError(f"--frame {text!r}: expected 7 finite numbers, got {len(vals)}")
    if abs(float(np.linalg.norm(vals[3:])) - 1.0) > 1e-3:
        raise ValueError(f"--frame {text!r}: quaternion must be unit")
    if name in ("ee", "object"):
        raise ValueError(f"--frame {text!r}: {name!r} is built in")
    return name, np.asarray(vals)


def run_learn(args: Any) -> dict[str, Any]:
    """Read ``args.demos`` (a folder), learn with ``args.method``, write ``args.out`` and,
    with ``args.report``, the report. Returns the summary dict.

    ``args`` is an argparse namespace from :func:`sctd.learn.cli.add_learn_arguments`
    (or anything with the same attributes).
    """
    from .export import write_linear_skill, write_report, write_vf_skill

    params = params_from_args(args)
    method = getattr(args, "method", "linear")
    quiet = bool(getattr(args, "quiet", False))
    demos = read_demos(args.demos)
    frames = dict(parse_frame(f) for f in (getattr(args, "frame", None) or []))
    stages = LINEAR_STAGES if method == "linear" else VF_STAGES
    prog = Progress(stages, enabled=not quiet)
    t0 = time.perf_counter()
    try:
        result: LinearResult | VectorFieldResult
        if method == "linear":
            lin = learn_linear(demos, frames, params, prog)
            skill = write_linear_skill(lin, args.out)
            result = lin
        elif method == "vf":
            vfr = learn_vector_fields(demos, params, prog)
            skill = write_vf_skill(vfr, args.out)
            result = vfr
        else:
            raise ValueError(f"method must be linear or vf, got {method!r}")
        result.timings["total_with_export"] = time.perf_counter() - t0
        prog("export")
    finally:
        prog.close()
    report = getattr(args, "report", None)
    return write_report(result, skill, report, demos_dir=str(args.demos))
