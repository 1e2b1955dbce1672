"""How every ``sctd`` command reports a problem and how it exits.

One style everywhere: ``sctd <command>: <file>: <field>: <problem>`` on stderr (the
file and field parts when there are some: a skill loader error already reads
``<file>: <field>: <problem>``), and one exit code per kind of ending:

====  ==========================================================================
0     done
1     the job ran and did not succeed (a demo whose task failed, a daemon that
      stopped on an error, a benchmark whose criteria are not met)
2     bad arguments or bad input (an unknown flag, a malformed skill, a missing
      file): nothing was started, or it was stopped before it moved anything
3     stopped on request, but a resource did not close within its bound and the
      process exited without it (``sctd router``: its Zenoh session, after 2 s)
====  ==========================================================================

Every ``--help`` lists 0, 1 and 2; a command that can also end with 3 says so in its own.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any, NoReturn

EXIT_OK = 0
EXIT_FAILED = 1
EXIT_USAGE = 2
EXIT_FORCED = 3

EXIT_CODES = ("exit codes: 0 done; 1 the job ran and did not succeed; "
              "2 bad arguments or input (nothing was started)")


def fail(command: str, problem: str, code: int = EXIT_USAGE) -> int:
    """Print ``sctd <command>: <problem>`` on stderr and return ``code`` (default 2)."""
    print(f"sctd {command}: {problem}", file=sys.stderr, flush=True)
    return code


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors read like every other ``sctd`` error
    (``sctd learn: --lambda: invalid float value: 'x'``) after the usage line, exit 2,
    and whose help ends with the exit codes."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("epilog", EXIT_CODES)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        self.print_usage(sys.stderr)
        self.exit(EXIT_USAGE, f"{self.prog}: {message}\n")
