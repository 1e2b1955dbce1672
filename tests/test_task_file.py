"""Task files: the shipped ones load, a bad one is refused naming the file and the field,
the registry finds tasks by path, by name and through entry points, and the predicates
mean what docs/tasks.md says."""

from __future__ import annotations

import copy
import dataclasses
import math
import os
from types import SimpleNamespace

import numpy as np
import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from sctd.task import (
    TaskError,
    add_to_path,
    find_task,
    known_tasks,
    load_task,
    shipped_folder,
    task_from_document,
)
from sctd.task import catalog as catalog_module
from sctd.task.judge import holds, thresholds
from sctd.task.kinds.move_joint import MoveJoint
from sctd.task.kinds.reach import Reach
from sctd.task.kinds.tilt import Tilt, Upright
from sctd.task.model import (
    AllOf,
    AnyOf,
    Compare,
    Near,
    Not,
    Reading,
    Teach,
    TeachStep,
)
from tests.conftest import ROOT

POUR = shipped_folder() / "pour.yaml"


def pour_doc() -> dict:
    return yaml.safe_load(POUR.read_text())


def test_the_shipped_tasks_load_under_their_file_names():
    names = sorted(p.stem for p in shipped_folder().glob("*.yaml"))
    assert {"pour", "drawer", "cabinet"} <= set(names)
    for name in names:
        t = find_task(name)
        assert t.name == name and t.object in t.scene.bodies and t.outcome.time_limit > 0
    pour = find_task("pour")
    assert pour.scene.held.contents.flow_angle == math.radians(75.0)
    np.testing.assert_array_equal(pour.scene.bodies["mug"].T_world[:3, :3], np.diag([-1.0, -1.0, 1.0]))
    assert thresholds(pour.outcome.done) == {"bottle.poured": 0.5}
    assert thresholds(find_task("drawer").outcome.done) == {"drawer.position": 0.2}


def _set(doc: dict, path: str, value):
    *head, last = path.split(".")
    d = doc
    for k in head:
        d = d[int(k)] if isinstance(d, list) else d[k]
    key = int(last) if isinstance(d, list) else last
    if value is DELETE:
        del d[key]
    else:
        d[key] = value


DELETE = object()


@pytest.mark.parametrize(("path", "value", "where", "problem"), [
    ("sctd_task", 2, "sctd_task", "reads task files of version 1, got 2"),
    ("name", "Pour Now", "name", "expected a name of lower-case letters"),
    ("object", "cup", "object", "unknown body 'cup' (bodies: mug)"),
    ("colour", "red", "colour", "unknown field"),
    ("scene.bodies.mug.position", "here", "scene.bodies.mug.position", "expected a list of 3 numbers"),
    ("scene.bodies.mug.rpy", [0, 0, "half a turn"], "scene.bodies.mug.rpy[2]", "expected an angle in rad"),
    ("scene.bodies.mug.container.rim_margin", 0.05, "scene.bodies.mug.container.rim_margin",
     "must be below the radius 0.04"),
    ("scene.start.vary.yaw", "200 deg", "scene.start.vary.yaw", "must be <= 3.14159"),
    ("scene.held.contents.outlet", "spout", "scene.held.contents.outlet", "unknown frame 'spout'"),
    ("scene.held.contents.into", "table", "scene.held.contents.into", "expected a body with a container"),
    ("scene.held.mass", -1, "scene.held.mass", "must be >= 0.0"),
    ("scene.held.frames.mug", {"position": [0, 0, 0.1]}, "scene", "the name 'mug' is used twice"),
    ("outcome.done", {"reading": "bottle.fullness", "at_least": 1}, "outcome.done.reading",
     "a contents reports poured, spilled, remaining, flowing; got 'fullness'"),
    ("outcome.done", {"reading": "cork.poured", "at_least": 1}, "outcome.done.reading",
     "unknown element 'cork'"),
    ("outcome.done", {"reading": "bottle.flowing", "at_least": 1}, "outcome.done",
     "bottle.flowing is a flag: compare it with is: true|false"),
    ("outcome.done", {"reading": "bottle.poured"}, "outcome.done", "expected a comparison"),
    ("outcome.done", {"some": []}, "outcome.done.some", "unknown predicate"),
    ("outcome.clock", {"near": {"frame": "spout", "to": "mug", "within": 0.3}}, "outcome.clock.near.frame",
     "unknown frame 'spout' (frames: hand, mug, bottle_tip)"),
    ("outcome.fail", {"when": True}, "outcome.fail", "expected a list of {when, reason}"),
    ("outcome.time_limit", 0, "outcome.time_limit", "must be > 0.0"),
    ("outcome.progress", DELETE, "outcome.progress", "missing"),
])
def test_a_bad_task_file_is_refused_naming_the_field(path, value, where, problem):
    doc = pour_doc()
    _set(doc, path, value)
    with pytest.raises(TaskError) as e:
        task_from_document(doc, "mine.yaml")
    assert str(e.value).startswith(f"mine.yaml: {where}: "), str(e.value)
    assert problem in str(e.value)


