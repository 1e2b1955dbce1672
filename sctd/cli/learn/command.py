"""``sctd learn`` and ``sctd dtw``: arguments, progress line, messages, exit codes.

The hyperparameter flags are derived (:mod:`sctd.app.options`) from the fields that
define them in :mod:`sctd.learn`; this module adds only the command's own arguments
(the folder, ``--method``, ``--out``, ``--frame``, ``--report``, ``--quiet``).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any, TextIO

import numpy as np
from numpy.typing import NDArray

from ...app.errors import fail
from ...app.options import add_arguments, flag_name, from_namespace
from ...learn import (
    METHODS,
    STAGES,
    Demo,
    DemoError,
    HyperparameterError,
    LinearIMLearner,
    LinearResult,
    Preprocessing,
    SkillOptions,
    VectorFieldLearner,
    VectorFieldOptions,
    VectorFieldResult,
    dtw,
    learn_linear,
    learn_vector_fields,
    read_demo_csv,
    read_demos,
)
from ...learn.gripper import GripperOptions
from ...learn.pipeline import hyperparameter_fields
from ...skill import SkillError
from ...task.demos import DEMOS_FILE, read_demos_info
from .report import write_report, write_skill


def add_learn_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``sctd learn DIR --method linear|vf --out SKILL.yaml ...``."""
    parser.add_argument("demos", type=Path, metavar="DIR", help="folder of demonstration CSVs")
    parser.add_argument("--method", choices=METHODS, default="linear",
                        help="linear input mappings (Ch. 4.1) or vector fields (Ch. 4.2)")
    parser.add_argument("--out", type=Path, required=True, help="skill YAML to write")
    parser.add_argument("--frame", action="append", default=[], metavar="NAME=x,y,z,qx,qy,qz,qw",
                        help="candidate feature frame as an offset from the ee (repeatable)")
    parser.add_argument("--report", type=Path, default=None, metavar="DIR",
                        help="write summary.json and figures here")
    # --seed seeds either learner: one flag, the same field name in both.
    add_arguments(parser, LinearIMLearner, only=("random_state",))
    add_arguments(parser, SkillOptions, only=("object",))
    # (unset: the folder's demos.yaml names it, :func:`resolve_object`)
    parser.set_defaults(object=None)
    parser.add_argument("--quiet", action="store_true", help="no progress line")
    add_arguments(parser.add_argument_group("preprocessing"), Preprocessing)
    add_arguments(parser.add_argument_group("linear IMs (Ch. 4.1)"), LinearIMLearner,
                  exclude=("random_state",))
    g = parser.add_argument_group("vector fields (Ch. 4.2)")
    add_arguments(g, VectorFieldLearner, exclude=("random_state",))
    add_arguments(g, VectorFieldOptions)
    add_arguments(g, SkillOptions, exclude=("object",))
    add_arguments(parser.add_argument_group("gripper events (demonstrations with the fingers)"),
                  GripperOptions)
    return parser


class ProgressLine:
    """A one-line progress indicator on stderr (no tqdm dependency): a callback for the
    learner's ``progress`` parameter, counting the stages it reports."""

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


def parse_frame(text: str) -> tuple[str, NDArray[np.float64]]:
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


def resolve_object(args: argparse.Namespace) -> None:
    """``args.object`` from the folder's ``demos.yaml`` where ``--object`` was not given;
    ValueError where neither names it, or where they disagree (the poses are in the
    folder's object's frame, whatever the flag says)."""
    info = read_demos_info(args.demos)
    if args.object is None:
        if info is None:
            raise ValueError(f"--object: name the task object whose frame the demonstrations are in: "
                             f"{args.demos} has no {DEMOS_FILE} to say it (sctd teach and sctd record "
                             "write one)")
        args.object = info.object
    elif info is not None and info.object != args.object:
        raise ValueError(f"--object {args.object}: the demonstrations in {args.demos} are of "
                         f"{info.object!r} ({args.demos / DEMOS_FILE})")


