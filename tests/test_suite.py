"""`sctd suite`: every task x its shipped skills x the competent baseline, one table;
each task's floor (the time no assistance can beat at the skill's speed limits)."""

from __future__ import annotations

import json
import math

import pytest

from sctd.skill import Limits
from sctd.task import find_task
from sctd_services.eval.suite import TaskRun, figure, floor, markdown, rows, skills_for, table
from tests.conftest import ROOT, run_sctd


def test_floor_is_travel_and_tilt_over_the_speed_limits():
    """Drawer: the hand's 27 cm to the handle counted from the clock's 20 cm, then the
    20 cm pull, at 0.1 m/s; pour: the bottle's opening (12 cm above the hand) 31.6 cm to
    5 cm over the mug, then the 1.65 rad tilt at 0.5 rad/s."""
    assert floor(find_task("drawer"), Limits()) == pytest.approx(0.40 / 0.10)
    pour = math.hypot(0.30, 0.10) / 0.10 + 1.65 / 0.5
    assert floor(find_task("pour"), Limits()) == pytest.approx(pour)
    assert floor(find_task("pour"), Limits(0.2, 1.0)) == pytest.approx(pour / 2)
    # the cabinet: the clock's 20 cm, then 65 deg of the door at the handle's 0.321 m lever
    lever = math.hypot(0.03, 0.32)
    assert floor(find_task("cabinet"), Limits()) == pytest.approx((0.20 + math.radians(65.0) * lever) / 0.10)


def test_a_skills_speed_cap_near_the_object_raises_its_floor():
    """The drink's learned skill caps the rim at 3 cm/s and the hand's turn at 0.3 rad/s
    within 10 cm of the mouth: the floor goes the way inside those 10 cm at the cap and
    tilts at the cap (the baseline, uncapped, keeps the plain floor); a skill with a
    state that has no cap is not capped."""
    import numpy as np

    from sctd.skill import load_skill
    from sctd.skill.catalog import shipped_folder
    from sctd_services.eval.evaluate import cap_of
    from sctd_services.eval.suite import _inside

    assert _inside(np.array([-1.0, 0, 0]), np.array([1.0, 0, 0]), np.zeros(3), 0.1) == pytest.approx(0.2)
    assert _inside(np.array([-1.0, 0.2, 0]), np.array([1.0, 0.2, 0]), np.zeros(3), 0.1) == 0.0
    assert _inside(np.array([-1.0, 0, 0]), np.array([0.05, 0, 0]), np.zeros(3), 0.1) == pytest.approx(0.15)
    drink = find_task("drink")
    skill = load_skill(shipped_folder() / "drink-vf.yaml")
    c = cap_of(skill)
    assert c is not None and (c.within, c.max_linear_speed, c.max_angular_speed) == (0.1, 0.03, 0.3)
    plain = floor(drink, skill.limits)
    assert plain == pytest.approx(0.25 / 0.10 + 1.0 / 0.5)  # the clock's 25 cm, the 1 rad tilt
    capped = floor(drink, skill.limits, c)
    slow = (capped - 1.0 / 0.3 - 0.25 / 0.10) / (1 / 0.03 - 1 / 0.10)  # the way inside the 10 cm
    assert 0.09 < slow <= 0.10 and capped > plain + 3.0
    assert cap_of(load_skill(shipped_folder() / "pour.yaml")) is None


