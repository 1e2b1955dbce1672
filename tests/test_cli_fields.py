"""A flag that sets a field of the options a command builds comes from that field
(:func:`sctd.app.options.add_arguments`): its name, default, type, help, choices and
metavar are defined once, in the field, and never again by hand beside it.

For each main command, :data:`OPTIONS` names the dataclasses it builds from its flags;
every flag whose destination is a field name of one of them must have been made from
such a field (:func:`~sctd.app.options.field_of`), unless :data:`BY_HAND` says why not.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Iterator

import pytest

from sctd.app.options import add_arguments, field_of
from sctd.cli.main import build_parser
from sctd.learn import LinearIMLearner, Preprocessing, SkillOptions, VectorFieldLearner, VectorFieldOptions
from sctd.runtime.controller import RuntimeConfig
from sctd_services.eval.trial import TaskSpec
from sctd_services.teach.demonstrator import TeachOptions
from sctd_sim.guard import TargetLimits
from sctd_sim.options import SimSettings

# The command (``robot NAME``: the driver's parser) -> the dataclasses it builds from flags.
OPTIONS: dict[str, tuple[type, ...]] = {
    "run": (RuntimeConfig,),
    "learn": (Preprocessing, LinearIMLearner, VectorFieldLearner, VectorFieldOptions, SkillOptions),
    "teach": (TeachOptions,),
    "eval": (TaskSpec,),
    "sim": (SimSettings, TargetLimits),
    "robot sim": (TargetLimits,),
    "robot kinematic": (TargetLimits,),
    "robot franky": (TargetLimits,),  # and FrankyOptions, below (its extra may be missing)
}

# (command, destination) -> why that flag is written by hand although a field has its name.
BY_HAND = {
    ("teach", "task"): "the one --task flag of every command (add_task_argument: its help, the "
                       "default from sctd/app/defaults.yaml, the deprecated --scene alias)",
    ("eval", "task"): "the one --task flag's name (TASK_HELP); sctd eval resolves it to the task "
                      "whose name or file TaskSpec.of then keeps",
}


def hand_written(parser: argparse.ArgumentParser, classes: tuple[type, ...]) -> Iterator[str]:
    """The destinations of ``parser``'s flags that set a field of ``classes`` but were
    not made from a field of theirs."""
    names = {f.name for cls in classes for f in dataclasses.fields(cls)}
    for a in parser._actions:
        made = field_of(a)
        if a.dest in names and not (made is not None and made[0] in classes and made[1] == a.dest):
            yield a.dest


def _parser(command: str) -> argparse.ArgumentParser:
    argv = command.split()
    if argv[0] == "robot":
        from sctd.robots.registry import get_driver
        from sctd_services.robots.service import driver_parser

        try:
            return driver_parser(get_driver(argv[1]))
        except ModuleNotFoundError:
            pytest.skip(f"{command}: its library is not installed")
    parser = build_parser(argv)
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[argv[0]]


def _classes(command: str) -> tuple[type, ...]:
    if command == "robot franky":
        try:
            from sctd_services.robots.franky import FrankyOptions
        except ModuleNotFoundError:
            pytest.skip("franky is not installed")
        return (*OPTIONS[command], FrankyOptions)
    return OPTIONS[command]


@pytest.mark.parametrize("command", sorted(OPTIONS))
def test_flags_that_set_a_field_come_from_it(command):
    found = [d for d in hand_written(_parser(command), _classes(command)) if (command, d) not in BY_HAND]
    assert not found, (f"sctd {command}: flags written by hand for fields of its options {found}: give "
                       "the field help metadata and add it with sctd.app.options.add_arguments")


def test_a_flag_written_by_hand_is_found():
    """The check can fail: a flag with a field's name, written by hand, is reported;
    the one made from the field, and flags of no field, are not."""

    @dataclasses.dataclass
    class Opts:
        rate: float = dataclasses.field(default=1.0, metadata={"help": "Hz"})
        depth: int = dataclasses.field(default=2, metadata={"help": "levels"})

    p = argparse.ArgumentParser()
    add_arguments(p, Opts, only=("rate",))
    p.add_argument("--depth", type=int, default=2, help="levels")
    p.add_argument("--verbose", action="store_true")
    assert list(hand_written(p, (Opts,))) == ["depth"]

    @dataclasses.dataclass
    class Other:
        depth: int = dataclasses.field(default=2, metadata={"help": "levels"})

    q = argparse.ArgumentParser()
    add_arguments(q, Other)  # made from a field, but of a class the command does not build
    assert list(hand_written(q, (Opts,))) == ["depth"]
