"""Goal inference in a room of several tasks, evaluated (sctd_services.eval.goals): the
room is the same whatever the user goes for, the goals are drawn from the seed, the
engagements are read off the set's changes, and a lockstep trial of the set engages the
user's task."""

from pathlib import Path

import numpy as np
import pytest

from sctd.skill import load_skill
from sctd.task import find_task
from sctd.task.compose import room as room_task
from sctd_services.eval.goals import (
    SetSpec,
    engagements,
    goal_of,
    set_job,
    summarise_set,
    tasks_of,
)

ROOM = ["cabinet", "drawer", "oven"]
SKILLS = ("skills/cabinet-vf.yaml", "skills/drawer.yaml", "skills/oven-vf.yaml")
ROOT = Path(__file__).resolve().parents[1]


def set_file(folder: Path) -> str:
    members = "\n".join(f"  - {{skill: {ROOT / s}, reach: 0.35}}" for s in SKILLS)
    path = folder / "room.yaml"
    path.write_text(f"sctd_set: 1\nname: room\nmembers:\n{members}\n")
    return str(path)


def _objects(task):
    return {n: b.T_world[:3, 3] for p in task.parts for n, b in p.scene.bodies.items()}


def test_the_room_is_laid_out_once_whatever_the_goal():
    rooms = {g: room_task([find_task(n) for n in ROOM], g) for g in ROOM}
    first = _objects(rooms["cabinet"])
    for g, task in rooms.items():
        assert task.parts[0].name == g and task.object == task.parts[0].object  # its outcome, its intent
        got = _objects(task)
        assert set(got) == set(first)
        for n in first:
            assert np.allclose(got[n], first[n]), (g, n)
        assert np.allclose(task.scene.start.T_world, rooms["cabinet"].scene.start.T_world)


def test_goals_come_from_the_seed_alone_and_each_task_is_drawn():
    drawn = [goal_of(s, ROOM) for s in range(60)]
    assert drawn == [goal_of(s, ROOM) for s in range(60)]
    assert set(drawn) == set(ROOM)


def test_each_member_names_its_task_and_a_task_is_in_the_room_once():
    skills = [load_skill(p) for p in SKILLS]
    assert [t.name for t in tasks_of(skills)] == ROOM
    with pytest.raises(ValueError, match="two members are skills for one task"):
        tasks_of([skills[1], load_skill("skills/drawer-vf.yaml")])


def test_engagements_read_off_the_changes():
    """teleop -> b (wrong) at 2 s, escaped at 2.5 s, -> a (right) at 4 s."""
    changes = [(2.0, "teleop", "b"), (2.5, "b", "teleop"), (4.0, "teleop", "a")]
    e = engagements(changes, "a", "teleop")
    assert e["first_engaged"] == "b" and not e["right_first"] and e["right_engaged"]
    assert e["t_engaged"] == 4.0 and e["wrong"] == 1 and e["recovery_s"] == [0.5]
    never = engagements([(1.0, "teleop", "b")], "a", "teleop")
    assert never["wrong"] == 1 and never["recovery_s"] == [None] and not never["right_engaged"]
    assert engagements([], "a", "teleop")["first_engaged"] is None


def test_with_a_change_of_mind_the_first_tasks_skill_is_right_until_the_change():
    """The user goes for b first and changes its mind at 5 s: b engaged at 3 s was what it
    wanted then; still engaged at the change, it is left 0.2 s after; c engaged at 6 s is
    wrong (undone at 6.5 s), a at 8 s right."""
    changes = [(3.0, "teleop", "b"), (5.2, "b", "teleop"), (6.0, "teleop", "c"), (6.5, "c", "teleop"),
               (8.0, "teleop", "a")]
    e = engagements(changes, "a", "teleop", detour="b", changed_at=5.0)
    assert e["first_engaged"] == "b" and e["right_first"] and e["right_engaged"] and e["t_engaged"] == 8.0
    assert e["wrong"] == 1 and e["recovery_s"] == [0.5] and e["after_change_s"] == 0.2
    kept = engagements([(3.0, "teleop", "b")], "a", "teleop", detour="b", changed_at=5.0)
    assert np.isnan(kept["after_change_s"]) and kept["wrong"] == 0 and not kept["right_engaged"]
    late = engagements([(6.0, "teleop", "b")], "a", "teleop", detour="b", changed_at=5.0)
    assert late["after_change_s"] is None and late["wrong"] == 1 and not late["right_first"]
    assert engagements(changes, "a", "teleop")["after_change_s"] is None


