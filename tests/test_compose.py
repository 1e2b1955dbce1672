"""Several tasks in one room: task files composed into one scene, their objects placed
clear of each other without moving any further from the arm."""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np
import pytest

from sctd.task import TaskError, find_task
from sctd.task.compose import CLEARANCE, compose, footprint
from sctd_sim.options import add_service_arguments
from sctd_sim.scenes import make_scene
from sctd_sim.service import _settings_from_args

NAMES = ("pour", "drawer", "cabinet", "oven")


def _horizontal(T):
    return math.hypot(T[0, 3], T[1, 3])


def test_the_tasks_are_placed_clear_of_each_other_at_their_distance_from_the_arm():
    tasks = [find_task(n) for n in NAMES]
    room = compose(tasks)
    assert room.name == "pour+drawer+cabinet+oven" and [p.name for p in room.parts] == list(NAMES)
    # the first task is the one the room's outcome, intent and start are
    assert room.outcome == tasks[0].outcome and room.intent == tasks[0].intent
    np.testing.assert_array_equal(room.scene.start.T_world, tasks[0].scene.start.T_world)
    assert room.scene.held == tasks[0].scene.held
    assert set(room.scene.bodies) == {b for t in tasks for b in t.scene.bodies}
    assert set(room.scene.joints) == {"drawer", "door", "oven_door"}
    balls = [footprint(p) for p in room.parts]
    for i, (c, r) in enumerate(balls):
        for c2, r2 in balls[:i]:
            assert np.linalg.norm(c - c2) >= r + r2 + CLEARANCE - 1e-9
    for t, p in zip(tasks, room.parts, strict=True):  # turned about the base's vertical only
        for name, b in t.scene.bodies.items():
            moved = p.scene.bodies[name].T_world
            assert _horizontal(moved) == pytest.approx(_horizontal(b.T_world))
            assert moved[2, 3] == pytest.approx(b.T_world[2, 3])
            np.testing.assert_allclose(moved[:3, 2], b.T_world[:3, 2], atol=1e-12)  # z stays up
    assert room.parts[0] is tasks[0] and compose([tasks[1]]) is tasks[1]


def test_each_part_is_judged_on_the_room_s_readings():
    scene = make_scene(compose([find_task("drawer"), find_task("cabinet")]))
    out = scene.outcome()
    assert set(out["tasks"]) == {"drawer", "cabinet"}
    assert out["tasks"]["cabinet"] == {"done": False, "success": False, "progress": 0.0}
    assert {"drawer.position", "door.position"} <= set(out["readings"])
    assert set(scene.objects(np.eye(4))) == {"drawer_handle", "door_handle"}


def test_clashing_names_and_a_second_held_object_are_refused():
    pour = find_task("pour")
    with pytest.raises(TaskError, match="'bottle' is also a name in an earlier task"):
        compose([pour, pour])
    renamed = dataclasses.replace(pour.scene, bodies={"cup": dataclasses.replace(pour.scene.bodies["mug"],
                                                                                   name="cup")})
    other = dataclasses.replace(pour, name="pour2", scene=renamed)
    with pytest.raises(TaskError, match="bottle"):  # its held bottle's name clashes first
        compose([pour, other])
    tip = renamed.held.frames["bottle_tip"]
    held = dataclasses.replace(renamed.held, name="flask", frames={"flask_tip": tip})
    with pytest.raises(TaskError, match=r"scene\.held: the hand already holds 'bottle'"):
        compose([pour, dataclasses.replace(other, scene=dataclasses.replace(renamed, held=held))])


def test_sctd_sim_takes_several_tasks():
    p = argparse.ArgumentParser()
    add_service_arguments(p)
    one = _settings_from_args(p.parse_args([]))
    assert one.task.name == "pour" and one.task.parts == ()
    two = _settings_from_args(p.parse_args(["--task", "drawer", "--task", "cabinet"]))
    assert two.task.name == "drawer+cabinet" and [t.name for t in two.task.parts] == ["drawer", "cabinet"]
    with pytest.raises(ValueError, match=r"--task: .*'drawer' is also a name in an earlier task"):
        _settings_from_args(p.parse_args(["--task", "drawer", "--task", "drawer"]))


def test_no_task_is_placed_behind_another_tasks_wall():
    """The light switch's wall is a plane solid behind it: placed after the drawer and
    the cabinet (which it would have cut through unturned), it is turned until both, and
    the hand's start, are in front of it; placed first, the others go in front of it."""
    from sctd.task.compose import walls

    for names in (["drawer", "cabinet", "light_switch"], ["light_switch", "drawer", "cabinet"]):
        room = compose([find_task(n) for n in names])
        (p, n), = [w for part in room.parts for w in walls(part)]
        for part in room.parts:
            if part.name != "light_switch":
                c, r = footprint(part)
                assert float(n @ (c - p)) >= r - 1e-9, (names, part.name)
        assert float(n @ (room.scene.start.T_world[:3, 3] - p)) >= 0.0
    unturned = compose([find_task("drawer"), find_task("cabinet")])
    (p, n), = walls(find_task("light_switch"))
    c, r = footprint(unturned.parts[0])
    assert float(n @ (c - p)) < r  # (where it stands in its own file, it would cut the drawer)
