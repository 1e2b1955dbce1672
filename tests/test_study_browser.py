"""``sctd study run --participant ID`` in a real headless Chromium (:mod:`tests.browser`):
two participants led through a plan by the page, each trial driven through the page's
keyboard by the simulated user and the questionnaires filled in, then the report; and a
trial stopped every way it can be before its end (the experimenter's safety stop, the
page closed, the runner killed), each marked aborted and run again, nothing finished lost.

What is asserted is what the programs report: the page's state, the study folder's files
and the report; never the test's own clock. The drawer is driven (the task the page's
tests drive reliably, docs/try.md).
"""

from __future__ import annotations

import csv
import json
import os
import re
import signal
from pathlib import Path

import pytest

from sctd.task import find_task
from tests.browser import drive_as_user, keyboard_injector, open_page
from tests.conftest import run_sctd, sctd, wait_for

# realtime, every test: the trials are driven in real time through the page, as
# tests/test_try_browser.py's, and beside another test on two cores the page's status lagged
pytestmark = [pytest.mark.slow, pytest.mark.realtime, pytest.mark.timeout(1800)]

START = 150_000  # ms for a trial's arm and daemon to start on a loaded machine
TLX = {"mental": 20, "physical": 10, "temporal": 35, "performance": 15, "effort": 40, "frustration": 0}
SUS = [4, 2, 4, 1, 3, 2, 4, 2, 3, 2]


def _plan(tmp_path_factory, practice: int) -> Path:
    path = tmp_path_factory.mktemp("plan") / "plan.yaml"
    r = run_sctd("study", "plan", "--participants", "2", "--condition", "drawer-vf", "--condition", "teleop",
                 "--task", "drawer", "--practice", str(practice), "--trials", "1", "--seed", "0",
                 "--out", str(path))
    assert r.returncode == 0, r.stderr
    return path


@pytest.fixture(scope="module")
def plan(tmp_path_factory):
    """One practice and one measured trial per block."""
    return _plan(tmp_path_factory, 1)


@pytest.fixture(scope="module")
def measured_only(tmp_path_factory):
    """One measured trial per block and no practice: four trials in real time for two
    participants rather than eight. A practice trial is one more trial through the same
    page (the stopped-trial test runs one; tests/test_study_runner.py walks a plan with
    practice through the runner's page)."""
    return _plan(tmp_path_factory, 0)


class Runner:
    """``sctd study run --participant`` and its URL and Zenoh endpoint."""

    def __init__(self, plan: Path, out: Path, pid: str, log: Path):
        self.proc = sctd("study", "run", "--participant", pid, "--plan", str(plan), "--out", str(out),
                         "--no-view", log=log)
        line = wait_for(lambda: re.search(r"open (http://\S+) .*\(Zenoh (\S+)\)", self.proc.output()), 60.0)
        assert line, self.proc.output()
        self.url, self.hub = line.group(1), line.group(2)

    def stop(self) -> int:
        return self.proc.stop(30.0)

    def kill(self) -> None:
        """SIGKILL, as a power cut would end it; then the trial's programs it started
        (they run in sessions of their own, connected to its Zenoh endpoint)."""
        self.proc.stop(sig=signal.SIGKILL)
        for pid in _processes_naming(self.hub):
            os.kill(pid, signal.SIGKILL)


def _processes_naming(text: str) -> list[int]:
    pids = []
    for entry in Path("/proc").iterdir():
        try:
            if entry.name.isdigit() and text.encode() in (entry / "cmdline").read_bytes():
                pids.append(int(entry.name))
        except OSError:
            pass
    return pids


def screen(page) -> dict:
    return page.evaluate("window.sctdState && window.sctdState.study")


def wait_screen(page, *kinds: str, timeout: float = 60_000) -> dict:
    page.wait_for_function(f"window.sctdState && {list(kinds)}.includes(window.sctdState.study.kind)",
                           timeout=timeout)
    return screen(page)


