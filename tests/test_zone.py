"""A goal pose held for a time: a task file's ``zones`` read and refused as the rest of
a task file is, the simulator's scene timing a frame of the hand inside one (``inside``,
``dwell``, ``max_dwell``), an outcome that asks for the frame held there for a time, and
composed rooms keeping every task's heads and zones."""

from __future__ import annotations

import copy
import json
import math

import numpy as np
import pytest
import yaml

from sctd import se3
from sctd.task import TaskError, find_task, shipped_folder, task_from_document
from sctd.task.compose import compose
from sctd.task.judge import holds
from sctd.task.kinds.zone import Zone
from sctd_sim.scenes import TaskScene

DT = 1e-3
AT_LIPS = {"frame": "cup_rim", "around": "mouth", "position": [0.01, 0.0, 0.01],
           "within": [0.01, 0.01, 0.008], "axis": [0, 0, 1], "tilt": "20 deg"}


def drink_with_zone(zone: dict | None = None, done_dwell: float = 0.5) -> dict:
    """The drink task, its outcome asking for the rim held at the lips for a time."""
    doc = yaml.safe_load((shipped_folder() / "drink.yaml").read_text())
    doc["name"] = "hold_cup"
    doc["scene"]["zones"] = {"at_lips": copy.deepcopy(AT_LIPS) if zone is None else zone}
    doc["outcome"]["done"] = {"reading": "at_lips.dwell", "at_least": done_dwell}
    return doc


def test_a_zone_reads_as_the_file_says():
    t = task_from_document(drink_with_zone(), "hold_cup.yaml")
    z = t.scene.zones["at_lips"]
    assert (z.name, z.frame, z.around) == ("at_lips", "cup_rim", "mouth")
    np.testing.assert_allclose(z.position, [0.01, 0.0, 0.01])
    np.testing.assert_allclose(z.within, [0.01, 0.01, 0.008])
    assert z.tilt == pytest.approx(math.radians(20))
    assert Zone.quantities == ("inside", "dwell", "max_dwell")
    # one number: the same tolerance along every axis; no axis: any orientation
    t = task_from_document(drink_with_zone({"frame": "hand", "around": "mouth", "position": [0.1, 0, 0],
                                            "within": 0.02}), "f.yaml")
    z = t.scene.zones["at_lips"]
    assert z.tilt is None and z.within.tolist() == [0.02] * 3


@pytest.mark.parametrize(("key", "value", "where", "problem"), [
    ("frame", "bottle_tip", "scene.zones.at_lips.frame", "expected 'hand' or a frame of what the hand holds"),
    ("around", "chin", "scene.zones.at_lips.around", "unknown body 'chin' (bodies: mouth)"),
    ("within", [0.01, 0.0, 0.01], "scene.zones.at_lips.within", "must be > 0 on every axis"),
    ("within", -0.01, "scene.zones.at_lips.within", "must be > 0.0"),
    ("position", [0.01, 0.0], "scene.zones.at_lips.position", "expected a list of 3"),
    ("tilt", None, "scene.zones.at_lips", "axis and tilt go together"),
    ("axis", [0, 0, 0], "scene.zones.at_lips.axis", ""),
    ("tilt", "200 deg", "scene.zones.at_lips.tilt", "must be <= 3.14"),
    ("colour", "red", "scene.zones.at_lips.colour", "unknown field"),
])
def test_a_zone_is_refused_where_it_is_wrong(key, value, where, problem):
    zone = copy.deepcopy(AT_LIPS)
    if value is None:
        del zone[key]
    else:
        zone[key] = value
    with pytest.raises(TaskError) as e:
        task_from_document(drink_with_zone(zone), "hold_cup.yaml")
    assert e.value.path == where and problem in e.value.problem, str(e.value)


def test_a_zone_shares_the_names_and_its_readings_are_checked():
    doc = drink_with_zone()
    doc["scene"]["zones"] = {"face": AT_LIPS}
    with pytest.raises(TaskError, match="the name 'face' is used twice"):
        task_from_document(doc, "f.yaml")
    doc = drink_with_zone()
    doc["outcome"]["done"] = {"reading": "at_lips.held", "at_least": 1.0}
    with pytest.raises(TaskError, match="a zone reports inside, dwell, max_dwell; got 'held'"):
        task_from_document(doc, "f.yaml")
    doc["outcome"]["done"] = {"reading": "at_lips.inside", "is": True}  # a flag
    assert task_from_document(doc, "f.yaml").scene.zones


def _hand_with_rim_at(t, offset, tilt=0.0):
    """The hand's pose that puts the cup's rim at ``offset`` from the zone's goal (mouth
    frame), the cup tilted by ``tilt`` about the mouth's y."""
    T_mouth = t.scene.bodies["mouth"].T_world
    goal = se3.transform_from_rt(se3.matrix_from_rotvec([0.0, tilt, 0.0]),
                                 np.asarray(AT_LIPS["position"]) + offset)
    return T_mouth @ goal @ np.linalg.inv(t.scene.held.frames["cup_rim"])