def _learn(args: argparse.Namespace, demos: list[Demo],
           progress: ProgressLine) -> LinearResult | VectorFieldResult:
    """The learning run the arguments describe, on ``demos``."""
    preprocessing = from_namespace(Preprocessing, args)
    options = from_namespace(SkillOptions, args)
    if args.method == "linear":
        frames = dict(parse_frame(f) for f in args.frame)
        return learn_linear(demos, frames, learner=from_namespace(LinearIMLearner, args),
                            preprocessing=preprocessing, options=options, progress=progress,
                            gripper=from_namespace(GripperOptions, args))
    return learn_vector_fields(demos, learner=from_namespace(VectorFieldLearner, args),
                               preprocessing=preprocessing, options=options,
                               field_options=from_namespace(VectorFieldOptions, args),
                               progress=progress, gripper=from_namespace(GripperOptions, args))


def _settings(args: argparse.Namespace) -> dict[str, Any]:
    """Every learning flag's value by field name, both methods', and ``seed`` (the name
    ``summary.json`` has always given ``random_state``): its ``hyperparameters`` keep
    every key they had, whatever the method."""
    names = [f.name for cls in (Preprocessing, LinearIMLearner, VectorFieldLearner, VectorFieldOptions,
                                SkillOptions, GripperOptions)
             for f in dataclasses.fields(cls) if "help" in f.metadata]
    return {**{n: getattr(args, n) for n in names if hasattr(args, n)}, "seed": args.random_state}


def run_learn(args: argparse.Namespace) -> dict[str, Any]:
    """Learn, write ``args.out`` (and its model file) and, with ``args.report``, the
    report; return the summary (as ``summary.json`` holds it)."""
    progress = ProgressLine([*STAGES[args.method], "export"], enabled=not args.quiet)
    t0 = time.perf_counter()
    try:
        demos = read_demos(args.demos)
        resolve_object(args)
        result = _learn(args, demos, progress)
        skill = write_skill(result, args.out)
        result.timings["total_with_export"] = time.perf_counter() - t0
        progress("export")
    finally:
        progress.close()
    return write_report(result, skill, args.report, demos_dir=str(args.demos), settings=_settings(args),
                        demos=demos)


def main_learn(args: argparse.Namespace) -> int:
    """Run ``sctd learn``; 0 on success, 2 on bad input (message on stderr)."""
    try:
        summary = run_learn(args)
    except HyperparameterError as exc:  # named by its flag
        field = next((f for f in hyperparameter_fields(args.method) if f.name == exc.name), None)
        return fail("learn", f"{flag_name(field) if field else exc.name}: {exc.problem}")
    except (DemoError, SkillError, ValueError) as exc:
        return fail("learn", str(exc))
    sk = summary["skill"]
    print(f"wrote {args.out} ({sk['id']}): {len(sk['states'])} state(s), "
          f"{len(sk['transitions'])} transition(s), {len(summary.get('fields', []))} field(s) "
          f"in {summary['timings'].get('total', 0):.2f} s")
    for f in summary.get("found_frames", []):
        print(f"frame {f['name']} found in the demonstrations ({f['kind']} "
              f"{'centre' if f['kind'] == 'sphere' else 'axis'}, ee offset "
              f"[{', '.join(f'{x:.3f}' for x in f['pose'][:3])}], spread {f['spread'] * 1000:.1f} mm)")
    for note in summary.get("trap_notes", []):  # Ch. 6.2: states that trap the user
        print(f"  {note}")
    if args.report is not None:
        print(f"report in {args.report}")
    return 0


def add_dtw_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``sctd dtw A.csv B.csv``."""
    parser.add_argument("a", type=Path, metavar="A.csv")
    parser.add_argument("b", type=Path, metavar="B.csv")
    add_arguments(parser, LinearIMLearner, only=("alpha",))
    parser.add_argument("--json", action="store_true", help="print JSON")
    return parser


def main_dtw(args: argparse.Namespace) -> int:
    """DTW with the tf-norm between two demonstrations (Ch. 5.1)."""
    try:
        a = read_demo_csv(args.a)
        b = read_demo_csv(args.b)
    except DemoError as exc:
        return fail("dtw", str(exc))
    cost, path = dtw(a.poses, b.poses, args.alpha)
    out = {"cost": cost, "path_length": len(path), "mean_cost": cost / len(path),
           "n_a": len(a), "n_b": len(b), "alpha": args.alpha}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"DTW cost {cost:.4f} over a path of {len(path)} pairs "
              f"(mean {cost / len(path):.5f}; {len(a)} x {len(b)} samples, alpha {args.alpha})")
    return 0
