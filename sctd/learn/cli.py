"""``sctd learn`` and ``sctd dtw``: argparse wiring (the lead registers these).

``add_learn_arguments(parser)`` / ``main_learn(args) -> int`` and
``add_dtw_arguments(parser)`` / ``main_dtw(args) -> int``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..skill import SkillError
from .demos import DemoError, read_demo_csv
from .pipeline import LearnParams

_D = LearnParams()


def add_learn_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``sctd learn DIR --method linear|vf --out SKILL.yaml ...``."""
    parser.add_argument("demos", type=Path, metavar="DIR", help="folder of demonstration CSVs")
    parser.add_argument("--method", choices=("linear", "vf"), default="linear",
                        help="linear input mappings (Ch. 4.1) or vector fields (Ch. 4.2)")
    parser.add_argument("--out", type=Path, required=True, help="skill YAML to write")
    parser.add_argument("--frame", action="append", default=[], metavar="NAME=x,y,z,qx,qy,qz,qw",
                        help="candidate feature frame as an offset from the ee (repeatable)")
    parser.add_argument("--report", type=Path, default=None, metavar="DIR",
                        help="write summary.json and figures here")
    parser.add_argument("--seed", type=int, default=_D.seed)
    parser.add_argument("--object", default=_D.object, help="task object name (the skill frame)")
    parser.add_argument("--quiet", action="store_true", help="no progress line")
    g = parser.add_argument_group("preprocessing")
    g.add_argument("--spacing", type=float, default=_D.spacing,
                   help="tf-norm sample spacing for linear IMs (m)")
    g.add_argument("--vf-spacing", type=float, default=_D.vf_spacing,
                   help="sample spacing for vector fields (m)")
    g.add_argument("--smooth", type=int, default=_D.smooth, help="moving-average window (samples)")
    g.add_argument("--no-despike", dest="despike", action="store_false",
                   help="keep isolated outlier samples")
    g = parser.add_argument_group("linear IMs (Ch. 4.1)")
    g.add_argument("--alpha", type=float, default=_D.alpha, help="tf-norm m/rad (eq. 4.9)")
    g.add_argument("--beta", type=float, default=_D.beta, help="cost per DoF (eq. 4.14)")
    g.add_argument("--lambda", dest="smoothness", type=float, default=_D.smoothness,
                   help="smoothness (eq. 4.16)")
    g.add_argument("--radius", type=float, default=_D.radius, help="neighbour radius (m)")
    g.add_argument("--max-n", type=int, default=_D.max_n, help="spatial neighbours")
    g.add_argument("--C", dest="C", type=float, default=_D.C, help="SVM penalty (eq. 4.17)")
    g.add_argument("--cut", choices=("swap", "expansion"), default=_D.cut,
                   help="graph-cut move (alpha-beta swap or alpha-expansion)")
    g.add_argument("--min-segment", type=int, default=_D.min_segment,
                   help="shortest run kept (displacements)")
    g.add_argument("--axis-support", type=float, default=_D.axis_support,
                   help="share of a state's net motion an axis needs to be in its IM")
    g.add_argument("--margin", type=float, default=_D.margin, help="transition hysteresis (m)")
    g.add_argument("--dtw-align", action="store_true",
                   help="add DTW-aligned displacements of different demos as graph-cut neighbours")
    g = parser.add_argument_group("vector fields (Ch. 4.2)")
    g.add_argument("--n-fields", type=int, default=_D.n_fields, help="RANSAC fields n_R")
    g.add_argument("--em-iterations", type=int, default=_D.em_iterations)
    g.add_argument("--angle-sphere", type=float, default=_D.angle_sphere, help="degrees")
    g.add_argument("--angle-translation", type=float, default=_D.angle_translation, help="degrees")
    g.add_argument("--angle-cylinder", type=float, default=_D.angle_cylinder, help="degrees")
    g.add_argument("--max-radius", type=float, default=_D.max_radius,
                   help="largest sphere/cylinder radius (m)")
    g.add_argument("--chance-weight", type=float, default=_D.chance_weight,
                   help="weight of the chance-inlier correction when comparing field types")
    g.add_argument("--min-v", type=float, default=_D.min_v, help="eq. 4.34 floor")
    g.add_argument("--max-d", type=float, default=_D.max_d, help="neighbour distance (m)")
    g.add_argument("--k-s", type=float, default=_D.k_s, help="sigmoid k (eq. 4.33)")
    g.add_argument("--vf-max-n", type=int, default=_D.vf_max_n, help="neighbours at run time")
    g.add_argument("--vf-motion", choices=("rigid", "translate"), default=_D.vf_motion,
                   help="rigid: motion along a sphere or cylinder field turns the hand about its "
                        "centre or axis; translate: only moves it, as in the thesis (default %(default)s)")
    g.add_argument("--vf-rotation-weight", type=float, default=_D.vf_rotation_weight,
                   help="m per rad: the neighbour-orientation constraint takes the demonstration "
                        "points nearest in pose (position and orientation) rather than in position "
                        "alone (0, the thesis) (default %(default)s)")
    g.add_argument("--vf-combine", choices=("intent", "weighted", "most_probable"), default=_D.vf_combine,
                   help="how fields' agreements combine: intent weighs them by the membership given "
                        "the position and the command; weighted (eq. 4.32) and most_probable "
                        "(eq. 4.31) by the position's alone (default %(default)s)")
    g.add_argument("--max-linear-speed", type=float, default=_D.max_linear_speed)
    g.add_argument("--max-angular-speed", type=float, default=_D.max_angular_speed)
    return parser


def main_learn(args: argparse.Namespace) -> int:
    """Run ``sctd learn``; 0 on success, 2 on bad input (message on stderr)."""
    from .pipeline import run_learn

    try:
        summary = run_learn(args)
    except (DemoError, SkillError, ValueError) as exc:
        print(f"sctd learn: error: {exc}", file=sys.stderr)
        return 2
    sk = summary["skill"]
    print(f"wrote {args.out} ({sk['id']}): {len(sk['states'])} state(s), "
          f"{len(sk['transitions'])} transition(s), {len(summary.get('fields', []))} field(s) "
          f"in {summary['timings'].get('total', 0):.2f} s")
    if args.report is not None:
        print(f"report in {args.report}")
    return 0


def add_dtw_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """Arguments of ``sctd dtw A.csv B.csv``."""
    parser.add_argument("a", type=Path, metavar="A.csv")
    parser.add_argument("b", type=Path, metavar="B.csv")
    parser.add_argument("--alpha", type=float, default=_D.alpha, help="tf-norm m/rad")
    parser.add_argument("--json", action="store_true", help="print JSON")
    return parser


def main_dtw(args: argparse.Namespace) -> int:
    """DTW with the tf-norm between two demonstrations (Ch. 5.1)."""
    from .demos import dtw

    try:
        a = read_demo_csv(args.a)
        b = read_demo_csv(args.b)
    except DemoError as exc:
        print(f"sctd dtw: error: {exc}", file=sys.stderr)
        return 2
    cost, path = dtw(a.poses, b.poses, args.alpha)
    out = {"cost": cost, "path_length": len(path), "mean_cost": cost / len(path),
           "n_a": len(a), "n_b": len(b), "alpha": args.alpha}
    if args.json:
        print(json.dumps(out))
    else:
        print(f"DTW cost {cost:.4f} over a path of {len(path)} pairs "
              f"(mean {cost / len(path):.5f}; {len(a)} x {len(b)} samples, alpha {args.alpha})")
    return 0