DRAWER = shipped_folder() / "drawer.yaml"


@pytest.mark.parametrize(("file", "path", "value", "where", "problem"), [
    (POUR, "intent", DELETE, "intent", "missing"),
    (POUR, "intent", [], "intent", "expected a non-empty list of steps"),
    (POUR, "intent.0.name", DELETE, "intent[0].name", "missing"),
    (POUR, "intent.0.name", "done", "intent[0].name", "'done' is the phase after the last step"),
    (POUR, "intent.1.name", "bring", "intent[1].name", "'bring' is the name of an earlier step"),
    (POUR, "intent.0.colour", "red", "intent[0].colour", "unknown field"),
    (POUR, "intent.2.tilt", {"to": 1.0, "until": True}, "intent[2]",
     "expected one of reach, tilt, upright, move_joint, press, grasp, place, turn; got tilt, upright"),
    (POUR, "intent.0", {"name": "tip", "upright": {"below": 0.3}}, "intent[0].upright",
     "the first step must be a reach"),
    (POUR, "intent.0.reach.frame", "mug", "intent[0].reach.frame",
     "expected a frame that moves with the hand, got 'mug' (frames: hand, bottle_tip)"),
    (POUR, "intent.0.reach.handle", "drawer", "intent[0].reach", "expected one goal"),
    (POUR, "intent.0.reach.to", [0, 0], "intent[0].reach.to", "expected a list of 3 numbers"),
    (POUR, "intent.0.reach.speed", 1, "intent[0].reach.speed", "unknown field"),
    (POUR, "intent.0.reach.reached", DELETE, "intent[0].reach", "expected reached, until or both"),
    (POUR, "intent.0.reach.reached", {}, "intent[0].reach.reached", "expected radial, height or both"),
    (POUR, "intent.0.reach.reached", {"radial": -0.01}, "intent[0].reach.reached.radial", "must be > 0.0"),
    (POUR, "intent.0.reach.lift", {"height": 0.04, "between": [0.07, 0.02]}, "intent[0].reach.lift.between",
     "expected [low, high] with low < high"),
    (POUR, "intent.0.reach.accept", {"height": [0.0, 0.1]}, "intent[0].reach.accept.radial", "missing"),
    (POUR, "intent.0.reach.accept", {"radial": 0.03, "tilt": "200 deg"}, "intent[0].reach.accept.tilt",
     "must be <= 3.14159"),
    (POUR, "intent.0.reach.orientation", "upright", "intent[0].reach.orientation",
     "expected free or {upright: <tilt>}"),
    (POUR, "intent.0.reach.orientation", {"upright": 0}, "intent[0].reach.orientation.upright",
     "must be > 0.0"),
    (POUR, "intent.0.reach.until", {"reading": "bottle.full", "is": True}, "intent[0].reach.until.reading",
     "a contents reports poured, spilled, remaining, flowing; got 'full'"),
    (POUR, "intent.1.tilt.until", {"reading": "cork.poured", "at_least": 0.5}, "intent[1].tilt.until.reading",
     "unknown element 'cork'"),
    (POUR, "intent.1.tilt.until", DELETE, "intent[1].tilt.until", "missing"),
    (POUR, "intent.1.tilt.to", 0, "intent[1].tilt.to", "must be > 0.0"),
    (POUR, "intent.1.tilt.off", 0.033, "intent[1].tilt.off",
     "unknown field (allowed: off_by, to, until, weight)"),
    (POUR, "intent.1.tilt.weight", -1, "intent[1].tilt.weight", "must be >= 0.0"),
    (POUR, "intent.2.upright", {"below": 0.3, "above": 0.1}, "intent[2].upright.above", "unknown field"),
    (POUR, "intent.2", {"name": "pull", "move_joint": {"joint": "drawer"}}, "intent[2].move_joint.joint",
     "unknown joint 'drawer' (joints: none)"),
    (DRAWER, "intent.1.move_joint.joint", "lid", "intent[1].move_joint.joint",
     "unknown joint 'lid' (joints: drawer)"),
    (DRAWER, "outcome.done", {"reading": "drawer.max_position", "at_least": 0.2},
     "intent[1].move_joint.joint", "outcome.done sets no at_least on drawer.position"),
    (DRAWER, "intent.0.reach.handle", "lid", "intent[0].reach.handle",
     "unknown joint 'lid' (joints: drawer)"),
    (DRAWER, "intent.1.move_joint.back", {"reading": "drawer.held"}, "intent[1].move_joint.back",
     "expected a comparison"),
    (DRAWER, "intent.0.reach.frame", "drawer_handle", "intent[0].reach.frame",
     "expected a frame that moves with the hand, got 'drawer_handle' (frames: hand)"),
])
def test_a_bad_intent_is_refused_naming_the_field(file, path, value, where, problem):
    doc = yaml.safe_load(file.read_text())
    _set(doc, path, value)
    with pytest.raises(TaskError) as e:
        task_from_document(doc, "mine.yaml")
    assert str(e.value).startswith(f"mine.yaml: {where}: "), str(e.value)
    assert problem in str(e.value)


