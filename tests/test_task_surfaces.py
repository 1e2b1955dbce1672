"""Surfaces, push buttons and press steps in task files: tasks/light_switch.yaml reads as it
says, and every bad field is refused naming the file and the field."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import yaml

from sctd.task import TaskError, find_task, shipped_folder, task_from_document
from sctd.task.kinds.press import Press
from sctd.task.kinds.reach import Reach
from sctd.task.kinds.surface import Button, Surface
from sctd.task.model import PRESS_MARGIN, TeachStep

SWITCH = shipped_folder() / "light_switch.yaml"
DELETE = object()


def switch_doc() -> dict:
    return yaml.safe_load(SWITCH.read_text())


def _set(doc: dict, path: str, value) -> None:
    *head, last = path.split(".")
    d = doc
    for k in head:
        d = d[int(k)] if isinstance(d, list) else d[k]
    key = int(last) if isinstance(d, list) else last
    if value is DELETE:
        del d[key]
    else:
        d[key] = value


def with_stylus(doc: dict) -> dict:
    """The switch pressed with the tip of a stylus the hand holds, 12 cm along its x."""
    doc = copy.deepcopy(doc)
    doc["scene"]["held"] = {"name": "stylus", "mass": 0.05, "com": [0.06, 0.0, 0.0],
                            "frames": {"stylus_tip": {"position": [-0.12, 0.0, 0.0]}}}
    doc["scene"]["bodies"]["light_switch"]["surface"]["touch"] = ["stylus_tip"]
    doc["intent"][0]["press"]["frame"] = "stylus_tip"
    doc["intent"][1]["reach"]["frame"] = "stylus_tip"
    return doc


def test_the_light_switch_reads_as_the_file_says():
    t = find_task("light_switch")
    body = t.scene.bodies["light_switch"]
    assert t.object == "light_switch" and t.outcome.time_limit == 30
    np.testing.assert_array_equal(body.T_world[:3, 3], [0.68, 0.08, 0.74])
    np.testing.assert_array_equal(body.T_world[:3, 0], [-1.0, 0.0, 0.0])  # x out of the wall, to the arm
    assert body.surface == Surface(2500.0, 50.0, 0.5, 0.01, ("hand",))
    assert body.button == Button(0.015, 0.006, 0.003, 250.0, 3.0)
    assert body.button.click_force == pytest.approx(3.75)
    press, retreat = (s.action for s in t.intent)
    assert isinstance(press, Press) and isinstance(retreat, Reach)
    assert (press.frame(), press.button, press.force) == ("hand", "light_switch", 8.0)
    assert str(press.until.reading) == "light_switch.on" and press.until.is_ is True
    assert t.teach.press_speed == 0.02
    assert t.teach.step("press") == TeachStep(margin=(0.005, 0.007), miss=0.03)
    assert TeachStep().margin is None and PRESS_MARGIN[0] < PRESS_MARGIN[1]


def test_a_surface_touches_every_frame_of_the_hand_unless_told():
    doc = with_stylus(switch_doc())
    t = task_from_document(doc, "mine.yaml")
    assert t.scene.bodies["light_switch"].surface.touch == ("stylus_tip",)
    assert t.intent[0].action.frame() == "stylus_tip"
    del doc["scene"]["bodies"]["light_switch"]["surface"]["touch"]
    t = task_from_document(doc, "mine.yaml")
    assert t.scene.bodies["light_switch"].surface.touch == ("hand", "stylus_tip")


def test_a_press_may_come_first_or_after_a_reach():
    doc = switch_doc()
    doc["intent"].insert(0, {"name": "near", "reach": {"frame": "hand", "to": [0.1, 0, 0],
                                                       "reached": {"radial": 0.02}}})
    t = task_from_document(doc, "mine.yaml")
    assert [s.name for s in t.intent] == ["near", "press", "retreat"]


BODY = "scene.bodies.light_switch"


@pytest.mark.parametrize(("path", "value", "where", "problem"), [
    (f"{BODY}.surface", DELETE, f"{BODY}.button", "a button sits in its body's surface"),
    (f"{BODY}.surface.stiffness", 0, f"{BODY}.surface.stiffness", "must be > 0.0"),
    (f"{BODY}.surface.stiffness", 1.0e6, f"{BODY}.surface.stiffness", "must be <= 50000"),
    (f"{BODY}.surface.stiffness", DELETE, f"{BODY}.surface.stiffness", "missing"),
    (f"{BODY}.surface.friction", -0.1, f"{BODY}.surface.friction", "must be >= 0.0"),
    (f"{BODY}.surface.friction_speed", 0, f"{BODY}.surface.friction_speed", "must be > 0.0"),
    (f"{BODY}.surface.colour", "white", f"{BODY}.surface.colour", "unknown field"),
    (f"{BODY}.surface.touch", [], f"{BODY}.surface.touch", "expected a non-empty list of frames"),
    (f"{BODY}.surface.touch", "hand", f"{BODY}.surface.touch", "expected a non-empty list of frames"),
    (f"{BODY}.surface.touch", ["hand", "hand"], f"{BODY}.surface.touch", "a frame is listed twice"),
    (f"{BODY}.surface.touch", ["elbow"], f"{BODY}.surface.touch[0]",
     "expected a frame that moves with the hand, got 'elbow' (frames: hand)"),
    (f"{BODY}.button.radius", 0, f"{BODY}.button.radius", "must be > 0.0"),
    (f"{BODY}.button.travel", DELETE, f"{BODY}.button.travel", "missing"),
    (f"{BODY}.button.click", 0.007, f"{BODY}.button.click", "must be at most the travel 0.006"),
    (f"{BODY}.button.spring", -1, f"{BODY}.button.spring", "must be >= 0.0"),
    (f"{BODY}.button.preload", "hard", f"{BODY}.button.preload", "expected a number"),
    (f"{BODY}.button.colour", "white", f"{BODY}.button.colour", "unknown field"),
    ("scene.start.position", [0.70, 0.08, 0.74], "scene.start",
     "hand starts 0.02 m behind the surface of 'light_switch'"),
    ("outcome.done", {"reading": "light_switch.on", "at_least": 1}, "outcome.done",
     "light_switch.on is a flag: compare it with is: true|false"),
    ("outcome.done", {"reading": "light_switch.touching", "at_most": 0}, "outcome.done",
     "light_switch.touching is a flag"),
    ("outcome.done", {"reading": "light_switch.max_force", "is": False}, "outcome.done",
     "light_switch.max_force is a number"),
    ("outcome.done", {"reading": "light_switch.colour", "is": True}, "outcome.done.reading",
     "a button reports force, max_force, touching, position, on, presses; got 'colour'"),
    ("intent.0.press.button", "wall", "intent[0].press.button",
     "expected a body with a button, got 'wall' (buttons: light_switch)"),
    ("intent.0.press.frame", "elbow", "intent[0].press.frame",
     "expected a frame that touches the surface of 'light_switch', got 'elbow' (its touch: hand)"),
    ("intent.0.press.force", 3.5, "intent[0].press.force",
     "the button takes 3.75 N to push to its click depth: a push of at most 3.5 N never switches it"),
    ("intent.0.press.force", -1, "intent[0].press.force", "must be > 0.0"),
    ("intent.0.press.until", DELETE, "intent[0].press.until", "missing"),
    ("intent.0.press.until", {"reading": "light_switch.lit", "is": True}, "intent[0].press.until.reading",
     "got 'lit'"),
    ("intent.0.press.speed", 0.01, "intent[0].press.speed", "unknown field"),
    ("intent.1", {"name": "tip", "upright": {"below": 0.3}}, "intent[1].upright",
     "a upright step moves the frame of a reach before it: no reach comes before it"),
    ("teach.steps.press.margin", [-0.001, 0.002], "teach.steps.press.margin", "expected depths >= 0"),
    ("teach.steps.press.margin", [0.004, 0.002], "teach.steps.press.margin", "low < high"),
    ("teach.steps.press.yaw", 0.2, "teach.steps.press.yaw", "unknown field (allowed: margin, miss)"),
    ("teach.speeds.press", 0, "teach.speeds.press", "must be > 0.0"),
])
def test_a_bad_surface_button_or_press_is_refused_naming_the_field(path, value, where, problem):
    doc = switch_doc()
    _set(doc, path, value)
    with pytest.raises(TaskError) as e:
        task_from_document(doc, "mine.yaml")
    assert str(e.value).startswith(f"mine.yaml: {where}: "), str(e.value)
    assert problem in str(e.value)


def test_a_surface_and_the_held_object_do_not_share_a_name():
    doc = with_stylus(switch_doc())
    doc["scene"]["held"]["name"] = "light_switch"
    with pytest.raises(TaskError, match=r"scene.bodies.light_switch.surface: the held object is called "
                                        r"'light_switch' too"):
        task_from_document(doc, "mine.yaml")


def test_a_held_frame_that_starts_behind_the_wall_is_refused():
    """The stylus, 12 cm ahead of the hand, 20 cm in front of the wall at the file's start:
    with the hand 10 cm nearer it would start 2 cm into the wall."""
    doc = with_stylus(switch_doc())
    task_from_document(doc, "mine.yaml")
    doc["scene"]["start"]["position"] = [0.58, 0.08, 0.74]
    with pytest.raises(TaskError, match=r"scene.start: stylus_tip starts 0.02 m behind the surface"):
        task_from_document(doc, "mine.yaml")


def test_a_press_needs_a_push_that_switches_the_button():
    """The push bound must exceed the button's preload plus its spring at the click depth."""
    doc = switch_doc()
    button = doc["scene"]["bodies"]["light_switch"]["button"]
    button.update(preload=1.0, spring=1000.0, click=0.005)  # 6 N to the click
    doc["intent"][0]["press"]["force"] = 6.0
    with pytest.raises(TaskError, match="takes 6 N to push to its click depth"):
        task_from_document(doc, "mine.yaml")
    doc["intent"][0]["press"]["force"] = 6.5
    assert math.isclose(task_from_document(doc, "mine.yaml").scene.bodies["light_switch"].button.click_force,
                        6.0)


def test_sctd_tasks_shows_the_switch(capsys):
    import json

    from sctd.cli.main import main

    assert main(["tasks", "show", "light_switch"]) == 0
    out = capsys.readouterr().out
    assert "surface light_switch: 2500 N/m, friction 0.5, touched by hand\n" in out
    assert "button light_switch: radius 15 mm, travel 6 mm, switches at 3 mm (3.75 N)\n" in out
    assert "done (switched on) at light_switch.on is true, light_switch.touching is false;" in out
    assert "fails: pressed too hard" in out and "intent: press (press), retreat (reach)\n" in out
    assert main(["tasks", "show", "light_switch", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["surfaces"]["light_switch"]["touch"] == ["hand"]
    assert s["surfaces"]["light_switch"]["button"]["click_force"] == pytest.approx(3.75)
    assert main(["tasks", "show", "pour", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["surfaces"] == {}
