"""``sctd bench link`` without namespaces: the sweep's points and their selection, the
table's rows and where assistance stops helping, the hand's unintended motion, and the
arguments refused before anything starts. (One point end to end through the cluster:
``tests/test_bench_link_multihost.py``, slow.)"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from sctd.bench.link import (
    BASELINE,
    POINTS,
    Record,
    format_table,
    pending,
    run_link_bench,
    select_points,
    spill_of,
    stops_helping,
    summarise,
)
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


def _recorded(point, condition, seed, outcome="success", skill="pour"):
    return {"task": "pour", "point": point, "condition": condition, "skill": skill, "seed": seed,
            "outcome": outcome, "reason": "", "time_s": 15.0, "readings": {}, "sim_rtf": 1.0,
            "wander_m": 0.001}


def test_a_record_keeps_each_trial_as_it_ends_and_a_new_run_skips_them(tmp_path):
    """A sweep of hours stopped after any trial is taken up where it stopped: the file
    has every trial that ended, a new :class:`Record` of it reads them back, and
    :func:`pending` leaves exactly those out, in the sweep's order."""
    path = tmp_path / "sweep.jsonl"
    first = Record(path)
    conditions = [("assisted", "/x/pour.yaml"), (BASELINE, "/x/teleop-pour.yaml")]
    points = tuple(p for p in POINTS if p.name in ("clean", "robot-stall-2"))
    todo = pending("pour", points, conditions, 2, 5, first)
    assert [(p.name, c, s) for p, c, _, s in todo] == [
        ("clean", "assisted", 5), ("clean", "assisted", 6), ("clean", BASELINE, 5), ("clean", BASELINE, 6),
        ("robot-stall-2", "assisted", 5), ("robot-stall-2", "assisted", 6),
        ("robot-stall-2", BASELINE, 5), ("robot-stall-2", BASELINE, 6)]
    for p, c, _, s in todo[:3]:  # three trials ended, then the sweep was killed
        first.add(_recorded(p.name, c, s, skill="pour" if c == "assisted" else "teleop-pour"))
    assert len(path.read_text().splitlines()) == 3
    again = Record(path)
    again.check("pour", conditions)
    left = pending("pour", points, conditions, 2, 5, again)
    assert left == todo[3:]
    assert again.get(("pour", "clean", BASELINE, 5))["outcome"] == "success"
    # a bigger sweep over the same file runs only what is new
    assert len(pending("pour", points, conditions, 3, 5, again)) == 12 - 3


def test_a_record_of_another_skill_or_not_of_trials_is_refused_naming_the_line(tmp_path):
    import json

    path = tmp_path / "sweep.jsonl"
    path.write_text(json.dumps(_recorded("clean", "assisted", 0, skill="pour-vf")) + "\n")
    with pytest.raises(ValueError, match=r"pour assisted was recorded with the skill 'pour-vf', this run's "
                                         r"is 'pour': give another --record file"):
        Record(path).check("pour", [("assisted", "/skills/pour.yaml")])
    Record(path).check("drawer", [("assisted", "/skills/drawer.yaml")])  # another task's trials: no matter
    path.write_text(json.dumps(_recorded("clean", "assisted", 0)) + "\n{\"task\": \"pour\"}\n")
    with pytest.raises(ValueError, match=r"sweep.jsonl: line 2: not a trial of sctd bench link"):
        Record(path)
    path.write_text("\n" + json.dumps(_recorded("clean", "assisted", 0))[:-4] + "\n")
    with pytest.raises(ValueError, match=r"sweep.jsonl: line 2: not JSON"):
        Record(path)
    path.write_text(json.dumps({**_recorded("clean", "assisted", 0), "seed": "0"}) + "\n")
    with pytest.raises(ValueError, match=r"line 1: seed must be an integer, got '0'"):
        Record(path)