@pytest.mark.parametrize(("file", "path", "value", "where", "problem"), [
    (POUR, "teach.colour", 1, "teach.colour", "unknown field"),
    (POUR, "teach.start", -0.1, "teach.start", "must be >= 0.0"),
    (POUR, "teach.speed", 1.5, "teach.speed", "must be <= 0.9"),
    (POUR, "teach.via_at", [0.0, 0.5], "teach.via_at", "fractions strictly between 0 and 1"),
    (POUR, "teach.start_height", [0.0, -0.1], "teach.start_height", "low < high"),
    (POUR, "teach.speeds", {"carry": 0.1}, "teach.speeds.carry",
     "unknown field (allowed: joint, press, reach, tilt, turn)"),
    (POUR, "teach.speeds", {"reach": 0}, "teach.speeds.reach", "must be > 0.0"),
    (POUR, "teach.steps", {"tip": {"yaw": 0.1}}, "teach.steps.tip",
     "unknown field (allowed: bring, pour, upright)"),
    (POUR, "teach.steps.pour", {"yaw": 0.1}, "teach.steps.pour.yaw", "unknown field (allowed: to)"),
    (POUR, "teach.steps.pour", {"to": ["100 deg", "90 deg"]}, "teach.steps.pour.to", "low < high"),
    (POUR, "teach.steps.pour", {"to": [1.0]}, "teach.steps.pour.to", "expected a list of 2 angles"),
    (POUR, "teach.steps.bring", {"miss": 0}, "teach.steps.bring.miss", "must be > 0.0"),
    (POUR, "teach.steps.upright", {"to": [0.1, 0.2]}, "teach.steps.upright.to", "unknown field"),
    (DRAWER, "teach.steps.reach", {"height": [0.0, 0.1]}, "teach.steps.reach.height",
     "only a reach to a point (to) has a goal height to vary"),
    (DRAWER, "teach.steps.pull", {"to": [0.2, 0.35]}, "teach.steps.pull.to",
     "expected positions within the joint's travel (0, 0.3]"),
])
def test_a_bad_teach_section_is_refused_naming_the_field(file, path, value, where, problem):
    test_a_bad_intent_is_refused_naming_the_field(file, path, value, where, problem)


