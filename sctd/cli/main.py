"""``sctd``: learn Shared Control Templates from demonstrations and run them."""

from __future__ import annotations

import argparse
import sys

from . import demo as demo_cmd
from . import run as run_cmd
from . import sim as sim_cmd


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="sctd", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("run", help="run a skill: the fixed-rate daemon")
    run_cmd.add_run_arguments(p)
    p.set_defaults(func=run_cmd.main_run)

    p = sub.add_parser("inspect", help="validate a skill and show its structure")
    run_cmd.add_inspect_arguments(p)
    p.set_defaults(func=run_cmd.main_inspect)

    p = sub.add_parser("swap", help="hot-swap a skill into the running daemon")
    run_cmd.add_swap_arguments(p)
    p.set_defaults(func=run_cmd.main_swap)

    p = sub.add_parser("demo", help="run a skill end to end on this machine (daemon, robot, user)")
    demo_cmd.add_demo_arguments(p)
    p.set_defaults(func=demo_cmd.main_demo)

    from . import learn as learn_cli

    p = sub.add_parser("learn", help="learn a skill from a folder of demonstrations")
    learn_cli.add_learn_arguments(p)
    p.set_defaults(func=learn_cli.main_learn)

    p = sub.add_parser("dtw", help="dynamic time warping distance between two demonstrations")
    learn_cli.add_dtw_arguments(p)
    p.set_defaults(func=learn_cli.main_dtw)

    from . import eval as eval_cmd

    p = sub.add_parser("eval", help="measure a skill's assistance with the simulated user "
                                    "(success, time, effort; lockstep or real time)")
    eval_cmd.add_eval_arguments(p)
    p.set_defaults(func=eval_cmd.main_eval)

    p = sub.add_parser("sim", help="the Pinocchio simulator as a real-time Zenoh service")
    sim_cmd.add_sim_arguments(p)
    p.set_defaults(func=sim_cmd.main_sim)

    p = sub.add_parser("record", help="record a demonstration (ee in the task object's frame) as CSV")
    sim_cmd.add_record_arguments(p)
    p.set_defaults(func=sim_cmd.main_record)

    bench = sub.add_parser("bench", help="benchmarks that print figures")
    bsub = bench.add_subparsers(dest="bench", required=True, metavar="BENCH")
    from ..bench import latency as runtime_bench

    p = bsub.add_parser("latency", help="daemon tick timing and input->target latency vs a Zenoh echo")
    runtime_bench.add_latency_arguments(p)
    p.set_defaults(func=runtime_bench.main_latency)

    from ..bench import robustness

    p = bsub.add_parser("robustness", help="the daemon next to the sim under floods, bad bundles, "
                                           "swaps and a jumping state")
    robustness.add_robustness_arguments(p)
    p.set_defaults(func=robustness.main_robustness)

    from . import fuzz

    p = bsub.add_parser("fuzz", help="coverage-guided fuzzing of every decoder, the bundle unpacker and "
                                     "the skill loader (atheris)")
    fuzz.add_fuzz_arguments(p)
    p.set_defaults(func=fuzz.main_fuzz)

    from ..bench import learn as learn_bench

    p = bsub.add_parser("learn", help="learning figures on generated demonstrations (accuracy, "
                        "centre error, directions, time, graph-cut energy)")
    learn_bench.add_bench_learn_arguments(p)
    p.set_defaults(func=learn_bench.main_bench_learn)

    p = bsub.add_parser("sim", help="simulator real-time factor, step response and tracking")
    sim_cmd.add_bench_sim_arguments(p)
    p.set_defaults(func=sim_cmd.main_bench_sim)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
