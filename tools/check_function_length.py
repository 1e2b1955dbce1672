"""List every hand-written function longer than 60 lines; exit 1 if there is one.

A function's length is the number of source lines from its ``def`` line (decorators not
counted) to its last line, inclusive: docstring, comments and blank lines inside it count,
as they do for a reader scrolling through it. A nested function counts towards the
function around it and is measured on its own as well. ``make lint`` runs this over
``sctd``, ``services`` and ``sim``; ``sim/canbus/_codec_generated.py`` is skipped by name
(the generated frame codec, unrolled on purpose, ``docs/architecture.md``).

Usage: ``python tools/check_function_length.py [PATH ...]`` (files or folders; the three
packages by default). Prints ``file:line name length`` for each function over the limit.
"""

from __future__ import annotations

import ast
import os
import sys
from collections.abc import Iterator
from pathlib import Path

LIMIT = 60
REPO = Path(__file__).resolve().parents[1]
ROOTS = ("sctd", "services", "sim")
GENERATED = frozenset({Path("sim/canbus/_codec_generated.py")})  # relative to the repository


def function_lengths(source: str) -> Iterator[tuple[int, str, int]]:
    """Yield ``(line, qualified name, length)`` for every function in ``source``, nested
    ones included (``Class.method``, ``outer.inner``)."""

    def visit(node: ast.AST, prefix: str) -> Iterator[tuple[int, str, int]]:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                assert child.end_lineno is not None
                yield child.lineno, f"{prefix}{child.name}", child.end_lineno - child.lineno + 1
                yield from visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                yield from visit(child, f"{prefix}{child.name}.")
            else:
                yield from visit(child, prefix)

    yield from visit(ast.parse(source), "")


def python_files(paths: list[Path]) -> Iterator[Path]:
    """The ``.py`` files under ``paths`` in sorted order, the generated codec left out."""
    skipped = {(REPO / generated).resolve() for generated in GENERATED}
    for path in paths:
        files = sorted(path.rglob("*.py")) if path.is_dir() else [path]
        for file in files:
            if file.resolve() not in skipped:
                yield file


def too_long(paths: list[Path], limit: int = LIMIT) -> list[str]:
    """``file:line name length`` for each function in ``paths`` over ``limit`` lines."""
    return [
        f"{file}:{line} {name} {length}"
        for file in python_files(paths)
        for line, name, length in function_lengths(file.read_text(encoding="utf-8"))
        if length > limit
    ]


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    paths = [Path(arg) for arg in args] or [Path(os.path.relpath(REPO / root)) for root in ROOTS]
    found = too_long(paths)
    for row in found:
        print(row)
    if found:
        print(f"{len(found)} function(s) over {LIMIT} lines", file=sys.stderr)
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