def test_the_teach_section_reads_as_the_file_says():
    """Degrees are radians, unnamed steps and fields take the defaults, a task without
    the section varies as the defaults say."""
    pour = find_task("pour").teach
    assert pour.step("pour").to == (math.radians(100.0), math.radians(120.0))
    assert pour.step("bring").yaw == 0.30 and pour.step("bring").miss == 0.06
    assert pour.step("upright") == TeachStep() and pour.start_height == (-0.10, 0.0)
    assert (pour.reach_speed, pour.tilt_rate, pour.turn_rate) == (0.10, 0.65, Teach().turn_rate)
    doc = yaml.safe_load(DRAWER.read_text())
    del doc["teach"]
    assert task_from_document(doc, "d.yaml").teach == Teach()


CABINET = shipped_folder() / "cabinet.yaml"


def test_a_revolute_joint_reads_as_the_file_says():
    """The cabinet's door: its hinge line in the handle's frame (the axis normalised), its
    travel and thresholds in radians (written in degrees), its inertia from the mass felt
    at the handle and the lever."""
    task = find_task("cabinet")
    door = task.scene.joints["door"]
    assert (door.kind, door.handle, door.unit) == ("revolute", "door_handle", "rad")
    np.testing.assert_array_equal(door.hinge.point, [-0.03, 0.32, 0.0])
    np.testing.assert_array_equal(door.hinge.axis, [0.0, 0.0, 1.0])
    assert door.hinge.lever == pytest.approx(math.hypot(0.03, 0.32))
    assert door.travel == math.radians(100.0)
    assert door.inertia == pytest.approx(1.5 * (0.03**2 + 0.32**2))
    assert (door.spring, door.damping, door.friction, door.friction_speed) == (0.5, 0.8, 0.3, 0.03)
    assert thresholds(task.outcome.done) == {"door.position": math.radians(65.0)}
    swing = task.intent[1].action
    assert isinstance(swing, MoveJoint) and swing.overshoot == math.radians(5.0)
    lost = task.outcome.fail[0].when.terms[2]
    assert lost == Compare(Reading("door", "position"), above=math.radians(2.0))
    drawer = find_task("drawer").scene.joints["drawer"]
    assert (drawer.kind, drawer.hinge, drawer.unit, drawer.inertia) == ("prismatic", None, "m", 2.0)
    doc = yaml.safe_load(CABINET.read_text())
    doc["scene"]["joints"]["door"]["hinge"]["axis"] = [0, 0, -2.0]
    assert task_from_document(doc, "x").scene.joints["door"].hinge.axis.tolist() == [0.0, 0.0, -1.0]


