"""A study folder: the writer API a runner calls, crash safety (a kill mid-write loses
at most the trial in progress, and readers say what they skipped), resume, and the
report built on what it holds; the CLI's errors for bad names, in-process."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from sctd.cli.main import main
from sctd_services.study import StudyError, StudyStore, check_answers, make_plan, read_trials
from sctd_services.study import store as store_module
from sctd_services.study.plan import Condition
from sctd_services.study.report import build_report, collect, markdown

A, T = Condition("a-vf", "skill", "assisted"), Condition("teleop", "teleop", "baseline")
GOOD = {"nasa_tlx": {"mental": 20, "physical": 10, "temporal": 35, "performance": 15, "effort": 40,
                     "frustration": 0}, "sus": [4, 2, 4, 1, 3, 2, 4, 2, 3, 2]}


def result(success=True, time_s=5.0, switches=0, effort=3.0):
    return {"outcome": "success" if success else "failure", "reason": "done" if success else "time limit",
            "time_s": time_s if success else None, "duration_s": time_s + 1.0, "mode_switches": switches,
            "effort": effort}


@pytest.fixture
def store(tmp_path):
    plan = make_plan([A, T], ["t"], participants=2, practice=1, trials=2, seed=0)
    return StudyStore.create(tmp_path / "study", plan)


def test_rows_and_logs_are_written_and_read_back(store):
    row = store.record_trial("P01", 0, result(), log={"trajectory": [[0.0, 1.0]]})
    assert row.practice and row.condition == "a-vf" and row.order == 1 and row.log == "logs/step-000.json"
    store.record_trial("P01", 1, result(False, switches=3))
    rows = store.trials("P01").rows
    assert [r.step for r in rows] == [0, 1]
    assert rows[1].success is False and rows[1].completion_time_s is None and rows[1].mode_switches == 3
    assert json.loads((store.directory / "P01" / rows[0].log).read_text())["trajectory"] == [[0.0, 1.0]]
    header = (store.directory / "P01" / "trials.csv").read_text().splitlines()[0]
    assert header.split(",") == list(store_module.COLUMNS)
    assert (store.directory / "plan.yaml").read_text().startswith("# sctd study plan")


def test_a_kill_mid_write_loses_only_that_trial(store, monkeypatch):
    """The append of step 1 is cut after half its bytes (as a kill would cut it): the
    reader keeps step 0, reports the cut line and skips it; resume asks for step 1 again;
    the next append cuts the fragment off first (keeping it in dropped.txt)."""
    store.record_trial("P01", 0, result())
    real_write = os.write

    def half_then_die(fd, data):
        real_write(fd, data[: len(data) // 2])
        raise KeyboardInterrupt  # the process dies here

    monkeypatch.setattr(store_module.os, "write", half_then_die)
    with pytest.raises(KeyboardInterrupt):
        store.record_trial("P01", 1, result(time_s=6.0))
    monkeypatch.setattr(store_module.os, "write", real_write)
    read = store.trials("P01")
    assert [r.step for r in read.rows] == [0]
    assert len(read.problems) == 1 and "line 3: cut short" in read.problems[0]
    assert "ignored" in read.problems[0]
    assert store.progress("P01").next_step.index == 1
    store.record_trial("P01", 1, result(time_s=6.0))
    read = store.trials("P01")
    assert [r.step for r in read.rows] == [0, 1] and not read.problems
    assert (store.directory / "P01" / "dropped.txt").read_text().startswith("1,P01,a-vf")


def test_a_malformed_row_is_skipped_and_reported(tmp_path, store):
    store.record_trial("P01", 0, result())
    path = store.directory / "P01" / "trials.csv"
    with open(path, "a") as fh:
        fh.write("garbage,row\n")
    read = read_trials(path)
    assert len(read.rows) == 1 and "line 3: not a trial row" in read.problems[0]
    (tmp_path / "other.csv").write_text("a,b\n1,2\n")
    with pytest.raises(StudyError, match="the header is not sctd's"):
        read_trials(tmp_path / "other.csv")


def test_progress_resumes_with_questionnaires_and_aborted_trials(store):
    p = store.progress("P01")
    assert (p.done, p.total, p.next_step.index, p.answers_due) == (0, 6, 0, None)
    for step in range(3):
        store.record_trial("P01", step, result())
    p = store.progress("P01")
    assert p.answers_due == ("a-vf", "t") and p.next_step.index == 3 and not p.finished
    store.record_answers("P01", "a-vf", "t", GOOD)
    store.mark_aborted("P01", 3, "safety stop", duration_s=2.0)
    p = store.progress("P01")
    assert p.answers_due is None and p.next_step.index == 3 and p.aborted == 1  # run again
    for step in range(3, 6):
        store.record_trial("P01", step, result())
    assert store.progress("P01").answers_due == ("teleop", "t")
    store.record_answers("P01", "teleop", "t", GOOD)
    assert store.progress("P01").finished
    assert [r.outcome for r in store.trials("P01").rows].count("aborted") == 1


def test_the_writer_refuses_what_is_not_in_the_plan(store):
    with pytest.raises(StudyError, match="participant P07: not in the plan"):
        store.record_trial("P07", 0, result())
    with pytest.raises(StudyError, match="looks like an e-mail address"):
        store.record_trial("jo@example.org", 0, result())
    with pytest.raises(StudyError, match="step 6: the plan has steps 0-5"):
        store.record_trial("P01", 6, result())
    bad = {**GOOD, "sus": [4, 2, 4, 1, 3, 2, 4, 2, 3, 0]}
    with pytest.raises(StudyError, match=r"participant P01, condition teleop, task t: sus.10: 0 is out of"):
        store.record_answers("P01", "teleop", "t", bad)
    with pytest.raises(StudyError, match="another plan"):
        StudyStore.create(store.directory, make_plan([A, T], ["t"], 4, 1, 2))


def _fill(store, pids, time_of):
    """Every planned trial of ``pids`` with completion times ``time_of(pid index, condition)``."""
    for i, pid in enumerate(pids):
        for step in store.plan.schedule(pid).steps():
            store.record_trial(pid, step.index, result(time_s=time_of(i, step.condition), effort=2.0 + i))
        for b in store.plan.schedule(pid).blocks:
            store.record_answers(pid, b.condition, b.task, GOOD)


def test_two_participants_get_a_report_that_says_the_test_is_underpowered(store):
    _fill(store, ["P01", "P02"], lambda i, c: 5.0 + i + (1.0 if c == "teleop" else 0.0))
    r = build_report(collect(store))
    json.dumps(r)  # plain data
    assert r["tables"]["t"]["a-vf"]["completion_time_s"]["median"] == pytest.approx(5.5)
    assert r["tables"]["t"]["teleop"]["successes"] == 4
    time = next(c for c in r["comparisons"] if c["metric"] == "completion_time_s")
    assert (time["a"], time["b"], time["n"]) == ("a-vf", "teleop", 2)
    assert time["note"].startswith("underpowered") and not time["significant"]
    sus = next(c for c in r["comparisons"] if c["metric"] == "sus_score")
    assert sus["note"].startswith("not possible")
    text = markdown(r)
    assert "| a-vf | 4/4 |" in text and "underpowered" in text and "## Task t" in text


def test_a_truncated_row_is_reported_in_the_report(store):
    _fill(store, ["P01"], lambda i, c: 5.0)
    with open(store.directory / "P01" / "trials.csv", "a") as fh:
        fh.write("6,P01,a-v")
    r = build_report(collect(store))
    assert any("cut short" in p for p in r["problems"])
    assert "Data problem (skipped)" in markdown(r)


def test_ten_participants_all_faster_is_significant_after_holm(tmp_path):
    plan = make_plan([A, T], ["t"], participants=10, practice=0, trials=2, seed=0)
    store = StudyStore.create(tmp_path / "s", plan)
    rng = np.random.default_rng(0)
    gains = rng.uniform(1.0, 3.0, 10)
    _fill(store, [s.participant for s in plan.participants],
          lambda i, c: 8.0 + (gains[i] if c == "teleop" else 0.0))
    r = build_report(collect(store))
    time = next(c for c in r["comparisons"] if c["metric"] == "completion_time_s")
    assert time["p"] == pytest.approx(2 / 2**10) and time["significant"] and time["r_rank_biserial"] == -1.0
    assert time["p_holm"] == pytest.approx(time["p"])  # one comparison in the metric's family


def test_the_figures_are_written(store, tmp_path):
    pytest.importorskip("matplotlib")
    from sctd_services.study.figures import write_figures

    _fill(store, ["P01", "P02"], lambda i, c: 5.0 + i)
    files = write_figures(build_report(collect(store)), tmp_path / "fig")
    assert sorted(f.name for f in files) == sorted(f"{m}.png" for m in (
        "success_rate", "completion_time_s", "mode_switches", "effort", "raw_tlx", "sus_score"))
    assert all(f.read_bytes()[:4] == b"\x89PNG" for f in files)


@pytest.mark.parametrize("argv, message", [
    (["--condition", "no_such_skill", "--condition", "teleop", "--task", "drawer"],
     "sctd study plan: --condition: no_such_skill: "),
    (["--condition", "drawer-vf", "--condition", "teleop", "--task", "no_such_task"],
     "sctd study plan: --task: no_such_task: "),
    (["--condition", "drawer-vf", "--condition", "drawer-vf", "--task", "drawer"],
     "--condition: drawer-vf is given twice"),
    (["--condition", "drawer-vf", "--condition", "teleop", "--task", "light_switch"],
     "--condition: drawer-vf: cannot run --task light_switch"),
])
def test_plan_names_the_flag_and_the_value(argv, message, capsys, tmp_path):
    assert main(["study", "plan", "--participants", "2", *argv, "--out", str(tmp_path / "p.yaml")]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "p.yaml").exists()


def test_plan_writes_the_file_and_warns(capsys, tmp_path):
    out = tmp_path / "p.yaml"
    assert main(["study", "plan", "--participants", "1", "--condition", "drawer-vf", "--condition", "teleop",
                 "--condition", "drawer", "--task", "drawer", "--out", str(out)]) == 0
    assert "warning: 1 participants for 6 sequences" in capsys.readouterr().err
    assert "# WARNING" in out.read_text()
    assert main(["study", "report", str(tmp_path / "none")]) == 2
    assert "no such study folder" in capsys.readouterr().err


def test_the_baseline_takes_the_assisted_conditions_limits():
    from sctd.task import find_task
    from sctd_services.study.conditions import block_of, resolve_condition

    plan = make_plan([resolve_condition("drawer-vf"), resolve_condition("teleop")], ["drawer"], 2, 0, 1)
    drawer = find_task("drawer")
    block = block_of(plan, "teleop", drawer)
    assert block.label.startswith("teleop (limits of drawer-vf")
    assisted = block_of(plan, "drawer-vf", drawer).skill
    assert block.skill is not None and assisted is not None and block.skill.limits == assisted.limits


def test_simulated_answers_are_valid_seeded_and_follow_the_trials():
    from sctd_services.study.simulate import simulated_answers
    from sctd_services.study.store import TrialRow

    def rows(success, duration):
        return [TrialRow(k, "P01", "a-vf", "t", 1, k + 1, False, k, success, "x", "", None, duration, 2, 5.0)
                for k in range(3)]

    easy = simulated_answers(rows(True, 6.0), 60.0, np.random.default_rng(1))
    hard = simulated_answers(rows(False, 60.0), 60.0, np.random.default_rng(1))
    assert easy == simulated_answers(rows(True, 6.0), 60.0, np.random.default_rng(1))
    scored_easy, scored_hard = check_answers(easy, "sim"), check_answers(hard, "sim")
    assert scored_easy["raw_tlx"] < scored_hard["raw_tlx"]
    assert scored_easy["sus_score"] > scored_hard["sus_score"]