@pytest.mark.slow
def test_a_user_who_changes_its_mind_escapes_the_first_tasks_skill(tmp_path):
    """Trial 0 with a change of mind: the set engages the first task's skill, the user
    changes its mind there, escapes it a reaction delay later, and the goal's skill
    engages and finishes; teleoperation runs the same person; no pre-selected run."""
    from sctd_services.eval.goals import detour_of

    r = set_job(SetSpec(set_file(tmp_path), detour=True), 0)
    skill = {"cabinet": "cabinet-vf", "drawer": "drawer", "oven": "oven-vf"}
    assert r["detour"] == detour_of(0, ROOM) != r["goal"] and "preselected" not in r
    assert r["first_engaged"] == skill[r["detour"]] and r["right_first"] and r["changed_at"] is not None
    assert 0.0 < r["after_change_s"] < 1.0 and r["escapes"] >= 1
    assert r["right_engaged"] and r["t_engaged"] > r["changed_at"]
    assert r["set"]["outcome"] == "success" and r["teleop"]["outcome"] == "success"


@pytest.mark.slow
def test_a_rest_at_the_mug_after_a_change_of_mind_engages_the_pour():
    """kitchen-pour, trial 0: the user goes for the drawer first, changes its mind for the
    pour there and carries the bottle to the mug, which lies on the way from the drawer
    to the light switch. Its stop at the mug engages the pour, which pours; without the
    rest's evidence (rest_speed 0) the belief stays split between the mug and the
    switch, nothing engages, and the set's teleoperation (about the hand's origin) cannot
    pour; the competent baseline (about the bottle's opening) can."""
    from sctd.skill.catalog import find_skill_set

    kitchen = str(find_skill_set("kitchen-pour"))
    r = set_job(SetSpec(kitchen, detour=True), 0)
    assert (r["goal"], r["detour"]) == ("pour", "drawer") and r["first_engaged"] == "drawer"
    assert r["right_engaged"] and r["t_engaged"] > r["changed_at"]
    assert [c[2] for c in r["changes"]] == ["drawer", "teleop", "pour"]
    assert r["set"]["reason"] == "poured" and r["teleop"]["reason"] == "poured"
    flat = set_job(SetSpec(kitchen, detour=True, belief=(("rest_speed", 0.0),)), 0)
    assert [c[2] for c in flat["changes"]] == ["drawer", "teleop"] and not flat["right_engaged"]
    assert flat["set"]["outcome"] != "success"


def test_the_summary_pairs_trials_that_both_finished():
    def row(goal, s, p, t, right=True):
        res = lambda d: {"outcome": "success" if d else "failure", "duration_s": d or 60.0}  # noqa: E731
        return {"goal": goal, "set": res(s), "preselected": res(p), "teleop": res(t),
                "right_first": right, "right_engaged": right, "t_engaged": 3.0 if right else None,
                "wrong": 0 if right else 1, "recovery_s": [] if right else [0.4]}
    rows = [row("a", 10.0, 8.0, 20.0), row("a", 12.0, 10.0, None), row("b", None, 9.0, 9.0, right=False)]
    s = summarise_set(rows)
    o = s["overall"]
    assert o["right_first"] == pytest.approx(2 / 3, abs=1e-4) and o["wrong"] == 1
    assert o["recovery_median_s"] == 0.4
    assert o["set_vs_preselected"] == pytest.approx(np.median([10 / 8, 12 / 10]))
    assert o["set_vs_teleop"] == 0.5 and o["set_vs_teleop_pairs"] == 1
    assert s["by_goal"]["b"]["set"]["successes"] == 0