@pytest.mark.parametrize(("file", "path", "value", "where", "problem"), [
    (CABINET, "scene.joints.door.type", "hinged", "scene.joints.door.type",
     "expected one of prismatic, revolute, got 'hinged'"),
    (CABINET, "scene.joints.door.type", DELETE, "scene.joints.door.type", "missing"),
    (CABINET, "scene.joints.door.hinge", DELETE, "scene.joints.door.hinge", "missing"),
    (CABINET, "scene.joints.door.hinge.axis", [0, 0, 0], "scene.joints.door.hinge.axis",
     "direction of zero length"),
    (CABINET, "scene.joints.door.hinge.axis", [0, 1], "scene.joints.door.hinge.axis",
     "expected a list of 3 numbers"),
    (CABINET, "scene.joints.door.hinge.point", DELETE, "scene.joints.door.hinge.point", "missing"),
    (CABINET, "scene.joints.door.hinge.point", [0.0, 0.0, 0.4], "scene.joints.door.hinge.point",
     "the handle (the frame's origin) is 0 m from the hinge line: it must be at least 0.01 m off it"),
    (CABINET, "scene.joints.door.hinge.point", [0.005, 0.0, 0.3], "scene.joints.door.hinge.point",
     "is 0.005 m from the hinge line"),
    (CABINET, "scene.joints.door.hinge.spring", 1.0, "scene.joints.door.hinge.spring", "unknown field"),
    (CABINET, "scene.joints.door.travel", 0, "scene.joints.door.travel", "must be > 0.0"),
    (CABINET, "scene.joints.door.travel", "400 deg", "scene.joints.door.travel", "must be <= 6.28"),
    (CABINET, "scene.joints.door.travel", "wide", "scene.joints.door.travel", "expected an angle in rad"),
    (CABINET, "scene.joints.door.mass", 0, "scene.joints.door.mass", "must be > 0.0"),
    (CABINET, "scene.joints.door.inertia", 0.2, "scene.joints.door.inertia", "unknown field"),
    (CABINET, "scene.joints.door.friction", -0.1, "scene.joints.door.friction", "must be >= 0.0"),
    (CABINET, "scene.joints.door.friction_speed", 0, "scene.joints.door.friction_speed", "must be > 0.0"),
    (CABINET, "scene.joints.door.grasp.release", 0.01, "scene.joints.door.grasp.release",
     "must be above the grasp radius 0.02"),
    (CABINET, "outcome.done", {"reading": "door.position", "at_least": "a lot"}, "outcome.done.at_least",
     "expected an angle in rad"),
    (CABINET, "intent.1.move_joint.overshoot", "-5 deg", "intent[1].move_joint.overshoot", "must be >= 0.0"),
    (DRAWER, "scene.joints.drawer.hinge", {"point": [0, 0.3, 0], "axis": [0, 0, 1]},
     "scene.joints.drawer.hinge", "unknown field"),
    (DRAWER, "outcome.done", {"reading": "drawer.position", "at_least": "20 deg"}, "outcome.done.at_least",
     "expected a number, got str"),
    (DRAWER, "intent.1.move_joint.overshoot", "3 deg", "intent[1].move_joint.overshoot",
     "expected a number, got str"),
])
def test_a_bad_joint_is_refused_naming_the_field(file, path, value, where, problem):
    doc = yaml.safe_load(file.read_text())
    _set(doc, path, value)
    with pytest.raises(TaskError) as e:
        task_from_document(doc, "mine.yaml")
    assert str(e.value).startswith(f"mine.yaml: {where}: "), str(e.value)
    assert problem in str(e.value)


def test_a_joint_knows_its_kind_by_its_hinge():
    door = find_task("cabinet").scene.joints["door"]
    with pytest.raises(ValueError, match="a revolute joint has a hinge"):
        dataclasses.replace(door, hinge=None)
    with pytest.raises(ValueError, match="a prismatic one none"):
        dataclasses.replace(door, kind="prismatic")


def test_a_joint_is_moved_by_the_reach_to_its_handle():
    doc = yaml.safe_load(DRAWER.read_text())
    doc["intent"][0]["reach"] = {"frame": "hand", "to": [0, 0, 0],
                                 "until": {"reading": "drawer.held", "is": True}}
    with pytest.raises(TaskError, match=r"intent\[1\]\.move_joint\.joint: the reach before it must go to the "
                                        r"handle of 'drawer'"):
        task_from_document(doc, "mine.yaml")
    doc = yaml.safe_load(DRAWER.read_text())
    doc["intent"].insert(1, {"name": "look", "reach": {"frame": "hand", "to": [0, 0, 0.1],
                                                       "reached": {"height": 0.01}}})
    with pytest.raises(TaskError, match="the reach before it must go to the handle"):
        task_from_document(doc, "mine.yaml")


