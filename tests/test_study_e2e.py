"""``sctd study plan`` -> ``run --simulated`` -> ``report`` end to end as processes, on
the light switch (the shortest shipped task: about 2 s a lockstep trial); and a run
killed mid-study that resumes where it stopped."""

from __future__ import annotations

import csv
import json
import signal

import pytest

from tests.conftest import run_sctd, sctd, wait_for

pytestmark = pytest.mark.slow  # starts sctd processes that run lockstep trials


def _plan(tmp_path, participants=2):
    plan = tmp_path / "plan.yaml"
    r = run_sctd("study", "plan", "--participants", str(participants), "--condition", "light_switch-vf",
                 "--condition", "teleop", "--task", "light_switch", "--practice", "1", "--trials", "2",
                 "--seed", "3", "--out", str(plan))
    assert r.returncode == 0, r.stderr
    return plan


def test_plan_a_killed_run_resumed_and_the_report(tmp_path):
    """One study folder: participant 1's simulated run killed mid-trial (SIGKILL) resumes
    where it stopped, nothing finished lost or run twice; the run goes on to participant 2;
    the report reads both."""
    plan = _plan(tmp_path)
    data, out = tmp_path / "study", tmp_path / "report"
    csv_file = data / "P01" / "trials.csv"
    run = sctd("study", "run", "--simulated", "1", "--plan", str(plan), "--out", str(data),
               log=tmp_path / "run.log")
    try:
        assert wait_for(lambda: csv_file.exists() and len(csv_file.read_text().splitlines()) >= 3, 120)
    finally:
        run.stop(sig=signal.SIGKILL)
    r = run_sctd("study", "run", "--simulated", "2", "--plan", str(plan), "--out", str(data), timeout=240)
    assert r.returncode == 0, r.stderr
    steps = [int(x["step"]) for x in csv.DictReader(csv_file.open()) if x["aborted"] == "0"]
    assert sorted(steps) == list(range(6)) and len(set(steps)) == 6
    answers = json.loads((data / "P01" / "answers.json").read_text())
    assert len(answers["blocks"]) == 2
    rows = list(csv.DictReader((data / "P02" / "trials.csv").open()))
    assert [int(x["step"]) for x in rows] == list(range(6))
    assert [x["condition"] for x in rows] == ["teleop"] * 3 + ["light_switch-vf"] * 3  # P02: sequence 2
    assert all((data / "P02" / x["log"]).is_file() for x in rows)
    assert rows[0]["practice"] == "1" and rows[1]["seed"] == "7"
    r = run_sctd("study", "report", str(data), "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["participants"] == ["P01", "P02"]
    table = doc["tables"]["light_switch"]
    assert table["light_switch-vf"]["trials"] == 4 and table["teleop"]["trials"] == 4
    assert table["teleop"]["raw_tlx"]["n"] == 2 and table["teleop"]["sus_score"]["n"] == 2
    assert all(c["p"] is None or c["note"] for c in doc["comparisons"])  # 2 participants: said, not tested
    assert {p.name for p in out.iterdir()} >= {"report.md", "report.json", "completion_time_s.png"}
    assert "## Task light_switch" in (out / "report.md").read_text()
