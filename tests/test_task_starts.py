"""Starts the demonstrations did not cover (sctd.task.starts, sctd_services.eval.starts):
a wide start is the file's drawn twice as far, a foreign one another task's hand start in
this task's scene, the others taken in turn."""

import numpy as np
import pytest

from sctd.task import find_task, known_tasks
from sctd.task.starts import STARTS, foreign_start, from_start_of, shares_a_room, trial_start, widened


def test_a_wide_start_is_drawn_twice_as_far_and_nothing_else_changes():
    pour = find_task("pour")
    wide = widened(pour)
    v, w = pour.scene.start.vary, wide.scene.start.vary
    assert np.any(v.position) and v.yaw > 0
    np.testing.assert_array_equal(w.position, 2 * v.position)
    assert w.yaw == 2 * v.yaw
    np.testing.assert_array_equal(wide.scene.start.T_world, pour.scene.start.T_world)
    assert wide.scene.bodies == pour.scene.bodies and wide.intent == pour.intent
    assert pour.scene.start.vary is v  # (the task given is not changed)


def test_a_foreign_start_is_the_other_tasks_start_in_a_room_of_the_two():
    """As sctd eval --set lays out a room: the other task where it is, this one beside it,
    the hand at the other's start, going for this task."""
    from sctd.task.compose import room

    pour, drawer = find_task("pour"), find_task("drawer")
    moved = from_start_of(pour, drawer)
    np.testing.assert_array_equal(moved.scene.start.T_world, drawer.scene.start.T_world)
    assert moved.scene.start.vary == drawer.scene.start.vary
    assert set(moved.scene.bodies) == {"mug", "drawer_handle"} and moved.scene.held == pour.scene.held
    assert moved.outcome == pour.outcome and moved.intent == pour.intent and moved.object == "mug"
    assert moved.name == room([drawer, pour], "pour").name == "pour+drawer"
    np.testing.assert_array_equal(moved.scene.bodies["drawer_handle"].T_world,
                                  drawer.scene.bodies["drawer_handle"].T_world)


def test_foreign_starts_take_the_other_tasks_in_turn_and_never_the_own():
    tasks = [find_task(k.name) for k in known_tasks()]
    pour = find_task("pour")
    others = sorted(t.name for t in tasks if t.name != "pour" and shares_a_room(pour, t))
    assert "drink" not in others and "bottle_to_fridge" not in others  # (both hold something)
    assert {"drawer", "cabinet", "tap"} <= set(others)
    seen = [foreign_start(pour, tasks, seed)[1] for seed in range(2 * len(others))]
    assert seen == others + others
    with pytest.raises(ValueError, match="no other task"):
        foreign_start(pour, [pour], 0)


def test_trial_start_by_mode():
    pour, drawer = find_task("pour"), find_task("drawer")
    assert trial_start(pour, "own", 3) == (pour, "pour")
    assert trial_start(pour, "wide", 3)[0].scene.start.vary.yaw == 2 * pour.scene.start.vary.yaw
    assert trial_start(pour, "foreign", 0, [pour, drawer])[1] == "drawer"
    assert STARTS == ("own", "wide", "foreign")
    with pytest.raises(ValueError, match="'far' is none of own, wide, foreign"):
        trial_start(pour, "far", 0)


def test_a_lockstep_trial_from_a_foreign_start_starts_there_and_says_whose():
    """The trial's hand starts at the other task's start (within its vary), the other
    tasks being those whose start the arm reaches."""
    from sctd_services.eval.starts import reachable_others, starts_task
    from sctd_sim.simulation import trial_scene

    others = {t.name for t in reachable_others()}
    assert {"drawer", "cabinet", "pour"} <= others
    task, whose = starts_task(find_task("drawer"), "foreign", 0)
    assert whose != "drawer" and whose in others
    scene, _ = trial_scene(task, 0)
    start = find_task(whose).scene.start
    off = scene.start_pose()[:3, 3] - start.T_world[:3, 3]
    assert np.all(np.abs(off) <= start.vary.position + 1e-9), (off, start.vary.position)


def test_a_trial_records_how_far_outside_the_skills_region_the_hand_starts():
    """pour-vf was taught from the pour's start: its own starts are inside its region,
    the drawer's (across the room) is not; the hand-written pour states no region."""
    from sctd.skill import load_skill
    from sctd.skill.catalog import find_skill
    from sctd_services.eval.lockstep import outside_region
    from sctd_sim.simulation import trial_scene

    vf, pour = load_skill(find_skill("pour-vf")), find_task("pour")
    assert outside_region(vf, trial_scene(pour, 0)[0]) == 0.0
    far = foreign_start(pour, [find_task("drawer")], 0)[0]  # the mug laid out beside the drawer
    assert outside_region(vf, trial_scene(far, 0)[0]) > 0.03
    assert outside_region(load_skill(find_skill("pour")), trial_scene(pour, 0)[0]) is None
