"""The runner for people without its processes: what the page is shown at each point of a
participant's plan (instructions, practice, measured trials, questionnaires, done), the
pause, a closed page's and a killed runner's trial marked aborted and run again, answers
out of range refused with nothing stored, and the lock on the study folder; in-process."""

from __future__ import annotations

import json
import os

import pytest

from sctd.cli.main import main
from sctd_services.study import StudyError, StudyStore, make_plan, plan_to_yaml
from sctd_services.study.lock import LOCK_FILE, RunnerLock
from sctd_services.study.plan import Condition
from sctd_services.study.runner import INTERRUPTED, RUNNING_FILE, StudyRunner, rig_folder

A, T = Condition("a-vf", "skill", "assisted"), Condition("teleop", "teleop", "baseline")
GOOD = {"nasa_tlx": {"mental": 20, "physical": 10, "temporal": 35, "performance": 15, "effort": 40,
                     "frustration": 0}, "sus": [4, 2, 4, 1, 3, 2, 4, 2, 3, 2]}
SUCCESS = {"outcome": "success", "reason": "opened", "time_s": 4.0, "duration_s": 5.0, "mode_switches": 1,
           "effort": 3.0}


@pytest.fixture
def store(tmp_path):
    plan = make_plan([A, T], ["t"], participants=2, practice=1, trials=1, seed=0)
    return StudyStore.create(tmp_path / "study", plan)


def runner(store, pid="P01"):
    return StudyRunner(store, pid, {"t": "Open the thing"})


def kind(r):
    return r.screen()["kind"]


def run_trial(r, result=SUCCESS):
    step = r.start()
    assert not isinstance(step, str), step
    assert kind(r) == "running" and (r.folder / RUNNING_FILE).exists()
    r.finish(result, {"result": result})
    assert not (r.folder / RUNNING_FILE).exists()
    return step


def test_the_page_leads_through_the_plan(store):
    r = runner(store)
    seen = []
    while kind(r) != "done":
        s = r.screen()
        seen.append(s["kind"])
        if s["kind"] == "instructions":
            assert any("deadman" in p for p in s["paragraphs"]) and "Open the thing" in s["paragraphs"][0]
            assert r.start() == "not now: the page shows instructions"
            assert r.next() is None
        elif s["kind"] == "ready":
            step = run_trial(r)
            assert (step.condition, step.seed, step.practice) == (s["step"]["condition"], s["step"]["seed"],
                                                                  s["step"]["practice"])
        else:
            assert s["kind"] == "questionnaire" and len(s["questionnaires"]["sus"]["items"]) == 10
            assert r.next() is not None and isinstance(r.start(), str)
            assert r.answer(GOOD) is None
    # P01 follows the square's first sequence: a-vf then teleop; one practice, one measured each
    assert seen == ["instructions", "ready", "ready", "questionnaire"] * 2
    order = [row.condition for row in store.trials("P01").rows]
    assert order == ["a-vf", "a-vf", "teleop", "teleop"]
    assert [row.practice for row in store.trials("P01").rows] == [True, False, True, False]
    assert [b["condition"] for b in store.answers("P01")["blocks"]] == ["a-vf", "teleop"]
    done = r.screen()
    assert (done["done"], done["total"]) == (4, 4)
    assert all(b["finished"] == b["trials"] and b["answered"] for b in done["blocks"])


def test_the_second_participant_starts_with_the_other_condition(store):
    r = runner(store, "P02")
    assert r.screen()["block"]["condition"] == "teleop"


def test_an_aborted_trial_comes_again_with_the_same_seed(store):
    r = runner(store)
    r.next()
    run_trial(r)  # the practice trial
    measured = r.start()
    r.abort("safety stop by the experimenter", 2.0)
    s = r.screen()
    assert s["kind"] == "ready" and s["last"]["outcome"] == "aborted"
    assert s["step"]["index"] == measured.index and s["step"]["seed"] == measured.seed
    assert s["step"]["attempt"] == 2 and s["aborted"] == 1 and s["done"] == 1
    rows = store.trials("P01").rows
    assert rows[-1].aborted and rows[-1].success is None
    assert rows[-1].reason == "safety stop by the experimenter"
    run_trial(r)
    assert kind(r) == "questionnaire"


