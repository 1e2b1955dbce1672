"""``sctd sim``, ``sctd record`` and ``sctd bench sim``: the simulator service, the
recorder and the simulator benchmark as ``sctd`` commands.

The programs define their own flags, once, where they live
(:func:`sctd_sim.options.add_service_arguments` for ``python -m sctd_sim.service``,
:func:`sctd_services.record.add_arguments` for ``python -m sctd_services.record``);
these commands take the same. The simulator's heavy parts (Pinocchio, python-can,
cantools) are imported only when one of these commands runs, so the rest of the CLI
starts without them.
"""

from __future__ import annotations

import argparse
import json
import sys

from sctd_services import record
from sctd_sim.options import add_service_arguments


def add_sim_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``sctd sim`` (those of ``python -m sctd_sim.service``)."""
    add_service_arguments(p)


def main_sim(args: argparse.Namespace) -> int:
    from sctd_sim.service import run

    return run(args)


def add_record_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``sctd record`` (those of ``python -m sctd_services.record``)."""
    record.add_arguments(p)


def main_record(args: argparse.Namespace) -> int:
    return record.run(args)


def add_bench_sim_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``sctd bench sim`` (see :mod:`sctd.bench.sim`)."""
    p.add_argument("--seconds", type=float, default=3.0,
                   help="simulated seconds of the real-time-factor run (default %(default)s)")
    p.add_argument("--rate", type=float, default=1000.0, help="cycle rate, Hz (default %(default)s)")
    p.add_argument("--scene", choices=("pour", "drawer"), default=None,
                   help="measure the step (5 cm along world x) and tracking in this scene, with "
                        "its load, instead of the empty-workspace figures")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def main_bench_sim(args: argparse.Namespace) -> int:
    from ..bench.sim import format_report, format_scene_report, run_bench, run_scene_bench

    if args.seconds <= 0 or args.rate <= 0:
        print("sctd bench sim: --seconds and --rate must be positive", file=sys.stderr)
        return 2
    if args.scene is not None:
        result = run_scene_bench(args.scene, args.rate)
        print(json.dumps(result, default=float) if args.json else format_scene_report(result))
        return 0
    result = run_bench(args.seconds, args.rate)
    if args.json:
        print(json.dumps(result, default=float))
    else:
        print(format_report(result))
    return 0