def start(page) -> dict:
    """The ready trial started from the page, once its arm runs; its step."""
    wait_screen(page, "ready")
    page.click("#start")
    page.wait_for_function("window.sctdState.study.kind === 'running' && "
                           "window.sctdState.trial.phase === 'running'", timeout=START)
    return screen(page)["step"]


def drive(page, hub: str) -> dict:
    """The running trial driven to its end by the simulated user through the keyboard;
    the page's next screen."""
    step = screen(page)["step"]
    drive_as_user(hub, find_task("drawer"), step["seed"], keyboard_injector(page),
                  lambda: screen(page)["kind"] != "running")
    return screen(page)


def answer(page, leave_out: str | None = None) -> None:
    for key, v in TLX.items():
        page.check(f'input[name="tlx-{key}"][value="{v}"]')
    for i, v in enumerate(SUS):
        if f"sus-{i + 1}" != leave_out:
            page.check(f'input[name="sus-{i + 1}"][value="{v}"]')
    page.click("#submit")


def walk(page, hub: str, first_questionnaire=None) -> list[str]:
    """Through the plan from where the page stands to its end; the screens seen."""
    seen: list[str] = []
    while True:
        s = wait_screen(page, "instructions", "ready", "questionnaire", "done")
        seen.append(s["kind"])
        if s["kind"] == "done":
            return seen
        if s["kind"] == "instructions":
            assert "deadman" in page.inner_text("#screen")
            page.click("#next")
            page.wait_for_function("window.sctdState.study.kind !== 'instructions'")
        elif s["kind"] == "ready":
            start(page)
            after = drive(page, hub)
            assert after["last"]["outcome"] in ("success", "failure", "stuck"), after["last"]
        else:
            if first_questionnaire is not None:
                first_questionnaire(page)
                first_questionnaire = None
            answer(page)
            page.wait_for_function("window.sctdState.study.kind !== 'questionnaire'")


def _bad_answers_are_shown_and_the_others_kept(page) -> None:
    answer(page, leave_out="sus-10")
    page.wait_for_selector("#notice:not([hidden])")
    assert "sus.10: missing" in page.inner_text("#notice")
    assert page.evaluate("document.querySelectorAll('#answers input:checked').length") == 15
    page.evaluate("window.sctdSocket.send(JSON.stringify({type: 'answers', nasa_tlx: "
                  f"Object.assign({json.dumps(TLX)}, {{effort: 105}}), sus: {json.dumps(SUS)}}}))")
    page.wait_for_function("document.getElementById('notice').textContent.includes('out of range')")
    assert "nasa_tlx.effort: 105 is out of range (0-100)" in page.inner_text("#notice")
    assert screen(page)["kind"] == "questionnaire"


def rows(folder: Path) -> list[dict]:
    return list(csv.DictReader((folder / "trials.csv").open()))