@pytest.mark.slow
def test_a_lockstep_trial_of_the_set_engages_the_users_task(tmp_path):
    """Trial 0's user goes for the cabinet: the set engages the cabinet's skill first,
    and the trial, the pre-selected skill's and teleoperation's all open it."""
    r = set_job(SetSpec(set_file(tmp_path)), 0)
    assert r["goal"] == goal_of(0, ROOM)
    assert r["first_engaged"] == {"cabinet": "cabinet-vf", "drawer": "drawer", "oven": "oven-vf"}[r["goal"]]
    assert r["wrong"] == 0 and r["t_engaged"] is not None
    assert [r[c]["outcome"] for c in ("set", "preselected", "teleop")] == ["success"] * 3
    trace = r["belief_trace"]  # 10 Hz, each member's column; the goal's passed the threshold
    t = np.array(trace["t"])
    assert set(trace) == {"t", "cabinet-vf", "drawer", "oven-vf"} and np.all(np.diff(t) >= 0.1 - 1e-9)
    p = np.array([trace[m] for m in ("cabinet-vf", "drawer", "oven-vf")], dtype=float)
    assert np.allclose(p.sum(axis=0), 1.0, atol=1e-3) and np.allclose(p[:, 0], 1 / 3, atol=1e-3)
    assert p[ROOM.index(r["goal"]), t <= r["t_engaged"]].max() >= 0.8


def test_the_user_escapes_a_skill_for_another_object_a_reaction_delay_later():
    """The display shows the drawer's skill to a user going for the cabinet: it keeps
    doing what it did for a reaction delay, then lets go of the stick and presses escape
    (a rising edge, again while the display still shows it); its own task's skill it
    uses."""
    from sctd.task import find_task
    from sctd_services.user import Observation, SetUser, SimulatedUser

    class Fixed(SimulatedUser):
        def step(self, t, obs):
            return (0.5, 0.0, 0.0), (0, 1, 0)

    task = find_task("cabinet")
    user = SetUser(Fixed(task), task.object)
    obs = Observation(0.0, np.eye(4), {}, {}, "drawer:reach")
    delay, period = user.profile.reaction_delay, user.profile.update_period
    seen = [(t, *user.step(t, obs, "drawer_handle")) for t in np.arange(0.0, 1.0, 0.01)]
    before = [b for t, u, b in seen if t < delay - 1e-9]
    assert before and all(b == (0, 1, 0) for b in before)
    after = [(t, u, b) for t, u, b in seen if t >= delay - 1e-9]
    assert all(u == (0.0, 0.0, 0.0) for _, u, _ in after)
    presses = [t for (t, _, b), (_, _, b0) in zip(after[1:], after, strict=False) if b[2] and not b0[2]]
    assert after[0][2] == (0, 1, 1) and presses and presses[0] == pytest.approx(delay + 4 * period, abs=0.011)
    assert user.escapes == [(0.0, pytest.approx(delay))]
    assert user.step(2.0, obs, task.object) == ((0.5, 0.0, 0.0), (0, 1, 0))  # its own: used
    assert user.step(2.01, obs, None) == ((0.5, 0.0, 0.0), (0, 1, 0))  # teleoperation


def test_a_user_changing_its_mind_uses_the_first_tasks_skill_until_then():
    """Going for the drawer first, the user drives as the drawer's user and uses the
    drawer's skill; a step pause after it reached the drawer's first step it changes its
    mind: from then it drives as the cabinet's user and escapes the drawer's skill a
    reaction delay later. One person: one knowledge of the device."""
    from sctd.task import find_task
    from sctd_services.user import Observation, SetUser, SimulatedUser

    class Fixed(SimulatedUser):
        def __init__(self, task, u):
            super().__init__(task, profile="pausing")
            self.u = u

        def step(self, t, obs):
            return self.u, (0, 1, 0)

    cabinet, drawer = find_task("cabinet"), find_task("drawer")
    goal, first = Fixed(cabinet, (0.5, 0.0, 0.0)), Fixed(drawer, (0.0, 0.3, 0.0))
    user = SetUser(goal, cabinet.object, first, drawer.object)
    assert first.models is goal.models and user.wanted == drawer.object
    obs = Observation(0.0, np.eye(4), {}, {}, "drawer:reach")
    assert user.step(0.0, obs, drawer.object) == ((0.0, 0.3, 0.0), (0, 1, 0))  # its skill: used
    first.intent.index = 1  # the drawer's first step reached
    pause = user.profile.step_pause
    assert user.step(1.0, obs, drawer.object)[0] == (0.0, 0.3, 0.0)
    assert user.step(1.0 + pause - 0.01, obs, drawer.object)[0] == (0.0, 0.3, 0.0)
    assert user.step(1.0 + pause, obs, drawer.object)[0] == (0.0, 0.3, 0.0) and user.changed_at == 1.0 + pause
    assert user.wanted == cabinet.object
    t = 1.0 + pause + 0.01
    assert user.step(t, obs, drawer.object) == ((0.5, 0.0, 0.0), (0, 1, 0))  # noticed a delay later
    pressed = user.step(t + user.profile.reaction_delay, obs, drawer.object)
    assert pressed == ((0.0, 0.0, 0.0), (0, 1, 1)) and len(user.escapes) == 1
    with pytest.raises(ValueError, match="both"):
        SetUser(goal, cabinet.object, first)


