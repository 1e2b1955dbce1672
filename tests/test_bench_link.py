"""``sctd bench link`` without namespaces: the sweep's points and their selection, the
table's rows and where assistance stops helping, the hand's unintended motion, and the
arguments refused before anything starts. (One point end to end through the cluster:
``tests/test_bench_link_multihost.py``, slow.)"""

from __future__ import annotations

import pytest

from sctd.bench.link import BASELINE, POINTS, format_table, select_points, spill_of, stops_helping, summarise
from sctd.bench.linktrial import Wander, driven
from sctd.cli.main import main


def test_the_sweep_has_the_clean_links_and_each_fault_on_each_link():
    names = [p.name for p in POINTS]
    assert names[0] == "clean"
    for link in ("input", "robot"):
        assert [n for n in names if n.startswith(f"{link}-delay")] == \
            [f"{link}-delay-5", f"{link}-delay-20", f"{link}-delay-50"]
        assert [n for n in names if n.startswith(f"{link}-stall")] == [f"{link}-stall-0.2", f"{link}-stall-2"]
    delay = next(p for p in POINTS if p.name == "robot-delay-50")
    assert delay.fault.delay_ms == 50 and delay.fault.jitter == 0.2 and delay.kind == "robot-delay"
    stall = next(p for p in POINTS if p.name == "input-stall-2")
    assert stall.stall == 2.0 and stall.fault.delay_ms == 0 and stall.kind == "input-stall"
    # the losses, over UDP (a plain cluster), after their reference: the same link losing none
    assert [(p.name, p.kind, p.fault.loss) for p in POINTS if p.udp] == \
        [("input-udp", "input-udp", 0.0), ("input-loss-1", "input-loss", 0.01),
         ("input-loss-5", "input-loss", 0.05)]
    assert not any(p.udp for p in POINTS if not p.name.startswith(("input-udp", "input-loss")))


def test_points_are_selected_by_name_in_the_sweeps_order_and_an_unknown_one_is_named():
    assert [p.name for p in select_points("robot-stall-2, clean")] == ["clean", "robot-stall-2"]
    assert select_points(None) == POINTS
    with pytest.raises(ValueError, match="unknown input-delay-7; the points are clean, input-delay-5"):
        select_points("clean,input-delay-7")
    with pytest.raises(ValueError, match=r"unknown \(none given\)"):
        select_points(" , ")


def _trial(point, condition, outcome, time_s, seed=0, spilled=0.0, wander=0.001, disarms=0, centred=0):
    return {"task": "pour", "point": point, "condition": condition, "seed": seed, "outcome": outcome,
            "reason": "", "time_s": time_s, "readings": {"bottle.spilled": spilled, "bottle.flowing": False},
            "sim_rtf": 0.9, "wander_m": wander, "stale_disarms": disarms, "centred": centred}


def test_rows_summarise_each_point_and_condition():
    trials = [_trial("clean", "assisted", "success", 20.0, spilled=0.0, wander=0.002),
              _trial("clean", "assisted", "success", 24.0, seed=1, spilled=0.01, wander=0.004, disarms=1,
                     centred=1),
              _trial("clean", "assisted", "failure", None, seed=2, wander=0.003),
              _trial("clean", BASELINE, "success", 30.0)]
    rows = summarise(trials)
    assert [(r["point"], r["condition"]) for r in rows] == [("clean", "assisted"), ("clean", BASELINE)]
    a = rows[0]
    assert (a["trials"], a["successes"], a["time_s"], a["spill"], a["wander_mm"]) == (3, 2, 22.0, 0.01, 4.0)
    assert (a["stale_disarms"], a["centred"]) == (1, 1)
    lines = format_table(rows)
    assert len(lines) == 3 and "   2/3" in lines[1] and "0.010" in lines[1] and "22.0" in lines[1]
    assert spill_of({"bottle.flowing": True}) is None
    assert spill_of({"a.spilled": 0.5, "b.spilled": 0.2}) == 0.5


def test_assistance_stops_helping_at_the_first_point_where_it_is_no_better_than_the_baseline():
    def both(point, a, b):  # (outcome, time) of each condition
        return [_trial(point, "assisted", *a), _trial(point, BASELINE, *b)]
    trials = (both("clean", ("success", 20.0), ("success", 30.0))
              + both("input-delay-5", ("success", 21.0), ("success", 30.0))
              + both("input-delay-20", ("success", 31.0), ("success", 30.0))  # slower: stops here
              + both("input-delay-50", ("failure", None), ("success", 33.0))
              + both("robot-stall-2", ("success", 25.0), ("failure", None)))  # helps: more successes
    got = stops_helping(summarise(trials))
    assert got == {"pour": {"clean": None, "input-delay": "input-delay-20", "robot-stall": None}}


def test_the_hands_unintended_motion_counts_only_while_no_device_drives():
    w = Wander()
    w.add((0.0, 0.0, 0.0), driven=True)
    w.add((0.1, 0.0, 0.0), driven=True)  # driven: any motion is the person's
    w.add((0.1, 0.0, 0.0), driven=False)  # a span begins here
    w.add((0.1, 0.003, 0.0), driven=False)
    w.add((0.1, 0.004, 0.0), driven=False)
    w.add((0.3, 0.0, 0.0), driven=True)
    w.add((0.3, 0.0, 0.0), driven=False)  # a new span, from here
    w.add((0.3, 0.0, 0.002), driven=False)
    assert w.worst == pytest.approx(0.004)
    assert driven({}) and driven({"input": {"owner": "pad"}}) and not driven({"input": {"owner": None}})


def test_bad_arguments_exit_2_before_anything_starts(capsys):
    assert main(["bench", "link", "--points", "clean,nowhere"]) == 2
    assert "unknown nowhere" in capsys.readouterr().err
    assert main(["bench", "link", "--task", "no-such-task"]) == 2
    assert main(["bench", "link", "--trials", "0"]) == 2
    assert "--trials: at least 1" in capsys.readouterr().err
