"""Benchmarks: the programs behind ``sctd bench ...``.

They sit on top of every other layer (application code, with the CLI): each one
starts processes or simulations, measures, and prints figures. The test suite never
asserts wall-clock times; these commands are where speed is shown.
"""

from __future__ import annotations

import argparse
import json
import signal
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sctd.app.errors import EXIT_FAILED, EXIT_OK, fail
from sctd.app.logs import log_folder


def _exit_on_sigterm(*_: object) -> None:
    raise SystemExit(143)  # unwinds the stack: the programs a benchmark started are stopped


def run_and_report(name: str, args: argparse.Namespace, run: Callable[[Path], dict[str, Any]],
                   print_report: Callable[[dict[str, Any]], None]) -> int:
    """Run a benchmark of processes (``run(logdir)``, logs in ``--logs`` or a temporary
    folder) and print its figures: JSON with ``--json``, else the report. A benchmark
    that could not run (RuntimeError) exits 1 with ``sctd bench <name>: <why>``."""
    logdir = log_folder(args.logs, "sctd-bench-")
    signal.signal(signal.SIGTERM, _exit_on_sigterm)  # its programs are stopped on the way out
    try:
        r = run(logdir)
    except RuntimeError as e:
        return fail(f"bench {name}", str(e), EXIT_FAILED)
    if args.json:
        print(json.dumps(r, indent=2))
    else:
        print_report(r)
    return EXIT_OK