def test_the_intent_reads_as_the_file_says():
    pour = find_task("pour").intent
    assert [s.name for s in pour] == ["bring", "pour", "upright"]
    bring, tilt, upright = (s.action for s in pour)
    assert isinstance(bring, Reach) and bring.frame() == "bottle_tip"
    assert bring.to.tolist() == [0.0, 0.0, 0.05]
    assert (bring.lift.height, bring.lift.start, bring.lift.span) == (0.04, 0.02, 0.05)
    assert (bring.reached.radial, bring.reached.height, bring.upright) == (0.025, 0.02, 0.5)
    assert (bring.accept.radial, bring.accept.height, bring.accept.tilt) == (0.03, (0.02, 0.10), 0.5)
    assert isinstance(tilt, Tilt) and (tilt.to, tilt.weight, tilt.off_by) == (1.65, 0.5, 0.033)
    assert thresholds(tilt.until) == {"bottle.poured": 0.5}
    assert isinstance(upright, Upright) and upright.below == 0.3
    reach, pull = (s.action for s in find_task("drawer").intent)
    assert isinstance(reach, Reach) and reach.handle == "drawer"
    assert reach.upright is None and reach.to is None
    assert reach.until == Compare(Reading("drawer", "held"), is_=True)
    assert isinstance(pull, MoveJoint) and (pull.joint, pull.overshoot) == ("drawer", 0.03)
    doc = pour_doc()
    doc["intent"][0]["reach"]["orientation"] = "free"
    doc["intent"][0]["reach"]["accept"]["tilt"] = "20 deg"
    bring = task_from_document(doc, "x").intent[0].action
    assert bring.upright is None and bring.accept.tilt == math.radians(20.0)


def test_a_bad_file_names_the_file_and_loads_nothing(tmp_path):
    f = tmp_path / "t.yaml"
    f.write_text("sctd_task: 1\nname: [\n")
    with pytest.raises(TaskError, match=r"t\.yaml.*invalid YAML"):
        load_task(f)
    f.write_text("sctd_task: 1\nname: a\nname: b\n")
    with pytest.raises(TaskError, match=r"t\.yaml"):
        load_task(f)


def test_angles_in_degrees_are_the_same_radians():
    doc = pour_doc()
    doc["scene"]["start"]["rpy"] = ["90 deg", "-45deg", 0.5]
    t = task_from_document(doc, "x")
    doc["scene"]["start"]["rpy"] = [math.pi / 2, -math.pi / 4, 0.5]
    np.testing.assert_allclose(task_from_document(doc, "x").scene.start.T_world, t.scene.start.T_world,
                               atol=1e-15)


def test_a_file_is_found_by_path_and_named_by_its_name_field(tmp_path):
    doc = pour_doc()
    doc["name"] = "pour_tea"
    f = tmp_path / "anything.yaml"
    f.write_text(yaml.safe_dump(doc))
    assert find_task(str(f)).name == "pour_tea"
    with pytest.raises(TaskError, match=r"no task of that name \(known: bottle_to_fridge, cabinet, "
                                        r"cup_to_table, drawer, (\w+, )*pour.*did you mean 'pour'"):
        find_task("pout")


def test_tasks_on_the_path_are_found_by_their_name_field(tmp_path, monkeypatch):
    """$SCTD_TASK_PATH's folders: a file found by its name field whatever the file is
    called, a shipped name shadows one on the path, a file that is no task is passed
    over, the first folder wins; add_to_path puts a file's folder first."""
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    doc = pour_doc()
    doc["name"] = "pour_tea"
    (a / "my-task.yaml").write_text(yaml.safe_dump(doc))
    doc["name"] = "pour"  # shadowed by the shipped one
    (a / "pour.yaml").write_text(yaml.safe_dump(doc))
    (a / "skill.yaml").write_text("sctd_skill: 1\n")  # no task: passed over
    doc["name"], doc["title"] = "pour_tea", "the second"
    (b / "tea.yaml").write_text(yaml.safe_dump(doc))
    monkeypatch.delenv("SCTD_TASK_PATH", raising=False)
    with pytest.raises(TaskError, match="no task of that name"):
        find_task("pour_tea")
    monkeypatch.setenv("SCTD_TASK_PATH", f"{a}:{b}")
    t = find_task("pour_tea")
    assert t.file == str(a / "my-task.yaml") and t.title != "the second"
    assert find_task("pour").file == str(shipped_folder() / "pour.yaml")
    listed = [(k.name, k.origin) for k in known_tasks()]
    assert ("pour_tea", f"SCTD_TASK_PATH {a}") in listed and [n for n, _ in listed].count("pour") == 1
    with pytest.raises(TaskError, match=r"known: .*pour_tea.*did you mean 'pour_tea'"):
        find_task("pour_te")
    monkeypatch.setenv("SCTD_TASK_PATH", str(a))
    add_to_path(b / "tea.yaml")
    assert os.environ["SCTD_TASK_PATH"] == f"{b}:{a}" and find_task("pour_tea").title == "the second"
    add_to_path("pour")  # a name: nothing to add
    assert os.environ["SCTD_TASK_PATH"] == f"{b}:{a}"