def test_a_killed_runners_trial_is_marked_aborted_on_resume(store):
    r = runner(store)
    r.next()
    run_trial(r)
    step = r.start()  # ... and the process dies here: running.json stays, no row
    assert json.loads((r.folder / RUNNING_FILE).read_text())["step"] == step.index
    again = runner(store)
    assert again.recovered is not None and "marked aborted" in again.recovered
    rows = store.trials("P01").rows
    assert len(rows) == 2 and rows[-1].step == step.index and rows[-1].reason == INTERRUPTED
    assert not (r.folder / RUNNING_FILE).exists()
    # a resumed runner shows the block's instructions again, then the same step
    assert kind(again) == "instructions"
    again.next()
    assert again.screen()["step"]["index"] == step.index
    assert rig_folder(again.folder, step, again.attempt(step)).name == f"step-{step.index:03d}-2"


def test_a_trial_recorded_just_before_a_kill_is_not_aborted(store):
    r = runner(store)
    r.next()
    step = r.start()
    marker = (r.folder / RUNNING_FILE).read_text()
    r.finish(SUCCESS, None)
    (r.folder / RUNNING_FILE).write_text(marker)  # killed between the row and the note's removal
    again = runner(store)
    assert again.recovered is None and not any(row.aborted for row in store.trials("P01").rows)
    assert again.screen()["done"] == 1 and step.index == 0


def test_answers_out_of_range_are_refused_naming_the_item_and_nothing_is_stored(store):
    r = runner(store)
    r.next()
    run_trial(r)
    run_trial(r)
    bad = {"nasa_tlx": dict(GOOD["nasa_tlx"], effort=105), "sus": GOOD["sus"]}
    why = r.answer(bad)
    assert why is not None and "nasa_tlx.effort: 105 is out of range (0-100)" in why
    missing = {"nasa_tlx": GOOD["nasa_tlx"], "sus": [*GOOD["sus"][:9], None]}
    assert "sus.10: missing" in (r.answer(missing) or "")
    assert store.answers("P01")["blocks"] == [] and kind(r) == "questionnaire"
    assert r.answer(GOOD) is None and kind(r) == "instructions"


def test_the_pause_holds_everything_until_the_experimenter_continues(store):
    r = runner(store)
    r.pause()
    assert kind(r) == "paused" and r.next() == "not now: the page shows paused"
    r.unpause()
    assert kind(r) == "instructions"


def test_a_participant_not_in_the_plan_is_refused(store):
    with pytest.raises(StudyError, match="P09: not in the plan"):
        runner(store, "P09")


def test_a_second_runner_on_a_folder_is_refused_naming_the_first(tmp_path):
    with RunnerLock(tmp_path) as first:
        assert first.stale is None
        with pytest.raises(StudyError, match=f"another sctd study run \\(pid {os.getpid()}\\)"):
            RunnerLock(tmp_path).acquire()
    assert (tmp_path / LOCK_FILE).read_text() == ""  # a clean exit leaves no pid
    with RunnerLock(tmp_path) as again:  # ... and the next runner takes it without a word
        assert again.stale is None


def test_a_dead_runners_lock_is_taken_over_and_said(tmp_path):
    (tmp_path / LOCK_FILE).write_text("999999\n")  # its pid, left by a kill; no process holds the lock
    with RunnerLock(tmp_path) as lock:
        assert lock.stale == 999999
        assert (tmp_path / LOCK_FILE).read_text() == f"{os.getpid()}\n"


def test_the_cli_refuses_a_participant_not_in_the_plan_and_a_held_folder(tmp_path, capsys):
    drawer = make_plan([Condition("drawer-vf", "skill"), T], ["drawer"], participants=2, practice=1, trials=1)
    plan = tmp_path / "plan.yaml"
    plan.write_text(plan_to_yaml(drawer))
    store = StudyStore.create(tmp_path / "study", drawer)
    args = ["study", "run", "--plan", str(plan), "--out", str(store.directory)]
    assert main([*args, "--participant", "P09"]) == 2
    assert "sctd study run: --participant: participant P09: not in the plan (its participants: P01, P02)" \
        in capsys.readouterr().err
    assert main([*args, "--participant", "jane.doe@example.org"]) == 2
    assert "looks like an e-mail address" in capsys.readouterr().err
    with RunnerLock(store.directory):
        assert main([*args, "--participant", "P01"]) == 2
    assert "runner.lock: another sctd study run" in capsys.readouterr().err
