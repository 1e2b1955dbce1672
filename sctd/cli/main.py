"""``sctd``: learn Shared Control Templates from demonstrations and run them."""

from __future__ import annotations

import argparse
import sys

from . import run as run_cmd


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
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
