"""``sctd sim``, ``sctd record`` and ``sctd bench sim``: thin wrappers over ``sctd_sim``.

The simulator package (Pinocchio, python-can, cantools) is imported only when one of
these commands runs, so the rest of the CLI starts without it.
"""

from __future__ import annotations

import argparse
import json
import sys

from ..runtime.codec import DEFAULT_ROBOT
from ..runtime.zsession import add_zenoh_arguments


def add_sim_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``sctd sim`` (also ``python -m sctd_sim.service``)."""
    p.add_argument("--scene", default="pour", choices=("pour", "drawer"),
                   help="task scene (default %(default)s)")
    p.add_argument("--robot", default=DEFAULT_ROBOT, help="key prefix sctd/<robot> (default %(default)s)")
    p.add_argument("--trial-seed", type=int, default=None, metavar="N",
                   help="start from the seeded random start N of an evaluation trial (hand within "
                        "+-10 cm and +-15 deg of yaw of the scene's start, the object within +-5 cm)")
    p.add_argument("--rate", type=float, default=1000.0,
                   help="simulation cycle rate, Hz (default %(default)s)")
    p.add_argument("--state-rate", type=float, default=1000.0,
                   help="state publication rate, Hz, at most --rate (default %(default)s)")
    p.add_argument("--object-rate", type=float, default=50.0,
                   help="objects rate, Hz (default %(default)s)")
    p.add_argument("--scene-rate", type=float, default=10.0,
                   help="scene key (task outcome, health) rate, Hz (default %(default)s)")
    p.add_argument("--faults", default="", metavar="SPEC",
                   help="joint-bus faults, e.g. drop=0.01,corrupt=0.001,delay=0.002 "
                        "(also duplicate, delay_rate, bus_off, tx=0/1, rx=0/1, seed)")
    p.add_argument("--can-interface", choices=("virtual", "socketcan", "auto"), default="virtual",
                   help="joint bus: python-can's in-process virtual bus (default), a socketcan "
                        "interface such as vcan0, or auto (socketcan when --can-channel exists)")
    p.add_argument("--can-channel", default=None,
                   help="socketcan interface name (default vcan0 for socketcan/auto)")
    p.add_argument("--drive-timeout", type=float, default=0.01,
                   help="drive command timeout before it brakes, s (default %(default)s)")
    from sctd_sim.guard import add_limit_arguments

    add_limit_arguments(p)
    p.add_argument("--no-stamp-check", action="store_true",
                   help="do not refuse targets stamped before the simulator started (senders "
                        "with unsynchronised clocks)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--view", action="store_true",
                   help="live 3D view in a browser, served on 127.0.0.1 (needs viser: "
                        "pip install 'sctd[view]'; make setup installs it)")
    p.add_argument("--view-port", type=int, default=0, metavar="PORT",
                   help="port of the --view page on 127.0.0.1 (default 0: a free one; the URL "
                        "is printed)")
    p.add_argument("--json", action="store_true", help="print the final summary as JSON on stdout")
    add_zenoh_arguments(p)


def main_sim(args: argparse.Namespace) -> int:
    from sctd_sim.service import run

    return run(args)


def add_record_arguments(p: argparse.ArgumentParser) -> None:
    """The flags of ``sctd record`` (also ``python -m sctd_sim.record``)."""
    p.add_argument("--out", required=True, metavar="DIR",
                   help="folder of demonstrations; writes the next free demo_NNN.csv")
    p.add_argument("--object", default=None, metavar="NAME",
                   help="task object whose frame the trajectory is expressed in "
                        "(default: the task object the simulator announces on the scene key)")
    p.add_argument("--robot", default=DEFAULT_ROBOT, help="key prefix sctd/<robot> (default %(default)s)")
    p.add_argument("--rate", type=float, default=100.0, help="sampling rate, Hz (default %(default)s)")
    p.add_argument("--min-distance", type=float, default=0.0, metavar="M",
                   help="skip samples closer than this (m, ee position) to the last row (default 0)")
    p.add_argument("--duration", type=float, default=None,
                   help="record this many seconds (default: until SIGINT/SIGTERM)")
    p.add_argument("--wait", type=float, default=10.0,
                   help="give up when no state/object arrives within this many seconds (default %(default)s)")
    add_zenoh_arguments(p)


def main_record(args: argparse.Namespace) -> int:
    from sctd_sim.record import run

    return run(args)


def add_bench_sim_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seconds", type=float, default=3.0,
                   help="simulated seconds of the real-time-factor run (default %(default)s)")
    p.add_argument("--rate", type=float, default=1000.0, help="cycle rate, Hz (default %(default)s)")
    p.add_argument("--scene", choices=("pour", "drawer"), default=None,
                   help="measure the step (5 cm along world x) and tracking in this scene, with "
                        "its load, instead of the empty-workspace figures")
    p.add_argument("--json", action="store_true", help="print the figures as JSON")


def main_bench_sim(args: argparse.Namespace) -> int:
    from sctd_sim.bench import format_report, run_bench

    if args.seconds <= 0 or args.rate <= 0:
        print("sctd bench sim: --seconds and --rate must be positive", file=sys.stderr)
        return 2
    if args.scene is not None:
        from sctd_sim.bench import format_scene_report, run_scene_bench

        result = run_scene_bench(args.scene, args.rate)
        print(json.dumps(result, default=float) if args.json else format_scene_report(result))
        return 0
    result = run_bench(args.seconds, args.rate)
    if args.json:
        print(json.dumps(result, default=float))
    else:
        print(format_report(result))
    return 0