def _result(name, limits, times, baseline_of=None, label=None):
    per_trial = [{"seed": k, "outcome": "success" if t else "failure", "time_s": t,
                  "reason": None if t else "time limit"} for k, t in enumerate(times)]
    ok = [t for t in times if t]
    return {"skill": label or name, "name": name, "baseline_of": baseline_of, "trials": len(times),
            "successes": len(ok), "success_rate": len(ok) / len(times),
            "time_s": {"median": sorted(ok)[len(ok) // 2] if ok else None}, "limits": limits,
            "mode_switches_mean": 1.0, "effort_mean": 5.0, "stuck": 0, "time_s_limited_median": 10.0,
            "per_trial": per_trial}


def test_rows_compare_each_skill_with_the_baseline_of_its_limits():
    slow, fast = {"max_linear_speed": 0.1, "max_angular_speed": 0.5}, {"max_linear_speed": 0.2,
                                                                        "max_angular_speed": 0.5}
    run = TaskRun(find_task("drawer"), ["a.yaml", "b.yaml"], [
        _result("a", slow, [4.0, 5.0, 6.0], label="a.yaml"),
        _result("b", fast, [3.0, None], label="b.yaml"),
        _result("teleop", slow, [10.0, 10.0, 10.0], baseline_of="a.yaml"),
        _result("teleop", fast, [6.0, 6.0], baseline_of="b.yaml"),
    ])
    out = rows([run])
    assert [r["skill"] for r in out] == ["a", "b", "baseline (a)", "baseline (b)"]
    assert [r["vs_baseline"] for r in out] == [0.5, 0.5, None, None]
    assert out[1]["failures"] == {"time limit": 1} and out[1]["times_s"] == [3.0]
    assert [r["floor_s"] for r in out] == [4.0, 2.0, 4.0, 2.0]
    lines = table(out)
    assert len(lines) == 2 + 4 and "time limit x1" in lines[3]
    md = markdown(out).splitlines()
    assert len(md) == 2 + 4 and md[2] == "| drawer | a | 3/3 | 5.00 | 0.50 | 4.00 | 1.0 | 5.00 |"


def test_a_capped_skill_is_compared_with_its_capped_baseline_when_its_copy_is_gone(tmp_path):
    """The drink's skill caps the rim near the mouth: of two baselines with its limits,
    its row is compared with the one made for it (capped), found by the skill it was made
    for, not by its own copy (in the suite's work folder, gone when the rows are made);
    both rows get the capped floor. An uncapped skill with the same limits gets the
    uncapped baseline."""
    drink = str(ROOT / "skills" / "drink-vf.yaml")
    plain = tmp_path / "plain.yaml"  # the drink's skill without its cap: the same limits
    text = (ROOT / "skills" / "drink-vf.yaml").read_text()
    plain.write_text(text[:text.index("    - type: speed_near")] + text[text.index("candidate_frames:"):])
    (tmp_path / "drink-vf.npz").write_bytes((ROOT / "skills" / "drink-vf.npz").read_bytes())
    limits = {"max_linear_speed": 0.1, "max_angular_speed": 0.5}
    gone = str(tmp_path / "work" / "teleop.yaml")
    run = TaskRun(find_task("drink"), [drink, str(plain)], [
        _result("drink-vf", limits, [18.0], label=drink),
        _result("plain", limits, [12.0], label=str(plain)),
        _result("teleop", limits, [14.0], baseline_of=str(plain), label=gone),
        _result("teleop", limits, [20.0], baseline_of=drink, label=gone + "2"),
    ])
    out = rows([run])
    assert [r["vs_baseline"] for r in out] == [0.9, round(12.0 / 14.0, 3), None, None]
    capped, uncapped = out[0]["floor_s"], out[1]["floor_s"]
    assert capped > uncapped and out[3]["floor_s"] == capped and out[2]["floor_s"] == uncapped


def test_the_figure_draws(tmp_path):
    limits = {"max_linear_speed": 0.1, "max_angular_speed": 0.5}
    run = TaskRun(find_task("pour"), [], [_result("teleop", limits, [None, None], baseline_of="-")])
    out = tmp_path / "suite.png"
    figure(rows([run])).savefig(out, dpi=50)  # no successful trial: an empty box, not an error
    assert out.stat().st_size > 5000


def test_skills_for_a_task_are_the_shipped_ones_on_its_object():
    names = sorted(p.rsplit("/", 1)[-1] for p in skills_for(find_task("drawer")))
    assert names == ["drawer-vf.yaml", "drawer.yaml"]


def test_the_floor_of_a_press_is_its_approach():
    """The light switch's first move is a press: the hand from its start to the switch's
    face (23.5 cm), counted from the clock's 20 cm, at 0.1 m/s; without that clock, the
    whole way."""
    import dataclasses

    task = find_task("light_switch")
    sc = task.scene
    way = math.dist(sc.start.T_world[:3, 3], sc.bodies["light_switch"].T_world[:3, 3])
    assert way == pytest.approx(0.2354, abs=1e-4)
    assert floor(task, Limits()) == pytest.approx(0.20 / 0.10)
    free = dataclasses.replace(task, outcome=dataclasses.replace(task.outcome, clock=True))
    assert floor(free, Limits()) == pytest.approx(way / 0.10)


def test_a_failure_from_another_tasks_start_says_whose_start_it_was():
    limits = {"max_linear_speed": 0.1, "max_angular_speed": 0.5}
    r = _result("a", limits, [4.0, None, None], label="a.yaml")
    r["per_trial"][1]["start_of"], r["per_trial"][2]["start_of"] = "pour", "drawer"
    r["per_trial"][1]["outside_region"] = 0.31
    out = rows([TaskRun(find_task("drawer"), ["a.yaml"], [r], "adaptive")])
    assert out[0]["failures"] == {"time limit (from pour's start) [out of region]": 1, "time limit": 1}
    assert out[0]["started_outside_region"] == 1
    assert out[0]["user_model"] == "adaptive"


def test_a_skill_is_also_judged_on_the_starts_its_baseline_finished_from():
    """Trials 1 and 3 the baseline did not finish either (the arm at a limit from there):
    over the other three the skill finished two; a failure at a joint limit says so."""
    limits = {"max_linear_speed": 0.1, "max_angular_speed": 0.5}
    a = _result("a", limits, [4.0, None, None, None, 5.0], label="a.yaml")
    a["per_trial"][1]["joint_limits"] = [1]
    base = _result("teleop", limits, [6.0, None, 6.0, None, 6.0], baseline_of="a.yaml")
    out = rows([TaskRun(find_task("drawer"), ["a.yaml"], [a, base])])
    assert out[0]["where_baseline_finished"] == [2, 3] and out[1]["where_baseline_finished"] is None
    assert out[0]["failed_at_joint_limit"] == 1
    assert out[0]["failures"] == {"time limit [joint 1 at its limit]": 1, "time limit": 2}
    assert "2/3" in table(out, paired=True)[2] and "2/3" not in table(out)[2]
    line = markdown(out, paired=True).splitlines()[2]
    assert line == "| drawer | a | 2/5 | 2/3 | 5.00 | 0.83 | 4.00 | 1.0 | 5.00 |"


@pytest.mark.slow
def test_sctd_suite_runs_each_user_model_from_foreign_starts_and_writes_its_files(tmp_path):
    """--user-model twice: the same trials under each, side by side (a user column);
    --starts foreign: every trial from another task's start, which each trial names;
    --out: the table, the figure and the JSON it printed. (The tasks' own starts and a
    task with two skills are run by tests/test_bench_kernels.py's suites.)"""
    run = run_sctd("suite", "--task", "oven", "--trials", "2", "--jobs", "2", "--starts", "foreign",
                   "--user-model", "plain", "--user-model", "adaptive", "--out", str(tmp_path), "--json",
                   timeout=600)
    assert run.returncode == 0, run.stderr
    doc = json.loads(run.stdout)
    assert doc["user_models"] == ["plain", "adaptive"] and doc["starts"] == "foreign"
    assert [(r["user_model"], r["skill"]) for r in doc["rows"]] == [
        ("plain", "oven-vf"), ("plain", "baseline (oven-vf)"),
        ("adaptive", "oven-vf"), ("adaptive", "baseline (oven-vf)")]
    for model in ("plain", "adaptive"):
        for result in doc["results_by_user_model"][model]["oven"]:
            whose = [t["start_of"] for t in result["per_trial"]]
            assert len(whose) == 2 and "oven" not in whose and whose[0] != whose[1], whose
    assert all(r["trials"] == 2 and r["floor_s"] > 0 for r in doc["rows"])
    md = (tmp_path / "suite.md").read_text()
    assert md.startswith("| task | user | skill |") and md.count("| oven | adaptive |") == 2
    assert md.count("| oven |") == 4
    assert (tmp_path / "suite.png").stat().st_size > 10000
    assert json.loads((tmp_path / "suite.json").read_text())["rows"] == doc["rows"]