@pytest.mark.slow
def test_a_practised_user_knows_the_modes_of_its_practice_runs(tmp_path):
    """With practice, the user of every condition starts knowing the modes it used in
    one run of the goal's task with the goal's skill and one with teleoperation (under
    the set, by the display's skill:state names), each tried out on every axis."""
    from sctd_services.eval.goals import _practised

    path = set_file(tmp_path)
    r = set_job(SetSpec(path, practice=True, conditions=("set",)), 0)
    goal = goal_of(0, ROOM)
    skill = {"cabinet": "cabinet-vf", "drawer": "drawer", "oven": "oven-vf"}[goal]
    own, teleop = _practised(path, goal, ROOM.index(goal), "pausing"), _practised(path, goal, -1, "pausing")
    assert own and teleop and all(m.known for m in [*own.values(), *teleop.values()])
    assert r["practised_modes"] == sorted([f"{skill}:{m}" for m in own] + [f"teleop:{m}" for m in teleop])
    assert r["set"]["outcome"] == "success" and r["right_first"]


def test_eval_refuses_a_bad_belief_or_practice_without_a_set(capsys):
    from sctd.cli.main import main

    for argv, problem in [
        (["--set", "doors", "--belief", "threshold"], "--belief: 'threshold' is not KEY=NUMBER"),
        (["--set", "doors", "--belief", "gamma=2"], "belief.gamma: unknown field (allowed: beta, "),
        (["--set", "doors", "--belief", "threshold=1.5"], "belief.threshold: expected a number in (0.5, 1)"),
        (["--skill", "pour", "--practised"], "--practised, --belief and --change-of-mind: only with --set"),
    ]:
        assert main(["eval", *argv, "--trials", "1"]) == 2, argv
        assert problem in capsys.readouterr().err, argv


def test_teleoperation_in_a_room_is_the_goals_competent_baseline():
    """The teleop condition runs the set's teleoperation as `sctd eval` and `sctd suite`
    compare a skill with: the goal member's limits, turning about the tip of what the
    hand holds where the goal tilts it. With it, the pour that teleoperation about the
    hand's origin never finished is poured; the report names each goal's baseline."""
    from sctd_services.eval.goals import format_set_report

    path = str(ROOT / "skills" / "sets" / "kitchen-pour.yaml")
    names = ["pour", "drawer", "light_switch"]
    seed = next(s for s in range(20) if goal_of(s, names) == "pour")
    r = set_job(SetSpec(path, conditions=("teleop",)), seed)
    assert r["goal"] == "pour" and r["baseline"] == "teleop (limits of pour, control frame bottle_tip)"
    assert r["teleop"]["outcome"] == "success", r["teleop"]
    seed = next(s for s in range(20) if goal_of(s, names) == "drawer")
    d = set_job(SetSpec(path, conditions=("teleop",)), seed)
    assert d["baseline"] == "teleop (limits of drawer)"  # (the drawer tilts nothing held)
    summary = summarise_set([r, d], ("teleop",))
    summary.update(set="kitchen-pour", members=names, room=names, teleop="teleop", profile="pausing",
                   seed=0, baselines={"pour": r["baseline"], "drawer": d["baseline"]})
    text = format_set_report(summary)
    assert "teleop for pour: teleop (limits of pour, control frame bottle_tip)" in text
    assert "teleop for drawer: teleop (limits of drawer)" in text