def test_a_sweep_whose_trials_are_all_recorded_starts_nothing_and_reports_them(tmp_path, monkeypatch):
    """Every trial of the selection in the record: no cluster is made (a Cluster would
    need root and namespaces), and the table is the record's, in the sweep's order."""
    import sctd.bench.link as link
    from sctd.task import find_task

    def no_cluster(*a, **k):
        raise AssertionError("a cluster was started for trials the record has")

    monkeypatch.setattr(link, "Cluster", no_cluster)
    task = find_task("pour")
    conditions = link.conditions_of(task, None, True, tmp_path / "skills")
    record = Record(tmp_path / "sweep.jsonl")
    for point in ("robot-delay-5", "clean"):  # recorded out of the sweep's order
        for cond, sk in conditions:
            for seed in (0, 1):
                record.add(_recorded(point, cond, seed, outcome="failure" if seed else "success",
                                     skill=Path(sk).stem))
    points = tuple(p for p in POINTS if p.name in ("clean", "robot-delay-5"))
    r = run_link_bench([task], None, points, 2, 0, tmp_path, True, Record(tmp_path / "sweep.jsonl"))
    assert r["recorded_before"] == 8 and len(r["trials"]) == 8
    assert [(row["point"], row["condition"], row["successes"], row["trials"]) for row in r["rows"]] == [
        ("clean", "assisted", 1, 2), ("clean", BASELINE, 1, 2),
        ("robot-delay-5", "assisted", 1, 2), ("robot-delay-5", BASELINE, 1, 2)]


def test_a_bad_record_exits_2_before_anything_starts(tmp_path, capsys):
    bad = tmp_path / "r.jsonl"
    bad.write_text("[1, 2]\n")
    assert main(["bench", "link", "--record", str(bad)]) == 2
    assert "r.jsonl: line 1: not a trial of sctd bench link" in capsys.readouterr().err


def test_the_figure_draws_each_point_and_condition_and_marks_where_assistance_stops_helping():
    from sctd.bench.linkfigure import figure

    trials = [_trial("clean", "assisted", "success", 15.0, wander=0.002),
              _trial("clean", BASELINE, "failure", None, wander=0.003),
              _trial("robot-delay-5", "assisted", "success", 18.0, wander=0.004),
              _trial("robot-delay-5", BASELINE, "success", 16.0, wander=0.001)]
    rows = summarise(trials)
    stops = stops_helping(rows)
    assert stops["pour"]["robot-delay"] == "robot-delay-5"
    fig = figure(rows, [p.name for p in POINTS], {p.name: p.kind for p in POINTS}, stops)
    success, time_s, wander = fig.axes
    heights = [b.get_height() for b in success.patches]  # assisted's bars, then the baseline's
    assert heights == [100.0, 100.0, 0.0, 100.0]
    times = [b.get_height() for b in time_s.patches]
    assert (times[0], times[1], times[3]) == (15.0, 18.0, 16.0)
    assert math.isnan(times[2])  # no time where nothing succeeded: no bar
    assert [b.get_height() for b in wander.patches] == pytest.approx([2.0, 4.0, 3.0, 1.0])
    assert [t.get_text() for t in success.get_xticklabels()] == ["clean", "robot-delay-5 *"]


def test_the_figure_is_written_from_a_record_and_a_bad_path_is_refused_first(tmp_path, monkeypatch, capsys):
    import sctd.bench.link as link
    from sctd.task import find_task

    monkeypatch.setattr(link, "Cluster", lambda *a, **k: pytest.fail("a cluster was started"))
    conditions = link.conditions_of(find_task("pour"), None, True, tmp_path / "skills")
    record = Record(tmp_path / "sweep.jsonl")
    for cond, sk in conditions:
        record.add(_recorded("clean", cond, 0, skill=Path(sk).stem))
    png = tmp_path / "link.png"
    args = ["bench", "link", "--task", "pour", "--points", "clean", "--trials", "1", "--record",
            str(tmp_path / "sweep.jsonl"), "--logs", str(tmp_path / "logs")]
    assert main([*args, "--figure", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "wrote" in capsys.readouterr().err
    assert main([*args, "--figure", str(tmp_path / "link.jpg")]) == 2
    assert "link.jpg: the file must end in .png, .svg, .pdf" in capsys.readouterr().err
    assert main([*args, "--figure", str(tmp_path / "nowhere" / "link.png")]) == 2
    assert "no folder" in capsys.readouterr().err
