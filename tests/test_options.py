"""sctd.app.options: argparse flags derived from dataclass fields."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

import pytest

from sctd.app.options import add_arguments, add_robot_argument, check_ranges, flag_name, from_namespace
from sctd.wire import DEFAULT_ROBOT


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


def test_prefixed_destinations_and_help_round_trip():
    """A device's settings kept apart from other flags (``emg_band_low_hz``) and
    built back with the same prefix."""
    p = argparse.ArgumentParser()
    add_arguments(p, Example, dest_prefix="dev_", help_prefix="--calibrate: ", show_default=True)
    ns = p.parse_args(["--rate", "2.5", "--seed", "3", "--verbose"])
    assert ns.dev_rate == 2.5 and not hasattr(ns, "rate")
    assert from_namespace(Example, ns, dest_prefix="dev_") == Example(rate=2.5, random_state=3, verbose=True)
    assert "--calibrate: ticks per second (default 1.5)" in " ".join(p.format_help().split())


@dataclass(frozen=True)
class Limits:
    speed: float = field(default=1.0, metadata={"help": "m/s"})
    deadband: float = field(default=0.0, metadata={"help": "fraction (0: none)"})
    count: int = 3


@pytest.mark.parametrize(("kw", "problem"), [({"speed": 0.0}, "--speed: must be > 0"),
                                             ({"speed": float("nan")}, "--speed: must be > 0"),
                                             ({"deadband": -0.1}, "--deadband: must be >= 0")])
def test_check_ranges_names_the_flag(kw, problem):
    check_ranges(Limits(), zero_allowed={"deadband"})  # the defaults pass
    with pytest.raises(ValueError, match=problem):
        check_ranges(Limits(**kw), zero_allowed={"deadband"})
    with pytest.raises(ValueError, match="--deadband: must be > 0"):
        check_ranges(Limits())  # 0 is allowed only where said


def test_one_robot_flag_for_every_program():
    p = argparse.ArgumentParser()
    add_robot_argument(p)
    assert p.parse_args([]).robot == DEFAULT_ROBOT and p.parse_args(["--robot", "r2"]).robot == "r2"
    q = argparse.ArgumentParser()
    add_robot_argument(q, None, "replay under this robot's prefix")
    assert q.parse_args([]).robot is None and "replay under" in q.format_help()


def test_the_robot_flag_is_defined_in_one_place():
    """Every program takes ``--robot`` from :func:`add_robot_argument`: no second
    definition (with its own default or help) anywhere in the package."""
    from tests.conftest import ROOT

    found = [str(f.relative_to(ROOT)) for folder in ("sctd", "services", "sim")
             for f in (ROOT / folder).rglob("*.py") if 'add_argument("--robot"' in f.read_text()]
    assert found == ["sctd/app/options.py"], found