def test_packages_register_tasks_by_entry_point(tmp_path, monkeypatch):
    doc = pour_doc()
    doc["name"] = "pour_tea"
    f = tmp_path / "tea.yaml"
    f.write_text(yaml.safe_dump(doc))
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(yaml.safe_dump(pour_doc()))  # named pour, registered as something else
    module = SimpleNamespace(tea=str(f), tea_file=lambda: f, wrong=str(wrong))
    monkeypatch.setitem(__import__("sys").modules, "sctd_test_tasks", module)
    points = [SimpleNamespace(name="pour_tea", value="sctd_test_tasks:tea_file"),
              SimpleNamespace(name="pour", value="sctd_test_tasks:tea"),  # a shipped name wins
              SimpleNamespace(name="odd", value="sctd_test_tasks:wrong"),
              SimpleNamespace(name="broken", value="sctd_test_tasks:missing")]
    monkeypatch.setattr(catalog_module, "entry_points", lambda group: points if group == "sctd.tasks" else [])
    assert find_task("pour_tea").name == "pour_tea"
    assert find_task("pour").file == str(POUR)
    with pytest.raises(TaskError, match="the task found as 'odd' is named 'pour'"):
        find_task("odd")
    with pytest.raises(TaskError, match=r"entry point sctd_test_tasks:missing \(sctd.tasks\) does not give"):
        find_task("broken")
    with pytest.raises(TaskError, match="broken"):
        known_tasks()  # one broken plug-in is named, not skipped
    points.pop()
    assert [(k.name, k.origin) for k in known_tasks()][-2:] == [
        ("odd", "entry point sctd_test_tasks:wrong"), ("pour_tea", "entry point sctd_test_tasks:tea_file")]


# -- predicates -----------------------------------------------------------------------------
R = Reading("bottle", "poured")
FLOW = Reading("bottle", "flowing")


@given(st.floats(-10, 10), st.floats(-10, 10), st.floats(-10, 10))
def test_a_comparison_is_its_bounds(x, lo, hi):
    r = {"bottle.poured": x}
    assert holds(Compare(R, at_least=lo), r, {}) == (x >= lo)
    assert holds(Compare(R, at_most=hi), r, {}) == (x <= hi)
    assert holds(Compare(R, above=lo, below=hi), r, {}) == (lo < x < hi)
    a, b = Compare(R, at_least=lo), Compare(R, at_most=hi)
    assert holds(AllOf((a, b)), r, {}) == (lo <= x <= hi)
    assert holds(AnyOf((a, b)), r, {}) == (x >= lo or x <= hi)
    assert holds(Not(a), r, {}) == (not x >= lo)


def test_flags_distances_and_what_is_not_reported():
    assert holds(Compare(FLOW, is_=False), {"bottle.flowing": False}, {})
    assert not holds(Compare(FLOW, is_=False), {}, {})  # not reported yet: false
    near = Near("bottle_tip", "mug", 0.35)
    pos = {"mug": np.zeros(3), "bottle_tip": np.array([0.2, 0.2, 0.2])}
    assert holds(near, {}, pos) and not holds(near, {}, {**pos, "bottle_tip": np.array([0.3, 0.2, 0.0])})
    assert not holds(near, {}, {"mug": np.zeros(3)})
    assert holds(True, {}, {}) and not holds(False, {}, {})
    deep = copy.deepcopy(AllOf((Compare(R, at_least=0.5), AnyOf((Compare(FLOW, is_=False),)))))
    assert thresholds(deep) == {"bottle.poured": 0.5} and thresholds(Not(Compare(R, at_least=1))) == {}