def test_the_scene_times_the_rim_held_at_the_lips():
    """Inside: the dwell grows by each step; a tilt past the tolerance or a step out of
    the box ends it (back to 0) and the longest stays; the outcome asks for 0.5 s."""
    t = task_from_document(drink_with_zone(), "hold_cup.yaml")
    scene = TaskScene(t)
    still = np.zeros(6)

    def run(T, n):
        for _ in range(n):
            scene.step(T, still, DT)
        return scene.readings()

    r = run(_hand_with_rim_at(t, [0.005, -0.005, 0.004], tilt=0.3), 300)  # 17 deg: inside
    assert r["at_lips.inside"] is True and r["at_lips.dwell"] == pytest.approx(0.3)
    assert not scene.outcome()["done"]
    r = run(_hand_with_rim_at(t, [0.0, 0.0, 0.0], tilt=0.4), 10)  # 23 deg: outside
    assert r["at_lips.inside"] is False and r["at_lips.dwell"] == 0.0
    assert r["at_lips.max_dwell"] == pytest.approx(0.3)
    r = run(_hand_with_rim_at(t, [0.0, 0.0, 0.009]), 10)  # 9 mm above: outside (8 mm)
    assert r["at_lips.inside"] is False
    r = run(_hand_with_rim_at(t, [0.0, 0.0, 0.0]), 500)
    assert r["at_lips.dwell"] == pytest.approx(0.5) and scene.outcome()["done"]
    assert holds(t.outcome.done, r, scene.positions())
    scene.reset()
    assert scene.readings()["at_lips.max_dwell"] == 0.0


def test_zone_inside_is_about_the_body_frame():
    """The box is along the body's axes and the axis in its frame: a body turned by 90
    deg turns both."""
    z = Zone("z", "hand", "b", np.zeros(3), np.array([0.05, 0.01, 0.01]), np.array([1.0, 0.0, 0.0]), 0.1)
    turned = se3.transform_from_rt(se3.matrix_from_rotvec([0.0, 0.0, math.pi / 2]), [1.0, 0.0, 0.0])
    z_along_world_y = se3.matrix_from_rotvec([-math.pi / 2, 0.0, 0.0])  # the body's x, turned
    assert z.inside(turned, se3.transform_from_rt(z_along_world_y, [1.0, 0.04, 0.0]))  # 4 cm along x
    assert not z.inside(turned, se3.transform_from_rt(z_along_world_y, [1.04, 0.0, 0.0]))  # along -y
    assert not z.inside(turned, se3.transform_from_rt(np.eye(3), [1.0, 0.04, 0.0]))  # z up: tilted


def test_a_composed_room_keeps_every_tasks_heads_and_zones():
    hold = task_from_document(drink_with_zone(), "hold_cup.yaml")
    room = compose([find_task("drawer"), hold])
    assert set(room.scene.heads) == {"face"} and set(room.scene.zones) == {"at_lips"}
    scene = TaskScene(room)
    assert {"face.force", "at_lips.dwell"} <= set(scene.readings())


def present_cup(tmp_path) -> str:
    """A task built here on the drink's scene (no contents, no container): bring the
    cup's rim to the lips, upright, and hold it there 1 s without pressing the face."""
    doc = drink_with_zone(done_dwell=1.0)
    doc["name"] = "present_cup"
    del doc["scene"]["held"]["contents"]
    del doc["scene"]["bodies"]["mouth"]["container"]
    doc["outcome"] = {"done": {"reading": "at_lips.dwell", "at_least": 1.0},
                      "success": {"reading": "face.max_force", "below": 5.0}, "done_reason": "presented",
                      "fail": [{"when": {"reading": "face.max_force", "at_least": 5.0},
                                "reason": "pressed into the face"}],
                      "progress": "at_lips.max_dwell",
                      "clock": {"near": {"frame": "cup_rim", "to": "mouth", "within": 0.25}},
                      "time_limit": 60}
    doc["intent"] = doc["intent"][:1]  # bring: the rim 1 cm in front of the lips, upright
    doc["teach"] = {"start": 0.05, "speeds": {"reach": 0.06}, "steps": {"bring": {"yaw": 0.15}}}
    path = tmp_path / "present.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return str(path)


@pytest.mark.slow
def test_a_dwell_is_demonstrated_and_held_by_the_user(tmp_path):
    """The demonstrator, its steps shown, holds the cup at the lips until the dwell is
    done, and keeps the demonstrations; the simulated user, its reach made, holds still
    there too: the competent baseline presents the cup in both lockstep trials."""
    from tests.conftest import run_sctd

    task = present_cup(tmp_path)
    taught = run_sctd("teach", "--task", task, "--demos", "2", "--out", str(tmp_path / "demos"),
                      "--seed", "0", "--logs", str(tmp_path / "logs"), timeout=300)
    assert taught.returncode == 0, taught.stdout + taught.stderr
    assert "kept 2 of 2 demonstrations" in taught.stdout and "at_lips.dwell" in taught.stdout
    run = run_sctd("eval", "--skill", "teleop", "--task", task, "--trials", "2", "--lockstep", "--json",
                   timeout=300)
    assert run.returncode == 0, run.stderr
    (result,) = json.loads(run.stdout)["results"]
    assert [(t["outcome"], t["reason"]) for t in result["per_trial"]] == [("success", "presented")] * 2
    assert all(t["progress"] >= 1.0 for t in result["per_trial"])
