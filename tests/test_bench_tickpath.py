"""The tick path in one process (sctd.bench.tickpath): the daemon's tick thread's own work
from bytes, as ``sctd bench cost`` times it in each tree."""

from __future__ import annotations

import json
import math

import pytest

from sctd.bench import tickpath
from sctd.cli.main import main


@pytest.mark.parametrize("full, mode", [(True, "running"), (False, "stopped")])
def test_the_person_drives_every_measured_tick_or_none(full, mode):
    """Full input with the deadman held steps the target on every measured tick (the arm
    following it); centred sticks step none; both cost some finite CPU."""
    r = tickpath.measure("pour", "pour", full, 200, 0.0)
    assert r["modes"] == {mode: 200}
    assert r["path"] == "tick" and r["input"] == ("full" if full else "zero")
    assert math.isfinite(r["us_per_tick"]) and r["us_per_tick"] > 0.0


def test_the_floors_path_the_control_and_a_sleep_before_each_tick_are_measured_too():
    for path in ("floor", "loop"):
        r = tickpath.measure("pour", "pour", False, 100, 0.0, path=path)
        assert r["path"] == path and r["modes"] == {} and r["us_per_tick"] > 0.0
    slept = tickpath.measure("pour", "pour", False, 100, 2e-4)
    assert slept["sleep_us"] == 200.0 and slept["modes"] == {"stopped": 100}


def test_split_times_each_part_and_the_mappings_only_under_a_push():
    """``--split``: every part of the path is timed; centred sticks never ask the skill's
    mappings for a step (its command part stays 0), full input asks on every tick."""
    zero, full = (tickpath.measure("pour-vf", "pour", f, 200, 0.0, split=True) for f in (False, True))
    for r in (zero, full):
        assert list(r["split"]) == list(tickpath.SPLIT)
        assert all(math.isfinite(v) and v >= 0.0 for v in r["split"].values()), r["split"]
        assert r["split"]["receive"] > 0.0 and r["split"]["controller"] > 0.0 and r["split"]["encode"] > 0.0
    assert zero["split"]["command"] == 0.0 and full["split"]["command"] > 0.0
    assert "split" not in tickpath.measure("pour", "pour", False, 50, 0.0)


def test_the_probe_prints_one_row_per_input_and_sleep_in_order(capsys):
    assert tickpath.main(["--skill", "pour", "--task", "pour", "--ticks", "50", "--inputs", "full,zero",
                          "--sleeps-us", "0,100"]) == 0
    rows = json.loads(capsys.readouterr().out)["rows"]
    assert [(r["input"], r["sleep_us"]) for r in rows] == [
        ("full", 0.0), ("full", 100.0), ("zero", 0.0), ("zero", 100.0)]


@pytest.mark.parametrize("args, message", [
    (["--sleeps-us", "0,x"], "'0,x': comma-separated numbers"),
    (["--inputs", "half"], "--inputs zero and/or full"),
    (["--ticks", "0"], "--ticks must be >= 1"),
    (["--path", "floor", "--split"], "--split times the tick path's parts, not --path floor's"),
])
def test_bad_arguments_are_refused_by_name(capsys, args, message):
    with pytest.raises(SystemExit):
        tickpath.main(["--skill", "pour", "--task", "pour", *args])
    assert message in capsys.readouterr().err


def test_bench_cost_refuses_a_negative_tick_count(capsys):
    assert main(["bench", "cost", "--tick-ticks", "-1"]) == 2
    assert "--tick-ticks >= 0" in capsys.readouterr().err


def test_the_report_gives_each_skill_input_and_tree_back_to_back_and_after_the_sleep(capsys):
    from sctd.bench.cost import _print_tick_path

    rows = [{"tree": t, "skill": s, "input": "zero", "path": "tick", "sleep_us": us, "us_per_tick": v,
             "modes": {}} for t, s, us, v in [("this", "pour", 0.0, 10.0), ("this", "pour", 900.0, 25.0),
                                                ("this", "floor", 0.0, 4.0), ("this", "floor", 900.0, 6.0),
                                                ("this", "loop", 0.0, 8.0), ("this", "loop", 900.0, 8.0)]]
    _print_tick_path(rows)
    out = capsys.readouterr().out.splitlines()
    assert out[1].split() == ["pour", "zero", "this", "10.0", "/", "25.0", "(2.5x)"]
    assert out[2].split() == ["floor's", "path", "this", "4.0", "/", "6.0", "(1.5x)"]
    assert out[3].split() == ["control:", "a", "tight", "loop", "this", "8.0", "/", "8.0", "(1.0x)"]