def test_two_participants_run_from_plan_to_report(measured_only, tmp_path):
    data = tmp_path / "study"
    for pid in ("P01", "P02"):
        runner = Runner(measured_only, data, pid, tmp_path / f"{pid}.log")
        try:
            with open_page(runner.url) as bp:
                seen = walk(bp.page, runner.hub, _bad_answers_are_shown_and_the_others_kept
                            if pid == "P01" else None)
        finally:
            assert runner.stop() == 0, runner.proc.output()
        assert seen == ["instructions", "ready", "questionnaire"] * 2 + ["done"]
        got = rows(data / pid)
        assert [int(r["step"]) for r in got] == [0, 1] and all(r["aborted"] == "0" for r in got)
        first = "drawer-vf" if pid == "P01" else "teleop"  # the square's two sequences
        assert got[0]["condition"] == first and [r["practice"] for r in got] == ["0", "0"]
        for r in got:
            log = json.loads((data / pid / r["log"]).read_text())
            assert log["step"] == int(r["step"]) and log["device"] == "browser"
            assert (data / pid / log["result"]["mcap"]).stat().st_size > 1000
        answers = json.loads((data / pid / "answers.json").read_text())
        assert [b["nasa_tlx"] for b in answers["blocks"]] == [TLX, TLX]
        assert "stopped; 2/2 trials recorded, all questionnaires" in runner.proc.output()
    r = run_sctd("study", "report", str(data), "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["participants"] == ["P01", "P02"]
    assert doc["progress"]["P01"] == {"done": 2, "total": 2, "aborted": 0}
    table = doc["tables"]["drawer"]
    assert table["drawer-vf"]["trials"] == 2 and table["teleop"]["trials"] == 2
    assert table["teleop"]["sus_score"]["n"] == 2
    assert not any((data / pid / "running.json").exists() for pid in ("P01", "P02"))


def test_a_stopped_trial_is_aborted_and_comes_again_nothing_finished_lost(plan, tmp_path):
    data = tmp_path / "study"
    folder = data / "P01"
    runner = Runner(plan, data, "P01", tmp_path / "run1.log")
    try:
        with open_page(runner.url) as bp:
            page = bp.page
            wait_screen(page, "instructions")
            page.click("#next")
            start(page)
            assert drive(page, runner.hub)["done"] == 1  # the practice trial, finished
            # the experimenter's safety stop, from their page
            step = start(page)
            watcher = page.context.new_page()
            watcher.goto(runner.url + "experimenter")
            watcher.wait_for_function("window.sctdState && window.sctdState.study.kind === 'running'")
            assert watcher.evaluate("window.sctdState.role") == "watcher"
            watcher.click("#stop")
            after = wait_screen(page, "ready")
            assert after["last"] == {"step": step["index"], "outcome": "aborted", "practice": False,
                                     "reason": "safety stop by the experimenter", "time_s": None}
            assert after["step"]["index"] == step["index"] and after["step"]["attempt"] == 2
            # the watcher's page hears of it with the next state message, not with the participant's
            watcher.wait_for_function("window.sctdState.study.aborted === 1", timeout=10_000)
            watcher.close()
            page.bring_to_front()
            # the participant's page closed mid-trial (its socket gone)
            start(page)
            page.evaluate("() => window.sctdSocket.close()")
            wait_for(lambda: len(rows(folder)) == 3, 60.0)
            page.reload()  # the same runner: the block's instructions were read, the trial is ready
            step = start(page)
            assert step["attempt"] == 3
            runner.kill()  # mid-trial, as a power cut
    finally:
        runner.proc.stop()
    got = rows(folder)
    assert [(r["step"], r["aborted"], r["reason"]) for r in got[1:]] == [
        ("1", "1", "safety stop by the experimenter"), ("1", "1", "the participant's page closed")]
    assert (folder / "running.json").exists()  # the kill left the trial's note
    runner = Runner(plan, data, "P01", tmp_path / "run2.log")
    try:
        out = wait_for(lambda: "marked aborted" in runner.proc.output() and runner.proc.output(), 30.0)
        assert out and "step 1: interrupted: the runner stopped during the trial" in out, runner.proc.output()
        with open_page(runner.url) as bp:
            s = wait_screen(bp.page, "instructions")
            assert (s["done"], s["aborted"]) == (1, 3)
    finally:
        assert runner.stop() == 0, runner.proc.output()
    got = rows(folder)
    assert got[0]["step"] == "0" and got[0]["aborted"] == "0" and got[0]["log"]  # the finished one, kept
    assert got[0]["practice"] == "1" and all(r["practice"] == "0" for r in got[1:])
    assert [r["aborted"] for r in got] == ["0", "1", "1", "1"] and got[-1]["step"] == "1"
    assert not (folder / "running.json").exists()
    assert sorted(p.name for p in (folder / "logs").iterdir() if p.is_dir()) == [
        "step-000-1", "step-001-1", "step-001-2", "step-001-3"]
