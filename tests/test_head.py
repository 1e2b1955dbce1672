"""A person's head in a task: the file's ``heads`` read and refused as the rest of a
task file is, the contact spring the simulator's scene pushes back with (its force on
the hand, the head's ``force`` and ``max_force``), and the mouth a container a cup's
contents go into or are spilled beside; ``sctd tasks show`` says what the head is."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import yaml

from sctd import se3
from sctd.task import TaskError, find_task, shipped_folder, task_from_document
from sctd.task.judge import holds, thresholds
from sctd.task.kinds import World
from sctd.task.kinds.head import Head, HeadPhysics
from sctd_sim.scenes import TaskScene, make_scene

DRINK = shipped_folder() / "drink.yaml"
DT = 1e-3


def drink_doc() -> dict:
    return yaml.safe_load(DRINK.read_text())


def test_the_drink_task_reads_as_the_file_says():
    t = find_task("drink")
    assert t.object == "mouth" and t.scene.heads == {
        "face": Head("face", "mouth", 0.09, stiffness=1000.0, damping=20.0)}
    assert Head.quantities == ("force", "max_force")
    assert thresholds(t.outcome.done) == {"cup.poured": 0.2}
    mouth = t.scene.bodies["mouth"]
    yaw = math.radians(50)
    np.testing.assert_allclose(mouth.T_world[:3, 0], [math.cos(yaw), math.sin(yaw), 0.0])
    # the head's centre 9 cm behind the lips, along the mouth's -x
    np.testing.assert_allclose(t.scene.heads["face"].centre(mouth.T_world),
                               mouth.T_world[:3, 3] - 0.09 * mouth.T_world[:3, 0])
    assert [s.name for s in t.intent] == ["bring", "sip", "upright", "away"]
    assert t.scene.held.contents.into == "mouth" and t.scene.held.contents.outlet == "cup_rim"


def _set(doc: dict, path: str, value) -> None:
    *head, last = path.split(".")
    d = doc
    for k in head:
        d = d[int(k)] if isinstance(d, list) else d[k]
    if value is DELETE:
        del d[int(last) if isinstance(d, list) else last]
    else:
        d[int(last) if isinstance(d, list) else last] = value


DELETE = object()
HEAD = {"behind": "mouth", "radius": 0.09, "contact": {"stiffness": 1, "damping": 0}}


@pytest.mark.parametrize(("path", "value", "where", "problem"), [
    ("scene.heads.face.behind", "chin", "scene.heads.face.behind", "unknown body 'chin' (bodies: mouth)"),
    ("scene.heads.face.radius", 0.01, "scene.heads.face.radius", "must be >= 0.03"),
    ("scene.heads.face.radius", 0.5, "scene.heads.face.radius", "must be <= 0.3"),
    ("scene.heads.face.radius", "big", "scene.heads.face.radius", "expected a number"),
    ("scene.heads.face.contact.stiffness", 0, "scene.heads.face.contact.stiffness", "must be > 0.0"),
    ("scene.heads.face.contact.damping", -1.0, "scene.heads.face.contact.damping", "must be >= 0.0"),
    ("scene.heads.face.contact.spring", 1.0, "scene.heads.face.contact.spring", "unknown field"),
    ("scene.heads.face.contact", DELETE, "scene.heads.face.contact", "missing"),
    ("scene.heads.face.colour", "pale", "scene.heads.face.colour", "unknown field"),
    ("scene.heads", {}, "scene.heads", "expected at least one head"),
    ("scene.heads", [], "scene.heads", "expected a mapping"),
    ("scene.heads.face", "round", "scene.heads.face", "expected a mapping"),
    ("scene.heads", {"Face": HEAD}, "scene.heads.Face", "expected a name of lower-case letters"),
    ("scene.heads", {"cup_rim": HEAD}, "scene",
     "the name 'cup_rim' is used twice (bodies, held frames, joints, heads, zones and 'hand'"),
    # the mouth moved to where the cup starts: the rim starts inside the face
    ("scene.bodies.mouth.position", [0.65, -0.27, 0.82], "scene.start", "cup_rim starts"),
    ("intent.0.reach.to", [-0.03, 0.0, 0.0], "intent[0].reach.to",
     "the goal lies 0.030 m inside the head 'face'"),
    ("outcome.fail.0.when", {"reading": "face.pressure", "above": 1}, "outcome.fail[0].when.reading",
     "a head reports force, max_force; got 'pressure'"),
    ("outcome.fail.0.when", {"reading": "face.max_force", "is": True}, "outcome.fail[0].when",
     "face.max_force is a number"),
])
def test_a_bad_head_is_refused_naming_the_field(path, value, where, problem):
    doc = drink_doc()
    _set(doc, path, value)
    with pytest.raises(TaskError) as e:
        task_from_document(doc, "mine.yaml")
    assert str(e.value).startswith(f"mine.yaml: {where}: "), str(e.value)
    assert problem in str(e.value), str(e.value)


def test_a_scene_without_heads_reads_as_before():
    doc = drink_doc()
    del doc["scene"]["heads"]
    doc["outcome"] = copy.deepcopy(doc["outcome"])
    doc["outcome"]["success"] = {"reading": "cup.spilled", "at_most": 1e-9}
    doc["outcome"]["fail"] = doc["outcome"]["fail"][1:]
    t = task_from_document(doc, "mine.yaml")
    assert t.scene.heads == {}
    with pytest.raises(TaskError, match="unknown element 'face'"):
        task_from_document(drink_doc() | {"scene": doc["scene"]}, "mine.yaml")


# -- the contact ------------------------------------------------------------------------
def drink_scene() -> TaskScene:
    scene = make_scene(find_task("drink"))
    assert isinstance(scene, TaskScene)
    return scene


def ee_for_rim(scene: TaskScene, p_mouth: np.ndarray, tilt: float = 0.0) -> np.ndarray:
    """The hand's pose (world) that puts the cup's rim at ``p_mouth`` (in the mouth's
    frame), the hand's x towards the lips, tilted by ``tilt`` about its y (the cup's top
    towards the lips)."""
    M = scene.poses["mouth"]
    R = M[:3, :3] @ se3.matrix_from_rotvec([0.0, 0.0, math.pi]) @ se3.matrix_from_rotvec([0.0, tilt, 0.0])
    T_rim = se3.transform_from_rt(R, M[:3, :3] @ p_mouth + M[:3, 3])
    return T_rim @ se3.invert_transform(scene.held.frames["cup_rim"])


def test_outside_the_head_nothing_pushes():
    scene = drink_scene()
    w = scene.step(ee_for_rim(scene, np.array([0.001, 0.0, 0.0])), np.zeros(6), DT)
    r = scene.readings()
    assert r["face.force"] == 0.0 and r["face.max_force"] == 0.0
    load = scene.payload()[0] * 9.81
    assert w[2] == pytest.approx(-load) and np.allclose(w[:2], 0.0)  # the cup's weight alone


def test_the_rim_inside_the_lips_is_pushed_out_by_the_spring():
    """The rim 5 mm inside the face, at rest: 1000 N/m x 5 mm = 5 N along the outward
    normal (the mouth's x), acting at the rim: a torque about the hand's origin."""
    scene = drink_scene()
    T_ee = ee_for_rim(scene, np.array([-0.005, 0.0, 0.0]))
    w = scene.step(T_ee, np.zeros(6), DT)
    x_mouth = scene.poses["mouth"][:3, 0]
    f = w[:3] - np.array([0.0, 0.0, -scene.payload()[0] * 9.81])
    np.testing.assert_allclose(f, 5.0 * x_mouth, atol=1e-9)
    arm = (T_ee @ scene.held.frames["cup_rim"])[:3, 3] - T_ee[:3, 3]
    com = T_ee[:3, :3] @ scene.held.com
    weight = np.array([0.0, 0.0, -scene.payload()[0] * 9.81])
    np.testing.assert_allclose(w[3:], np.cross(arm, 5.0 * x_mouth) + np.cross(com, weight), atol=1e-9)
    assert scene.readings()["face.force"] == pytest.approx(5.0)
    # backing out: no force, the highest kept; a reset forgets it
    scene.step(ee_for_rim(scene, np.array([0.02, 0.0, 0.0])), np.zeros(6), DT)
    r = scene.readings()
    assert r["face.force"] == 0.0 and r["face.max_force"] == pytest.approx(5.0)
    scene.reset()
    assert scene.readings()["face.max_force"] == 0.0


def test_the_damper_pushes_harder_going_in_and_never_pulls():
    head = Head("face", "mouth", 0.09, stiffness=1000.0, damping=20.0)
    contact = HeadPhysics(head, [np.eye(4)])  # the hand's origin alone
    T_mouth = np.eye(4)

    def step(T_ee: np.ndarray, twist: np.ndarray) -> np.ndarray:
        return contact.step(World(T_ee, twist, {"mouth": T_mouth}), DT)

    T_ee = se3.transform_from_rt(np.eye(3), [-0.002, 0.0, 0.0])  # 2 mm in, along the mouth's x
    going_in = np.array([-0.05, 0.0, 0.0, 0.0, 0.0, 0.0])
    w = step(T_ee, going_in)
    assert w[0] == pytest.approx(1000.0 * 0.002 + 20.0 * 0.05)
    going_out = np.array([0.5, 0.0, 0.0, 0.0, 0.0, 0.0])  # faster out than the spring pushes
    assert np.array_equal(step(T_ee, going_out), np.zeros(6))
    assert contact.force == 0.0 and contact.max_force == pytest.approx(3.0)
    # a turning hand: its point's speed is the twist's at the point
    contact = HeadPhysics(head, [se3.transform_from_rt(np.eye(3), [0.0, 0.0, 0.1])])
    T_ee = se3.transform_from_rt(np.eye(3), [-0.002, 0.0, -0.1])
    spin = np.array([0.0, 0.0, 0.0, 0.0, -0.5, 0.0])  # about -y: the point 0.1 m up moves along -x
    w = step(T_ee, spin)
    n = np.array([-0.002 + 0.09, 0.0, 0.0])
    n /= np.linalg.norm(n)
    assert w[0] == pytest.approx(1000.0 * 0.002 + 20.0 * 0.05 * n[0])


def test_a_sip_goes_into_the_mouth_and_beside_it_is_spilled():
    scene = drink_scene()
    T_ee = ee_for_rim(scene, np.array([0.01, 0.0, 0.01]), tilt=math.radians(55))
    for _ in range(1000):
        scene.step(T_ee, np.zeros(6), DT)
    r = scene.readings()
    assert r["cup.poured"] > 0.05 and r["cup.spilled"] == 0.0 and r["cup.flowing"]
    assert r["face.max_force"] == 0.0  # the tilted cup turns about its rim, clear of the face
    scene = drink_scene()
    T_ee = ee_for_rim(scene, np.array([0.01, 0.05, 0.01]), tilt=math.radians(55))  # beside the lips
    for _ in range(100):
        scene.step(T_ee, np.zeros(6), DT)
    r = scene.readings()
    assert r["cup.poured"] == 0.0 and r["cup.spilled"] > 0.0


def test_the_outcome_judges_the_sip_the_spill_and_the_force():
    """Done once a fifth of the cup is in the mouth, the cup no longer pours and its rim
    is 4 cm off the lips; a success without spill, under 5 N on the face; the trial's
    fail rules name what went wrong."""
    t = find_task("drink")
    o = t.outcome
    far = {"cup_rim": np.array([0.1, 0.0, 0.0]), "mouth": np.zeros(3)}
    near = {"cup_rim": np.array([0.01, 0.0, 0.0]), "mouth": np.zeros(3)}
    sip = {"cup.poured": 0.25, "cup.flowing": False, "cup.spilled": 0.0, "face.max_force": 0.4}
    assert holds(o.done, sip, far) and holds(o.success, sip, far)
    assert not holds(o.done, sip, near) and not holds(o.done, sip | {"cup.flowing": True}, far)
    fails = {f.reason: f.when for f in o.fail}
    assert holds(fails["pressed into the face"], sip | {"face.max_force": 5.0}, far)
    assert not holds(o.success, sip | {"face.max_force": 5.0}, far)
    assert holds(fails["spilled"], sip | {"cup.spilled": 1e-6}, far)
    assert holds(fails["more than a sip"], sip | {"cup.poured": 0.51}, far)


def test_sctd_tasks_shows_the_head(capsys):
    from sctd.cli.main import main

    assert main(["tasks", "show", "drink"]) == 0
    out = capsys.readouterr().out
    assert "task object: mouth; frames: mouth, cup_rim" in out
    assert "head face: a sphere of 0.09 m behind mouth, contact 1000 N/m, 20 N s/m" in out
    assert "done (drunk) at cup.poured >= 0.2" in out and "fails: pressed into the face, spilled" in out
    assert "intent: bring (reach), sip (tilt), upright (upright), away (reach)" in out
    assert main(["tasks", "show", "drink", "--json"]) == 0
    import json
    s = json.loads(capsys.readouterr().out)
    assert s["heads"] == {"face": {"behind": "mouth", "radius": 0.09, "stiffness": 1000.0, "damping": 20.0}}
