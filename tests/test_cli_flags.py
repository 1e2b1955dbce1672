"""Every ``sctd`` command takes the flags it took: the same names, destinations, defaults,
types, choices and actions, against the table in ``tests/data/cli_flags.json``.

The table guards refactorings of how flags are defined (a flag derived from a dataclass
field instead of written by hand must be the same flag). A deliberate change of a flag
rewrites it: ``python -m tests.test_cli_flags`` (and say why in the commit). Help texts
and metavars are left out: they may improve.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

import pytest

from sctd.cli.main import COMMANDS, build_parser
from tests.conftest import ROOT

TABLE = ROOT / "tests" / "data" / "cli_flags.json"


def _argvs() -> list[list[str]]:
    """The argv that builds each command's parser (a group: each of its subcommands;
    ``robot NAME``: each built-in driver's)."""
    return [[name, sub] for name, cmd in COMMANDS.items() for sub in cmd.group] + \
        [[name] for name, cmd in COMMANDS.items() if not cmd.group] + [["robot", d] for d in _drivers()]


def _type(a: argparse.Action) -> str:
    """The name of the flag's type; ``str`` for a value taken as given (argparse's
    default), whether said or not."""
    if a.type is None and a.nargs != 0:
        return "str"
    return getattr(a.type, "__name__", repr(a.type))


def _row(a: argparse.Action) -> dict[str, Any]:
    return {"options": sorted(a.option_strings), "dest": a.dest, "default": repr(a.default),
            "type": _type(a), "nargs": a.nargs, "const": repr(a.const),
            "choices": None if a.choices is None else [repr(c) for c in a.choices],
            "action": type(a).__name__, "required": a.required}


def flag_table(parser: argparse.ArgumentParser, prefix: str = "") -> dict[str, dict[str, Any]]:
    """One row per flag or positional of ``parser`` and of the subcommands it was built
    with, keyed by ``<command path> <first option or dest>``."""
    rows: dict[str, dict[str, Any]] = {}
    for a in parser._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, sub in a.choices.items():
                rows.update(flag_table(sub, f"{prefix} {name}".strip()))
        elif not isinstance(a, argparse._HelpAction):
            rows[f"{prefix} {a.option_strings[0] if a.option_strings else a.dest}".strip()] = _row(a)
    return rows


def _drivers() -> list[str]:
    from sctd.robots.registry import BUILTIN

    return list(BUILTIN)


def _parser(argv: list[str]) -> argparse.ArgumentParser:
    """The parser of ``sctd ARGV``; ``robot NAME``: the driver's (parsed after the name)."""
    if argv[0] == "robot" and len(argv) == 2:
        from sctd.robots.registry import get_driver
        from sctd_services.robots.service import driver_parser

        parser = argparse.ArgumentParser()
        parser.add_subparsers().add_parser("robot").add_subparsers().add_parser(
            argv[1], parents=[driver_parser(get_driver(argv[1]))], add_help=False)
        return parser
    return build_parser(argv)


def _own(rows: dict[str, dict[str, Any]], argv: list[str]) -> dict[str, dict[str, Any]]:
    """The rows of the command ``argv`` itself (not of ``robot``'s drivers under ``robot``)."""
    head = " ".join(argv) + " "
    deeper = tuple(" ".join(a) + " " for a in _argvs() if len(a) > len(argv) and a[:len(argv)] == argv)
    return {k: v for k, v in rows.items() if k.startswith(head) and not k.startswith(deeper)}


def _rows(argv: list[str]) -> dict[str, dict[str, Any]]:
    return _own(flag_table(_parser(argv)), argv)


def _table(argv: list[str]) -> dict[str, dict[str, Any]]:
    try:
        return _rows(argv)
    except (SystemExit, ModuleNotFoundError):  # the command's optional extra is not installed here
        pytest.skip(f"sctd {' '.join(argv)}: its extra is not installed")


@pytest.mark.parametrize("argv", _argvs(), ids=" ".join)
def test_every_command_takes_the_flags_it_took(argv):
    want = _own(json.loads(TABLE.read_text()), argv)
    got = _table(argv)
    assert sorted(got) == sorted(want), "flags added or removed (python -m tests.test_cli_flags rewrites)"
    for key in want:
        assert got[key] == want[key], key


def test_the_table_tells_a_changed_default():
    """The comparison can fail: a parser whose default moved gives another row."""
    p = argparse.ArgumentParser()
    p.add_argument("--rate", type=float, default=1.0)
    before = flag_table(p)
    p.set_defaults(rate=2.0)
    assert flag_table(p) != before


def _write() -> None:
    rows: dict[str, dict[str, Any]] = {}
    for argv in _argvs():
        rows.update(_rows(argv))
    TABLE.write_text(json.dumps(rows, indent=1, sort_keys=True) + "\n")
    print(f"{TABLE}: {len(rows)} flags", file=sys.stderr)


if __name__ == "__main__":
    _write()
