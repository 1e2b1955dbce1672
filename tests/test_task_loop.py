"""A task nobody here tuned, written in the test as a file (not shipped): `sctd teach`
shows it from its intent, `sctd learn` learns the demonstrations, `sctd eval` runs the
learned skill on it in lockstep. Nothing in the package names it."""

from __future__ import annotations

import json

import pytest

from sctd.learn.demos import read_demos
from sctd.skill import load_skill
from tests.conftest import run_sctd

SIDE_DRAWER = """\
# a drawer in a cabinet beside the chair, to the left, pulled towards the chair's side
sctd_task: 1
name: side_drawer
title: Open the drawer beside the chair
object: side_handle
scene:
  start:
    position: [0.50, 0.15, 0.62]
    rpy: [0, 0, -90 deg]
    vary: {position: 0.06, yaw: 10 deg}
  bodies:
    side_handle:
      position: [0.55, 0.40, 0.52]
      rpy: [0, 0, -90 deg]
      vary: {position: 0.03}
  joints:
    side_drawer:
      type: prismatic
      handle: side_handle
      travel: 0.25
      mass: 1.5
      spring: 20.0
      damping: 10.0
      friction: 2.0
      friction_speed: 0.01
      grasp: {radius: 0.02, release: 0.06, stiffness: 2000.0, damping: 60.0}
outcome:
  done: {reading: side_drawer.position, at_least: 0.15}
  done_reason: opened
  fail:
    - when:
        all:
          - {reading: side_drawer.grasps, at_least: 1}
          - {reading: side_drawer.held, is: false}
          - {reading: side_drawer.position, above: 0.01}
      reason: handle lost while pulling
  progress: side_drawer.position
  clock: {near: {frame: hand, to: side_handle, within: 0.20}}
  time_limit: 60
intent:
  - name: reach
    reach:
      frame: hand
      handle: side_drawer
      until: {reading: side_drawer.held, is: true}
  - name: pull
    move_joint:
      joint: side_drawer
      overshoot: 0.03
      back: {reading: side_drawer.held, is: false}
teach:
  steps:
    reach: {yaw: 0.2, miss: 0.05}
    pull: {to: [0.18, 0.22]}
"""


@pytest.mark.slow
def test_teach_learn_and_eval_a_task_written_here(tmp_path):
    task = tmp_path / "my-drawer.yaml"  # the file's name is not the task's
    task.write_text(SIDE_DRAWER)
    demos, skill = tmp_path / "demos", tmp_path / "side-vf.yaml"
    taught = run_sctd("teach", "--task", str(task), "--demos", "4", "--out", str(demos), "--seed", "0",
                      "--logs", str(tmp_path / "logs"), timeout=300)
    assert taught.returncode == 0, taught.stdout + taught.stderr
    assert "sctd teach: side_drawer on a simulator" in taught.stdout
    assert "kept 4 of 4 demonstrations" in taught.stdout
    assert len(read_demos(demos)) == 4
    learned = run_sctd("learn", str(demos), "--method", "vf", "--object", "side_handle", "--out", str(skill))
    assert learned.returncode == 0, learned.stdout + learned.stderr
    assert load_skill(skill).object == "side_handle"
    run = run_sctd("eval", "--skill", str(skill), "--task", str(task), "--trials", "3", "--lockstep",
                   "--json", timeout=300)
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout)
    (result,) = report["results"]
    assert (report["task"], report["task_file"]) == ("side_drawer", str(task))
    outcomes = [t["outcome"] for t in result["per_trial"]]
    assert len(outcomes) == 3 and outcomes.count("success") >= 2, result["per_trial"]
    assert all(t["reason"] == "opened" for t in result["per_trial"] if t["outcome"] == "success")