def test_sctd_tasks_lists_and_shows(capsys):
    from sctd.cli.main import main

    assert main(["tasks"]) == 0
    out = capsys.readouterr().out
    assert "pour" in out and "Open a drawer" in out and "object drawer_handle" in out
    assert main(["tasks", "show", "pour"]) == 0
    out = capsys.readouterr().out
    assert "held: bottle" in out and "done (poured) at bottle.poured >= 0.5" in out
    assert "intent: bring (reach), pour (tilt), upright (upright)" in out
    assert main(["tasks"]) == 0
    assert "Open a cabinet door" in capsys.readouterr().out
    assert main(["tasks", "show", "cabinet"]) == 0
    out = capsys.readouterr().out
    assert "joint door: revolute, handle door_handle, travel 1.74533 rad (100 deg)" in out
    assert "done (opened) at door.position >= 1.13446" in out
    assert "intent: reach (reach), swing (move_joint)" in out
    assert main(["tasks", "show", "drawer"]) == 0
    assert "joint drawer: prismatic, handle drawer_handle, travel 0.3 m\n" in capsys.readouterr().out
    assert main(["tasks", "show", "juggle"]) == 2
    assert "sctd tasks show: juggle: no such file" in capsys.readouterr().err


def test_sctd_tasks_show_checks_the_arm_reaches_the_start(tmp_path, capsys):
    """A start out of the arm's reach is refused naming the pose and the arm; every
    shipped task is reached at its start and the starts of trials 0-9."""
    from sctd.cli.main import main

    far = tmp_path / "far.yaml"
    text = (ROOT / "tasks" / "drink.yaml").read_text().replace("name: drink", "name: far")
    far.write_text(text.replace("position: [0.59, -0.27, 0.70]", "position: [1.59, -0.27, 0.70]"))
    assert main(["tasks", "show", str(far)]) == 2
    err = capsys.readouterr().err
    assert "sctd tasks show: task far: the start pose [1.590, -0.270, 0.700" in err
    assert "is out of reach of the arm of edan_arm.urdf (frame 'ee')" in err
    assert main(["tasks", "show", str(far), "--no-reach"]) == 0
    for name in ("pour", "drawer", "drink", "cabinet", "light_switch", "oven"):
        assert main(["tasks", "show", name]) == 0, capsys.readouterr().err
        assert "reach: edan_arm.urdf (frame 'ee') reaches the start and the starts of trials 0-9" in \
            capsys.readouterr().out


def test_scene_is_a_deprecated_alias_of_task(capsys):
    import argparse

    from sctd_sim.options import add_service_arguments

    p = argparse.ArgumentParser(prog="sctd sim")
    add_service_arguments(p)
    assert p.parse_args([]).task == "pour"
    assert p.parse_args(["--task", "drawer"]).task == ["drawer"]  # repeatable: a list once given
    assert p.parse_args(["--task", "drawer", "--task", "oven"]).task == ["drawer", "oven"]
    assert capsys.readouterr().err == ""
    assert p.parse_args(["--scene", "drawer"]).task == "drawer"
    err = capsys.readouterr().err
    assert "sctd sim: --scene is deprecated (it goes in the next release): use --task" in err


def test_sctd_sim_refuses_an_unknown_task_before_it_starts(capsys, tmp_path):
    from sctd_sim import service

    assert service.main(["--task", "juggle"]) == 2
    assert "sctd sim: --task: juggle: no such file, and no task of that name" in capsys.readouterr().err
    bad = tmp_path / "bad.yaml"
    bad.write_text("sctd_task: 1\nname: bad\n")
    assert service.main(["--task", str(bad)]) == 2
    assert f"sctd sim: --task: {bad}: intent: missing" in capsys.readouterr().err
