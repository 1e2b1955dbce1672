"""sctd.cli.options: argparse flags derived from dataclass fields."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

import pytest

from sctd.cli.options import add_arguments, flag_name, from_namespace


@dataclass(frozen=True)
class Example:
    rate: float = field(default=1.5, metadata={"help": "ticks per second"})
    random_state: int | None = field(default=0, metadata={"help": "seed", "flag": "--seed",
                                                           "metavar": "SEED"})
    mode: str = field(default="a", metadata={"help": "mode", "choices": ("a", "b")})
    despike: bool = field(default=True, metadata={"help": "keep spikes", "flag": "--no-despike"})
    verbose: bool = field(default=False, metadata={"help": "say more"})
    hidden: int = 7  # no help: no flag


def _parser(**kwargs) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser()
    add_arguments(p, Example, **kwargs)
    return p


def test_defaults_round_trip():
    assert from_namespace(Example, _parser().parse_args([])) == Example()


def test_flags_types_and_switches():
    ns = _parser().parse_args(["--rate", "2", "--seed", "4", "--mode", "b", "--no-despike",
                               "--verbose"])
    assert from_namespace(Example, ns) == Example(2.0, 4, "b", False, True)
    assert isinstance(ns.rate, float) and isinstance(ns.random_state, int)
    with pytest.raises(SystemExit):
        _parser().parse_args(["--mode", "c"])
    with pytest.raises(SystemExit):
        _parser().parse_args(["--hidden", "1"])


def test_names_help_and_selection():
    fields = {f.name: f for f in Example.__dataclass_fields__.values()}
    assert flag_name(fields["rate"]) == "--rate" and flag_name(fields["random_state"]) == "--seed"
    text = _parser().format_help()
    assert "--seed SEED" in text and "ticks per second" in text
    only = _parser(only=("rate",)).parse_args([])
    assert vars(only) == {"rate": 1.5}
    assert "random_state" not in vars(_parser(exclude=("random_state",)).parse_args([]))
    with pytest.raises(TypeError, match="hidden"):
        _parser(only=("hidden",))
