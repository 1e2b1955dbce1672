"""Task element kinds as a registry: the shipped kinds have every part, a kind from
another package is found through its entry point, and the pick-and-place kinds behave
(supports, items, the two fingers, the grasp and place steps)."""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml

from sctd import se3
from sctd.task import TaskError, find_task, task_from_document
from sctd.task.judge import holds
from sctd.task.kinds import (
    BUILTIN,
    Facet,
    FacetPhysics,
    Run,
    Shape,
    StepKind,
    StepMind,
    facets,
    registry,
    step_kinds,
)
from sctd.wire.codec import GripperCmd
from sctd_services.user.grasping import GraspButton
from sctd_services.user.intent import Observation, TaskIntent
from sctd_sim.fingers import MAX_WIDTH, Fingers
from sctd_sim.scenes import TaskScene, make_scene

CUP = "cup_to_table"


def cup_doc() -> dict:
    return yaml.safe_load(Path(find_task(CUP).file).read_text())


def read(doc: dict):
    return task_from_document(doc, "test.yaml")


# -- the registry -------------------------------------------------------------------------
@pytest.mark.parametrize("name", [CUP, "bottle_to_fridge", "tap"])
def test_the_shipped_kinds_are_registered_with_every_part(name):
    reg = registry()
    assert set(BUILTIN) <= set(reg)
    assert list(facets()) == ["container", "surface", "button", "support", "item", "knob"]  # (support, item)
    assert list(step_kinds())[:8] == ["reach", "tilt", "upright", "move_joint", "press", "grasp", "place",
                                      "turn"]
    task = find_task(name)
    for body, b in task.scene.bodies.items():
        for key, facet in b.facets.items():
            assert isinstance(facet, Facet) and type(facet) is reg[key]
            # its writer: read back to the same facet
            r = _reader()
            assert type(facet).read(r, copy.deepcopy(facet.to_yaml()), "x") == facet
            assert all(isinstance(s, Shape) for s in facet.shapes()) and facet.shapes()
            assert isinstance(facet.physics(body, task.scene), FacetPhysics)
            assert set(facet.flags) <= set(facet.quantities)
    run = Run(task, TaskIntent(task))
    for i, step in enumerate(task.intent):
        assert isinstance(step.action, StepKind)
        back = type(step.action).read(_reader(), copy.deepcopy(step.action.to_yaml(task.scene)), "x",
                                      task.scene, task.outcome, task.intent[:i])
        assert back == step.action
        run.minds.append(step.action.mind(run, i))
        assert isinstance(run.minds[-1], StepMind)


def _reader():
    from sctd.task.reader import _Reader

    return _Reader("test.yaml")


@pytest.mark.parametrize("name", ["pour", "drink", "drawer", "cabinet", "oven", "light_switch"])
def test_the_older_steps_are_registered_kinds_written_and_read_back(name):
    """Reaches, tilts, uprights, joint moves and presses are step kinds like any other:
    each in the registry under its key, written by its own to_yaml and read back equal
    (with the steps before it: a tilt takes the frame of the reach before it), with a
    mind for a run of the task."""
    from sctd.task.kinds.move_joint import MoveJoint
    from sctd.task.kinds.press import Press
    from sctd.task.kinds.reach import Reach
    from sctd.task.kinds.tilt import Tilt, Upright

    reg = registry()
    assert [reg[k] for k in ("reach", "tilt", "upright", "move_joint", "press")] == [Reach, Tilt, Upright,
                                                                                      MoveJoint, Press]
    task = find_task(name)
    run = Run(task, TaskIntent(task))
    for i, step in enumerate(task.intent):
        kind = type(step.action)
        assert reg[kind.key] is kind
        doc = copy.deepcopy(step.action.to_yaml(task.scene))
        back = kind.read(_reader(), doc, "x", task.scene, task.outcome, task.intent[:i])
        assert back == step.action and back.frame() == step.action.frame()
        assert back.to_yaml(task.scene) == step.action.to_yaml(task.scene)
        run.minds.append(step.action.mind(run, i))
    assert all(isinstance(m, StepMind) for m in run.minds)


def test_a_tilt_without_a_reach_before_it_is_refused_by_its_kind():
    from sctd.task.kinds.tilt import Tilt

    pour = find_task("pour")
    tilt = pour.intent[1].action
    doc = tilt.to_yaml(pour.scene)
    with pytest.raises(TaskError, match=r"x: a tilt step moves the frame of a reach before it: the first"):
        Tilt.read(_reader(), doc, "x", pour.scene, pour.outcome, ())
    assert Tilt.read(_reader(), doc, "x", pour.scene, pour.outcome, pour.intent[:1]).frame() == "bottle_tip"


TEST_KIND = '''
"""A test kind from outside sctd: a beacon on a body that lights while the hand is near."""
from dataclasses import dataclass
import numpy as np
from sctd.task.kinds import Facet, FacetPhysics, Shape


@dataclass(frozen=True)
class Beacon(Facet):
    key = "beacon"
    quantities = ("lit", "lit_for")
    flags = ("lit",)
    within: float

    @classmethod
    def read(cls, r, v, path):
        d = r.fields(v, path, {"within"})
        return cls(r.positive(d["within"], f"{path}.within"))

    def to_yaml(self):
        return {"within": float(self.within)}

    def physics(self, body, scene):
        return _Lamp(body, self.within)

    def shapes(self):
        return [Shape("cylinder", (0.01, 0.01, 0.02), np.eye(4))]


class _Lamp(FacetPhysics):
    def __init__(self, body, within):
        self.body, self.within, self.t = body, within, 0.0

    def reset(self, world):
        self.t = 0.0

    def step(self, world, dt):
        if self._lit(world):
            self.t += dt
        return np.zeros(6)

    def _lit(self, world):
        d = world.T_world_ee[:3, 3] - world.poses[self.body][:3, 3]
        return float(np.linalg.norm(d)) < self.within

    def readings(self, world):
        return {f"{self.body}.lit": self._lit(world), f"{self.body}.lit_for": self.t}
'''

PROBE = '''
import numpy as np
from sctd import se3
from sctd.task import find_task
from sctd.task.kinds import registry
from sctd.task.writer import task_to_yaml
from sctd_sim.scenes import make_scene
assert "beacon" in registry(), sorted(registry())
t = find_task(__import__("sys").argv[1])
assert t.scene.bodies["lamp"].facets["beacon"].within == 0.1
assert t.outcome.done.reading.element == "lamp"
sc = make_scene(t)
T = t.scene.bodies["lamp"].T_world.copy()
for _ in range(100):
    sc.step(T, np.zeros(6), 0.01)
o = sc.outcome()
print(o["readings"]["lamp.lit"], round(o["readings"]["lamp.lit_for"], 6), o["done"])
from sctd.task import task_from_document
again = task_from_document(task_to_yaml(t), "again")
assert again.scene.bodies["lamp"].facets == t.scene.bodies["lamp"].facets
'''


@pytest.mark.slow
def test_a_kind_from_another_package_is_found_through_its_entry_point(tmp_path):
    """Adding a kind is one module: the package's class, registered under the entry
    point group; a task file then uses it, the simulator runs it and the writer writes it."""
    site = tmp_path / "site"
    (site / "sctd_beacon").mkdir(parents=True)
    (site / "sctd_beacon" / "__init__.py").write_text(textwrap.dedent(TEST_KIND))
    dist = site / "sctd_beacon-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: sctd-beacon\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[sctd.task_kinds]\nbeacon = sctd_beacon:Beacon\n")
    doc = {"sctd_task": 1, "name": "beacon_test", "object": "lamp",
           "scene": {"start": {"position": [0.45, 0.0, 0.6]},
                     "bodies": {"lamp": {"position": [0.6, 0.0, 0.6], "beacon": {"within": 0.1}}}},
           "outcome": {"done": {"reading": "lamp.lit_for", "at_least": 0.5}, "progress": "lamp.lit_for",
                       "clock": True, "time_limit": 10},
           "intent": [{"name": "go", "reach": {"frame": "hand", "to": [0, 0, 0],
                                               "reached": {"radial": 0.01, "height": 0.01}}}]}
    f = tmp_path / "beacon_test.yaml"
    f.write_text(yaml.safe_dump(doc))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", PROBE, str(f)], env=env, capture_output=True, text=True,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["True", "1.0", "True"]
    # without the package, the same file is refused naming the field
    only_read = "import sys; from sctd.task import find_task; find_task(sys.argv[1])"
    bare = subprocess.run([sys.executable, "-c", only_read, str(f)], capture_output=True, text=True,
                          timeout=120)
    assert bare.returncode != 0 and "scene.bodies.lamp.beacon: unknown field" in bare.stderr


@pytest.mark.slow
def test_a_registered_kind_that_is_not_a_kind_is_refused_by_name(tmp_path):
    site = tmp_path / "site"
    (site / "notakind").mkdir(parents=True)
    (site / "notakind" / "__init__.py").write_text("class Thing:\n    key = 'thing'\n")
    dist = site / "notakind-0.1.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: notakind\nVersion: 0.1\n")
    (dist / "entry_points.txt").write_text("[sctd.task_kinds]\nthing = notakind:Thing\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", "from sctd.task.kinds import registry; registry()"], env=env,
                         capture_output=True, text=True, timeout=120)
    assert out.returncode != 0
    assert "task element kind 'thing' (notakind:Thing): not a Facet or StepKind subclass" in out.stderr


# -- reading them ----------------------------------------------------------------------------
@pytest.mark.parametrize("edit, where, what", [
    (lambda d: d["scene"]["bodies"]["cup"]["item"].update(rests_on="cup"), "scene.bodies.cup.item.rests_on",
     "'cup' is no support (supports: shelf, tabletop)"),
    (lambda d: d["scene"]["bodies"]["cup"].update(position=[0.68, 0.18, 0.80]),
     "scene.bodies.cup.item.rests_on",
     "'cup' does not stand on 'shelf'"),
    (lambda d: d["scene"]["bodies"]["cup"]["item"].update(grip=0.2), "scene.bodies.cup.item.grip",
     "expected a height on its side, 0.010-0.090 m above its base, got 0.2"),
    (lambda d: d["scene"]["bodies"]["shelf"]["support"].update(size=[0.2, -0.1]),
     "scene.bodies.shelf.support.size",
     "expected two lengths > 0"),
    (lambda d: d["intent"][0]["grasp"].update(item="shelf"), "intent[0].grasp.item",
     "'shelf' is no item (items: cup)"),
    (lambda d: d["intent"][1]["place"].update(onto="cup"), "intent[1].place.onto", "'cup' is no support"),
    (lambda d: d["intent"][1]["place"].update(at=[0.2, 0.0]), "intent[1].place.at",
     "is not on the top of 'tabletop'"),
    (lambda d: d["outcome"].update(progress="cup.colour"), "outcome.progress",
     "an item reports held, grasps"),
    (lambda d: d["outcome"]["fail"][0]["when"].update({"is": 1}), "outcome.fail[0].when.is",
     "expected true or false"),
])
def test_bad_pick_and_place_fields_are_refused_naming_them(edit, where, what):
    doc = cup_doc()
    edit(doc)
    with pytest.raises(TaskError) as e:
        read(doc)
    assert e.value.path == where and what in e.value.problem, str(e.value)


def test_an_item_and_its_readings_are_published_frames():
    task = find_task(CUP)
    assert task.scene.frames() == ["shelf", "tabletop", "cup", "cup_rim"]
    assert task.scene.with_facet("support").keys() == {"shelf", "tabletop"}


# -- the fingers -----------------------------------------------------------------------------
def cmd(n: int, action: str, **kw) -> GripperCmd:
    return GripperCmd(n, 0.0, n, action, **kw)


def test_the_fingers_take_each_command_once_and_never_open_on_their_own():
    f = Fingers()
    assert f.width == MAX_WIDTH and f.reading().cmd == -1
    assert f.command(cmd(1, "close", force=20.0))
    for _ in range(200):
        f.advance(0.01)
    assert f.width == 0.0 and not f.reading().grasped and not f.reading().moving  # (closed on nothing)
    assert not f.command(cmd(1, "open"))  # a repeat of number 1: nothing changes
    for _ in range(100):
        f.advance(0.01)
    assert f.width == 0.0 and f.closing
    assert f.command(cmd(2, "width", width=0.03))
    for _ in range(100):
        f.advance(0.01)
    assert f.width == pytest.approx(0.03) and not f.closing and f.reading().cmd == 2
    assert f.command(cmd(3, "close", force=500.0)) and f.force == 70.0  # (cut to the hand's most)


# -- items on supports ------------------------------------------------------------------------
def scene_at_cup(seed: int | None = None) -> tuple[TaskScene, np.ndarray]:
    sc = make_scene(find_task(CUP), seed)
    assert isinstance(sc, TaskScene)
    T_cup = sc.live["cup"]
    T = se3.transform_from_rt(np.eye(3), T_cup[:3, 3] + np.array([0.0, 0.0, 0.05]))
    return sc, T


def run(sc: TaskScene, T: np.ndarray, seconds: float, twist: np.ndarray | None = None) -> np.ndarray:
    w = np.zeros(6)
    for _ in range(round(seconds / 0.01)):
        w = sc.step(T, np.zeros(6) if twist is None else twist, 0.01)
    return w


def readings(sc: TaskScene) -> dict:
    return sc.outcome()["readings"]


def test_fingers_closed_about_the_axis_take_the_item_and_it_moves_with_the_hand():
    sc, T = scene_at_cup()
    sc.grip(cmd(1, "close", force=20.0))
    run(sc, T, 0.5)
    r = readings(sc)
    assert r["cup.held"] and r["cup.grasps"] == 1 and not r["cup.resting"] and r["shelf.items"] == 0
    g = sc.gripper()
    assert g.grasped and g.width == pytest.approx(0.07)
    assert sc.payload()[0] == pytest.approx(0.25)
    up = T.copy()
    up[2, 3] += 0.06
    run(sc, up, 0.1)
    assert readings(sc)["cup.lifted"] == pytest.approx(0.06)
    assert np.allclose(sc.objects(up)["cup_rim"][:3, 3], sc.live["cup"][:3, 3] + [0, 0, 0.10])


@pytest.mark.parametrize("dx, dy, taken", [(0.0, 0.0, True), (0.012, 0.0, True), (0.02, 0.0, False),
                                            (0.0, 0.006, True), (0.0, -0.006, True), (0.0, 0.012, False)])
def test_the_fingers_take_it_only_with_its_axis_between_them(dx, dy, taken):
    sc, T = scene_at_cup()
    T[:3, 3] += [dx, dy, 0.0]
    sc.grip(cmd(1, "close", force=20.0))
    run(sc, T, 2.0)
    assert readings(sc)["cup.held"] is taken
    assert sc.gripper().grasped is taken and (sc.gripper().width == 0.0) is (not taken)
    if taken:  # (slid to the fingers' middle)
        assert abs((se3.invert_transform(T) @ sc.live["cup"])[1, 3]) < 1e-12


def test_fingers_along_the_axis_do_not_take_it():
    sc, T = scene_at_cup()
    T[:3, :3] = se3.matrix_from_rotvec([math.pi / 2, 0.0, 0.0])  # the fingers' line vertical
    sc.grip(cmd(1, "close", force=20.0))
    run(sc, T, 0.5)
    assert not readings(sc)["cup.held"]


def test_an_item_wider_than_the_open_fingers_is_never_taken():
    doc = cup_doc()
    doc["scene"]["bodies"]["cup"]["item"]["radius"] = 0.045
    sc = make_scene(read(doc))
    T = se3.transform_from_rt(np.eye(3), sc.live["cup"][:3, 3] + [0.0, 0.0, 0.05])
    sc.grip(cmd(1, "close", force=20.0))
    run(sc, T, 2.0)
    assert not readings(sc)["cup.held"] and sc.gripper().width == 0.0


def test_a_weak_squeeze_lets_it_slip_and_fall_once_it_is_off_its_support():
    sc, T = scene_at_cup()
    sc.grip(cmd(1, "close", force=1.0))  # 2 * 0.8 * 1 N < 0.25 kg * g
    run(sc, T, 0.5)
    assert readings(sc)["cup.held"]  # (the shelf bears it)
    up = T.copy()
    up[2, 3] += 0.06
    run(sc, up, 0.5)
    r = readings(sc)
    assert r["cup.grasps"] == 1 and r["cup.slips"] == 1 and not r["cup.held"] and r["cup.dropped"]
    assert not sc.gripper().grasped  # (and it is not taken again where it fell)


def test_let_go_over_a_support_it_lands_standing_in_the_air_it_is_dropped():
    sc, T = scene_at_cup()
    sc.grip(cmd(1, "close", force=20.0))
    run(sc, T, 0.5)
    table = sc.live["tabletop"]
    over = se3.transform_from_rt(np.eye(3), table[:3, 3] + [0.0, 0.0, 0.05 + 0.02])  # base 2 cm over it
    run(sc, over, 0.1)
    sc.grip(cmd(2, "open"))
    run(sc, over, 0.5)
    r = readings(sc)
    assert not r["cup.held"] and r["cup.resting"] and not r["cup.dropped"] and r["tabletop.items"] == 1
    assert sc.live["cup"][2, 3] == pytest.approx(table[2, 3])
    # the same from 20 cm up, or tilted past its topple angle: dropped
    for pose in (se3.transform_from_rt(np.eye(3), table[:3, 3] + [0.0, 0.0, 0.25]),
                 se3.transform_from_rt(se3.matrix_from_rotvec([0.6, 0.0, 0.0]), table[:3, 3] + [0, 0, 0.06])):
        sc, T = scene_at_cup()
        sc.grip(cmd(1, "close", force=20.0))
        run(sc, T, 0.5)
        run(sc, pose, 0.1)
        sc.grip(cmd(2, "open"))
        run(sc, pose, 0.5)
        r = readings(sc)
        assert r["cup.dropped"] and not r["cup.resting"] and r["tabletop.items"] == 0
        # the outcome reports it: the task's fail rule holds, it is not done
        task = find_task(CUP)
        assert [f.reason for f in task.outcome.fail if holds(f.when, r, sc.positions())] == ["dropped"]
        assert not sc.outcome()["done"]


def test_a_support_pushes_back_on_an_item_carried_into_it():
    sc, T = scene_at_cup()
    sc.grip(cmd(1, "close", force=20.0))
    run(sc, T, 0.5)
    into = T.copy()
    into[2, 3] -= 0.01  # the base 1 cm into the shelf's top
    w = run(sc, into, 0.05)
    assert w[2] == pytest.approx(3000.0 * 0.01 - 0.25 * 9.81, rel=1e-6)
    assert readings(sc)["cup.force"] == pytest.approx(30.0)


def test_a_rim_keeps_what_is_carried_over_it_up():
    doc = cup_doc()
    doc["scene"]["bodies"]["tabletop"]["support"]["rim"] = 0.04
    sc = make_scene(read(doc))
    T = se3.transform_from_rt(np.eye(3), sc.live["cup"][:3, 3] + [0.0, 0.0, 0.05])
    sc.grip(cmd(1, "close", force=20.0))
    run(sc, T, 0.5)
    table = sc.live["tabletop"]
    edge = table[:3, 3] + [0.15, 0.0, 0.02 + 0.05]  # the base 2 cm up, across the rim's line
    w = run(sc, se3.transform_from_rt(np.eye(3), edge), 0.05)
    assert readings(sc)["cup.force"] == pytest.approx(3000.0 * 0.02)
    inside = table[:3, 3] + [0.0, 0.0, 0.02 + 0.05]  # inside it, the same height: free
    w = run(sc, se3.transform_from_rt(np.eye(3), inside), 0.05)
    assert readings(sc)["cup.force"] == 0.0 and w[2] == pytest.approx(-0.25 * 9.81)


def test_the_item_moves_with_its_support_where_a_trial_puts_it():
    for seed in range(5):
        sc = make_scene(find_task(CUP), seed)
        shelf, cup = sc.live["shelf"], sc.live["cup"]
        p = se3.invert_transform(shelf) @ cup[:, 3]
        assert abs(p[2]) < 1e-12 and abs(p[0]) <= 0.02 + 1e-12 and abs(p[1]) <= 0.02 + 1e-12
        assert readings(sc)["shelf.items"] == 1 and readings(sc)["cup.resting"]


# -- the steps: a person who moves the hand as they wish ---------------------------------------
def ideal_run(task, seed: int, limit: float = 60.0) -> tuple[dict, list[str]]:
    """The hand moved exactly as the intent wishes, the fingers as it asks: the steps
    alone, without a device, a skill or an arm."""
    sc = make_scene(task, seed)
    it = TaskIntent(task)
    T = sc.start_pose()
    n, last, phases = 0, None, []
    for k in range(round(limit / 0.01)):
        d = it.desire(Observation(k * 0.01, T, sc.objects(T), sc.outcome()))
        if not phases or phases[-1] != d.phase:
            phases.append(d.phase)
        if d.grip is not None and d.grip != last:
            n += 1
            sc.grip(cmd(n, d.grip, force=20.0 if d.grip == "close" else None))
            last = d.grip
        v, w = d.twist[:3], d.twist[3:]
        T2 = T.copy()
        T2[:3, 3] += v * 0.01
        T2[:3, :3] = se3.matrix_from_rotvec(w * 0.01) @ T[:3, :3]
        sc.step(T2, d.twist, 0.01)
        T = T2
        o = sc.outcome()
        if o["done"] or o["readings"].get("cup.dropped"):
            return o, phases
    return sc.outcome(), phases


@pytest.mark.parametrize("seed", range(4))
def test_the_grasp_and_place_steps_take_the_cup_to_the_table(seed):
    o, phases = ideal_run(find_task(CUP), seed)
    assert o["done"] and o["success"], o["readings"]
    assert phases == ["take", "put"]
    r = o["readings"]
    assert r["cup.grasps"] == 1 and r["cup.slips"] == 0 and r["tabletop.items"] == 1 and r["shelf.items"] == 0


def test_a_place_that_loses_the_item_goes_back_to_the_grasp():
    task = find_task(CUP)
    sc, T = scene_at_cup()
    it = TaskIntent(task)
    sc.grip(cmd(1, "close", force=20.0))
    T2 = T.copy()
    T2[2, 3] += 0.08
    run(sc, T, 0.3)
    run(sc, T2, 0.3)
    assert it.desire(Observation(0.0, T2, sc.objects(T2), sc.outcome())).phase == "put"
    sc.grip(cmd(2, "open"))  # let go in the air: dropped
    run(sc, T2, 0.5)
    assert it.desire(Observation(1.0, T2, sc.objects(T2), sc.outcome())).phase == "take"


# -- the grasp button --------------------------------------------------------------------------
def test_the_grasp_button_taps_to_close_holds_to_open_and_waits_between():
    b = GraspButton()
    open_ = {"gripper": {"closing": False, "grasped": False, "moving": False}}
    holding = {"gripper": {"closing": True, "grasped": True, "moving": False}}
    empty = {"gripper": {"closing": True, "grasped": False, "moving": False}}
    assert not b.down(0.0, None, open_)
    assert b.down(0.0, "close", open_) and b.down(0.1, "close", open_) and not b.down(0.2, "close", open_)
    assert not b.down(0.5, "close", open_)  # (waiting to see what it did)
    assert not b.down(1.5, "close", holding)  # holds it: nothing to do
    assert b.down(2.0, "open", holding) and b.down(2.7, "open", holding) and not b.down(2.85, "open", holding)
    assert b.down(5.0, None, empty) and b.presses == 3  # closed on nothing: opened again
    assert not b.down(10.0, "close", {})  # fingers it cannot see: no press


# -- a knob turned in the hand ------------------------------------------------------------------
def tap_scene() -> tuple[TaskScene, np.ndarray]:
    sc = make_scene(find_task("tap"))
    assert isinstance(sc, TaskScene)
    T = se3.transform_from_rt(np.eye(3), sc.live["tap"][:3, 3] + [0.0, 0.0, 0.03])
    return sc, T


def turned(T: np.ndarray, angle: float) -> np.ndarray:
    out = T.copy()
    out[:3, :3] = se3.matrix_from_rotvec([0.0, 0.0, angle]) @ T[:3, :3]
    return out


def test_a_knob_turns_with_the_hand_that_holds_it_up_to_its_end_stop():
    sc, T = tap_scene()
    run(sc, turned(T, 0.5), 0.1)  # (turning the hand without holding it turns nothing)
    assert readings(sc)["tap.position"] == 0.0
    sc.grip(cmd(1, "close", force=20.0))
    run(sc, T, 1.0)
    r = readings(sc)
    assert r["tap.held"] and r["tap.grasps"] == 1 and sc.gripper().width == pytest.approx(0.036)
    run(sc, turned(T, 0.8), 0.1)
    assert readings(sc)["tap.position"] == pytest.approx(0.8, abs=1e-9)
    w = run(sc, turned(T, math.radians(110.0)), 0.1)  # 10 deg past its 100 deg stop
    r = readings(sc)
    assert r["tap.position"] == pytest.approx(math.radians(100.0))
    assert r["tap.torque"] == pytest.approx(-20.0 * math.radians(10.0))
    assert w[5] == pytest.approx(r["tap.torque"])
    run(sc, turned(T, 1.2), 0.1)
    sc.grip(cmd(2, "open"))
    run(sc, turned(T, 1.2), 0.5)
    run(sc, turned(T, 0.2), 0.1)  # let go: it stays where it was turned
    r = readings(sc)
    assert not r["tap.held"] and r["tap.position"] == pytest.approx(1.2) and \
        r["tap.max_position"] == pytest.approx(math.radians(100.0))


def test_a_knob_pulled_away_from_slips_out_of_the_fingers():
    sc, T = tap_scene()
    sc.grip(cmd(1, "close", force=20.0))
    run(sc, T, 1.0)
    near = T.copy()
    near[0, 3] += 0.02
    w = run(sc, near, 0.05)
    assert readings(sc)["tap.held"] and w[0] == pytest.approx(-2000.0 * 0.02)  # (the grasp's spring)
    far = T.copy()
    far[0, 3] += 0.04
    run(sc, far, 0.05)
    assert not readings(sc)["tap.held"]


@pytest.mark.parametrize("edit, where, what", [
    (lambda d: d["intent"][0]["turn"].update(knob="sink"), "intent[0].turn.knob",
     "'sink' is no knob (knobs: tap)"),
    (lambda d: d["outcome"].update(done={"reading": "tap.held", "is": False}), "intent[0].turn.knob",
     "outcome.done sets no at_least on tap.position"),
    (lambda d: d["intent"][0]["turn"].update(overshoot="45 deg"), "intent[0].turn.overshoot",
     "turns it to 105.0 deg, past its travel of 100.0 deg"),
    (lambda d: d["scene"]["bodies"]["tap"]["knob"].update(grip=0.001), "scene.bodies.tap.knob.grip",
     "expected a height on its side"),
])
def test_bad_knob_fields_are_refused_naming_them(edit, where, what):
    doc = yaml.safe_load(Path(find_task("tap").file).read_text())
    edit(doc)
    with pytest.raises(TaskError) as e:
        read(doc)
    assert e.value.path == where and what in e.value.problem, str(e.value)


@pytest.mark.parametrize("seed", range(3))
def test_the_turn_step_turns_the_tap_on(seed):
    o, phases = ideal_run(find_task("tap"), seed)
    assert o["done"] and o["success"] and phases == ["turn"]
    assert math.radians(60.0) <= o["readings"]["tap.position"] <= math.radians(67.0)
    assert o["readings"]["tap.grasps"] == 1


# -- what the hand cannot take, said before anything moves ----------------------------------------
def test_the_shipped_tasks_hand_can_take_what_they_ask_it_to():
    from sctd_sim.handreach import hand_problems
    from sctd_sim.robot import load_arm_model

    arm = load_arm_model()
    for name in (CUP, "bottle_to_fridge", "tap"):
        assert hand_problems(find_task(name), arm) == [], name


def test_too_wide_or_out_of_reach_is_named_by_tasks_show_and_the_simulator(tmp_path, capsys):
    from sctd.cli.main import main
    from sctd_sim.handreach import hand_problems
    from sctd_sim.robot import load_arm_model

    doc = cup_doc()
    doc["name"] = "wide_cup"
    doc["scene"]["bodies"]["cup"]["item"]["radius"] = 0.045
    wide = tmp_path / "wide_cup.yaml"
    wide.write_text(yaml.safe_dump(doc))
    assert main(["tasks", "show", str(wide)]) == 2
    err = capsys.readouterr().err
    assert "task wide_cup: cup is 9.0 cm across; the fingers open 8.0 cm: the hand cannot take it" in err
    doc = cup_doc()
    doc["scene"]["bodies"]["tabletop"]["position"] = [1.40, -0.18, 0.58]
    far = read(doc)
    problems = hand_problems(far, load_arm_model())
    assert len(problems) == 1
    assert problems[0].startswith("cup put down on tabletop at [1.400, -0.180, 0.630] is out of the arm's "
                                  "reach (edan_arm.urdf, frame 'ee')")
    from sctd_sim.service import main as sim_main

    assert sim_main(["--task", str(wide), "--duration", "0.1"]) == 2
    assert "--task: task wide_cup: cup is 9.0 cm across" in capsys.readouterr().err


def test_the_view_draws_each_facets_shapes_with_its_body():
    from sctd_services.view.task_scene import part_pose, task_parts

    task = find_task("bottle_to_fridge")
    parts = {p.name: p for p in task_parts(task)}
    assert {"worktop/support0", "bottle/item0"} <= set(parts)
    assert sum(n.startswith("door_shelf/support") for n in parts) == 5  # (the board, the rim's four walls)
    bottle = parts["bottle/item0"]
    assert bottle.rgb == (76, 140, 217) and bottle.anchor == ("body", "bottle")
    # a 7 cm wide, 20 cm tall cylinder standing on the body's origin
    lo, hi = bottle.vertices.min(axis=0), bottle.vertices.max(axis=0)
    assert np.allclose(lo, [-0.035, -0.035, 0.0], atol=1e-9)
    assert np.allclose(hi, [0.035, 0.035, 0.2], atol=1e-9)
    carried = se3.transform_from_rt(np.eye(3), [0.5, 0.2, 0.9])
    assert part_pose(bottle, task, {"bottle": carried}, None) is carried


def test_a_pick_and_place_floor_is_the_straight_way_through_its_points():
    """cup_to_table at 0.1 m/s: the clock starts 20 cm from the cup's base, the grip 5 cm
    over it (so 15 cm to go), the 5 cm lift, straight to where the hand holds the cup
    down on the table top's middle, 10 cm back."""
    from sctd.skill.model import Limits
    from sctd_services.eval.suite import floor

    task = find_task(CUP)
    lift_top = np.array([0.68, 0.18, 0.79 + 0.05])
    down = np.array([0.60, -0.18, 0.58 + 0.05])
    metres = 0.15 + 0.05 + float(np.linalg.norm(down - lift_top)) + 0.10
    assert floor(task, Limits(max_linear_speed=0.1, max_angular_speed=0.5)) == pytest.approx(metres / 0.1)
    # the tap: 17 cm to the grip (the clock's 20 cm less the grip's 3 cm), 9 cm back, 60 deg
    tap = floor(find_task("tap"), Limits(max_linear_speed=0.1, max_angular_speed=0.5))
    assert tap == pytest.approx((0.17 + 0.09) / 0.1 + math.radians(60.0) / 0.5)


def test_the_surface_and_its_button_are_registered_facets():
    """The light switch's wall and button: facets read back by their writer, the surface's
    physics a contact that gives way at the button (the button has none of its own), the
    readings named by the button, the last of the body's facets with readings."""
    from sctd.task.kinds.surface import Button, Contact, PushButton, Surface
    from sctd.task.reader import _elements

    task = find_task("light_switch")
    body = task.scene.bodies["light_switch"]
    assert list(body.facets) == ["surface", "button"]
    assert body.surface is body.facets["surface"] and body.button is body.facets["button"]
    for key, cls in (("surface", Surface), ("button", Button)):
        facet = body.facets[key]
        assert type(facet) is registry()[key] is cls
        assert cls.read(_reader(), copy.deepcopy(facet.to_yaml()), "x") == facet and facet.shapes()
    physics = body.surface.physics("light_switch", task.scene)
    assert isinstance(physics, PushButton) and isinstance(physics, Contact)
    assert body.button.physics("light_switch", task.scene) is None
    assert _elements(task.scene)["light_switch"] == "button"
    assert isinstance(TaskScene(task).contacts[0], PushButton)


def test_the_container_and_the_contents_are_registered_facets():
    """The pour's mug and what the bottle holds: the container a facet of its body, the
    contents one of the held object (its readings by the held object's name), both read
    back by their writers; the contents' physics pours and the arm carries what is left."""
    from sctd.task.kinds import held_facets
    from sctd.task.kinds.contents import Container, Contents, Flow
    from sctd.task.reader import _elements

    assert "container" in facets() and list(held_facets()) == ["contents"]
    task = find_task("pour")
    mug, held = task.scene.bodies["mug"], task.scene.held
    assert isinstance(mug.container, Container) and mug.facets == {"container": mug.container}
    assert isinstance(held.contents, Contents) and held.facets == {"contents": held.contents}
    for facet in (mug.container, held.contents):
        assert type(facet).read(_reader(), copy.deepcopy(facet.to_yaml()), "x") == facet
    assert mug.container.extent() == 0.04 and [s.name for s in mug.container.shapes()] == ["container"]
    flow = held.contents.physics(held.name, task.scene)
    assert isinstance(flow, Flow) and flow.held_mass() == held.contents.mass
    assert _elements(task.scene)["bottle"] == "contents"


# -- sections: kinds that own a section of the scene ------------------------------------------
def test_the_head_is_a_registered_section_with_every_part():
    from sctd.task.kinds import Section, sections
    from sctd.task.kinds.head import Head

    assert sections()["heads"] is Head and registry()["heads"] is Head
    task = find_task("drink")
    head = task.scene.sections["heads"]["face"]
    assert isinstance(head, Section) and task.scene.heads == {"face": head}
    assert Head.read(_reader(), "face", copy.deepcopy(head.to_yaml()), "x", task.scene) == head
    assert isinstance(head.physics(task.scene), FacetPhysics)
    assert head.body() == "mouth" and [s.kind for s in head.shapes()] == ["sphere"]
    (centre, radius), = head.footprint(task.scene)
    assert radius == 0.09 and np.allclose(centre, head.centre(task.scene.bodies["mouth"].T_world))


def test_the_zone_is_a_registered_section_read_back_by_its_writer():
    from sctd.task.kinds import sections
    from sctd.task.kinds.zone import Zone, ZoneWatch
    from tests.test_zone import drink_with_zone

    assert list(sections())[:3] == ["joints", "heads", "zones"] and sections()["zones"] is Zone
    task = read(drink_with_zone())
    zone = task.scene.sections["zones"]["at_lips"]
    assert task.scene.zones == {"at_lips": zone}
    back = Zone.read(_reader(), "at_lips", copy.deepcopy(zone.to_yaml()), "x", task.scene)
    assert back.to_yaml() == zone.to_yaml() and back.tilt == zone.tilt
    assert isinstance(zone.physics(task.scene), ZoneWatch) and zone.shapes() == []


@pytest.mark.parametrize("name", ["drawer", "cabinet"])
def test_the_joint_is_a_registered_section_drawn_at_its_handle(name):
    """A joint: read back by its writer, its handle's physics, its footprint the handle's
    path, and its drawing where the joint's position has moved the handle."""
    from sctd.task import handle_pose
    from sctd.task.kinds import sections
    from sctd.task.kinds.joint import Handle, Joint

    assert sections()["joints"] is Joint
    task = find_task(name)
    (joint_name, joint), = task.scene.joints.items()
    assert task.scene.sections["joints"] == {joint_name: joint}
    back = Joint.read(_reader(), joint_name, copy.deepcopy(joint.to_yaml()), "x", task.scene)
    assert back.to_yaml() == joint.to_yaml() and back.travel == joint.travel
    assert isinstance(joint.physics(task.scene), Handle)
    T0 = task.scene.bodies[joint.handle].T_world
    path = joint.footprint(task.scene)
    assert len(path) == 9 and np.allclose(path[-1][0], handle_pose(joint, T0, joint.travel)[:3, 3])
    at = joint.drawn_at({joint.handle: T0}, {f"{joint_name}.position": 0.1})
    assert np.allclose(at, handle_pose(joint, T0, 0.1)) and joint.drawn_at({}, {}) is None
    assert [s.name for s in joint.shapes()] == ["moving"]


LAMP_DOC = {"sctd_task": 1, "name": "lamps_test", "object": "desk",
            "scene": {"start": {"position": [0.45, 0.0, 0.6]},
                      "bodies": {"desk": {"position": [0.6, 0.0, 0.6]}},
                      "lamps": {"lamp": {"over": "desk", "within": 0.1}}},
            "outcome": {"done": {"reading": "lamp.lit_for", "at_least": 0.5}, "progress": "lamp.lit_for",
                        "clock": True, "time_limit": 10},
            "intent": [{"name": "go", "reach": {"frame": "hand", "to": [0, 0, 0],
                                                "reached": {"radial": 0.01, "height": 0.01}}}]}


@pytest.fixture
def lamps(monkeypatch):
    """A section kind of the test's own (``scene.lamps.<name>: {over, within}``: a lamp
    that lights while the hand is within ``within`` of the body ``over``), registered."""
    from dataclasses import dataclass

    from sctd.task import kinds
    from sctd.task.kinds import Section

    @dataclass(frozen=True)
    class Lamp(Section):
        key = "lamps"
        noun = "lamp"
        order = 90
        quantities = ("lit", "lit_for")
        flags = ("lit",)
        name: str
        over: str
        within: float

        @classmethod
        def read(cls, r, name, v, path, scene):
            d = r.fields(v, path, {"over", "within"})
            if d["over"] not in scene.bodies:
                raise r.fail(f"{path}.over", f"unknown body {d['over']!r}")
            return cls(name, d["over"], r.positive(d["within"], f"{path}.within"))

        def to_yaml(self):
            return {"over": self.over, "within": float(self.within)}

        def physics(self, scene):
            return _LampPhysics(self)

        def body(self):
            return self.over

        def shapes(self):
            return [Shape("sphere", (0.02, 0.02, 0.02), np.eye(4), (1.0, 1.0, 0.0))]

    class _LampPhysics(FacetPhysics):
        def __init__(self, lamp):
            self.lamp, self.t = lamp, 0.0

        def reset(self, world):
            self.t = 0.0

        def _lit(self, world):
            d = world.T_world_ee[:3, 3] - world.poses[self.lamp.over][:3, 3]
            return float(np.linalg.norm(d)) < self.lamp.within

        def step(self, world, dt):
            self.t += dt if self._lit(world) else 0.0
            return np.zeros(6)

        def readings(self, world):
            n = self.lamp.name
            return {f"{n}.lit": self._lit(world), f"{n}.lit_for": self.t}

    real = kinds.sections()
    monkeypatch.setattr(kinds, "sections", lambda: {**real, "lamps": Lamp})
    return Lamp


def test_a_section_kind_is_read_written_simulated_and_drawn(lamps):
    """A kind that owns a section of the scene: the reader reads its entries by name (its
    readings by the entry's name), the writer writes them back, the simulator steps its
    physics and the view draws it with its body."""
    from sctd.task.writer import task_to_yaml
    from sctd_services.view.task_scene import task_parts

    task = read(copy.deepcopy(LAMP_DOC))
    assert task.scene.sections == {"lamps": {"lamp": lamps("lamp", "desk", 0.1)}}
    assert task.outcome.progress.element == "lamp"
    assert task_to_yaml(task)["scene"]["lamps"] == {"lamp": {"over": "desk", "within": 0.1}}
    assert read(task_to_yaml(task)).scene.sections == task.scene.sections
    scene = make_scene(task)
    T = task.scene.bodies["desk"].T_world.copy()
    for _ in range(100):
        scene.step(T, np.zeros(6), 0.01)
    out = scene.outcome()
    assert out["readings"]["lamp.lit"] is True and out["done"]
    assert [(p.name, p.anchor) for p in task_parts(task)] == [("lamp/lamp", ("entry", "lamps/lamp"))]


@pytest.mark.parametrize("edit, where, what", [
    (lambda d: d["scene"].update(lamps={}), "scene.lamps", "expected at least one lamp (or no lamps field)"),
    (lambda d: d["scene"]["lamps"].update(Lamp={"over": "desk", "within": 0.1}), "scene.lamps.Lamp",
     "expected a name of lower-case letters"),
    (lambda d: d["scene"]["lamps"].update(desk={"over": "desk", "within": 0.1}), "scene",
     "the name 'desk' is used twice (bodies, held frames, joints, heads, zones, lamps and 'hand'"),
    (lambda d: d["scene"]["lamps"]["lamp"].update(over="chair"), "scene.lamps.lamp.over",
     "unknown body 'chair'"),
    (lambda d: d["outcome"].update(progress="lamp.colour"), "outcome.progress",
     "a lamp reports lit, lit_for; got 'colour'"),
    (lambda d: d["outcome"].update(done={"reading": "lamp.lit", "at_least": 1}), "outcome.done",
     "lamp.lit is a flag"),
])
def test_bad_section_entries_are_refused_naming_them(lamps, edit, where, what):
    doc = copy.deepcopy(LAMP_DOC)
    edit(doc)
    with pytest.raises(TaskError) as e:
        read(doc)
    assert e.value.path == where and what in e.value.problem, str(e.value)


def test_tasks_show_prints_the_registered_kinds_fields(capsys):
    from sctd.cli.main import main

    assert main(["tasks", "show", CUP, "--no-reach"]) == 0
    out = capsys.readouterr().out
    assert "  support tabletop: size [0.3, 0.3]\n" in out
    assert "  item cup: rests_on shelf, mass 0.25, radius 0.035, height 0.1, grip 0.05, frames " in out
    assert "  intent: take (grasp), put (place)\n" in out


def test_an_observer_beside_a_real_arm_judges_a_pick_and_place_from_its_gripper():
    """sctd robot NAME --task cup_to_table: the scene follows the arm's measured hand and
    its gripper's readings (no physics of its own): the cup taken when the real fingers
    hold something about its axis, put down when they open over the table top."""
    from sctd.wire.codec import GripperReading
    from sctd_services.robots.observer import observer_for

    obs = observer_for(find_task(CUP))
    cup = obs.scene.live["cup"].copy()
    grip = se3.transform_from_rt(np.eye(3), cup[:3, 3] + [0.0, 0.0, 0.05])
    t = 0.0

    def go(T: np.ndarray, width: float, grasped: bool, seconds: float = 0.2) -> dict:
        nonlocal t
        for _ in range(round(seconds / 0.01)):
            t += 0.01
            obs.step(t, T, GripperReading(width, grasped))
        return obs.outcome()["readings"]

    assert not go(grip, 0.08, False)["cup.held"]  # (open fingers about it: not taken)
    assert go(grip, 0.07, True)["cup.held"]
    table = obs.scene.live["tabletop"]
    over = se3.transform_from_rt(np.eye(3), table[:3, 3] + [0.0, 0.0, 0.05 + 0.005])
    assert go(over, 0.07, True)["cup.lifted"] < 0.0  # (carried: the table is lower)
    r = go(over, 0.08, False)
    assert not r["cup.held"] and r["cup.resting"] and r["tabletop.items"] == 1
    away = over.copy()
    away[0, 3] -= 0.12
    go(away, 0.08, False)
    assert obs.outcome()["done"] and obs.outcome()["success"]


def test_inspect_says_which_states_are_in_another_bodys_frame(capsys):
    from sctd.cli.main import main

    assert main(["inspect", str(Path(__file__).parents[1] / "skills" / "cup_to_table-linear.yaml")]) == 0
    out = capsys.readouterr().out
    assert "object cup:" in out and "  state s0 (start) in the frame of shelf\n" in out
    assert main(["inspect", str(Path(__file__).parents[1] / "skills" / "tap-linear.yaml")]) == 0
    assert "in the frame of" not in capsys.readouterr().out  # (every state in the skill's object's)


# -- a step kind of another package, with the hooks the older kinds use ------------------------
def hold_doc() -> dict:
    """The light switch's scene and outcome, its intent a reach and a hold after it."""
    doc = yaml.safe_load(Path(find_task("light_switch").file).read_text())
    doc.pop("teach", None)
    go = {"frame": "hand", "to": [0.1, 0.0, 0.0], "reached": {"radial": 0.01}}
    doc["intent"] = [{"name": "go", "reach": go},
                     {"name": "stay", "hold": {"within": 0.02, "turn": 0.5}}]
    return doc


@pytest.fixture
def hold(monkeypatch):
    """A step kind of the test's own (``hold: {within, turn}``: keep the frame of the reach
    before it at that reach's goal), registered: it reads with the steps before it, finds
    the reach's mind in its run, shares its look, settles within ``2 within`` and adds its
    turn to the floor."""
    from dataclasses import dataclass, field

    from sctd.task import kinds
    from sctd.task.kinds import Floor, StepKind, StepMind, Want
    from sctd.task.kinds.reach import anchor_mind, anchor_of

    @dataclass(frozen=True)
    class Hold(StepKind):
        key = "hold"
        within: float
        turn: float
        frame_name: str = field(default="hand", compare=False)

        @classmethod
        def read(cls, r, v, path, scene, outcome, before):
            anchor = anchor_of(r, cls.key, path, before)
            d = r.fields(v, path, {"within", "turn"})
            return cls(r.positive(d["within"], f"{path}.within"), r.positive(d["turn"], f"{path}.turn"),
                       anchor.frame())

        def to_yaml(self, scene):
            return {"within": float(self.within), "turn": float(self.turn)}

        def frame(self):
            return self.frame_name

        def mind(self, run, index):
            return HoldMind(self, anchor_mind(run, index), index)

        def floor_path(self, task, before):
            return Floor(radians=self.turn)

    class HoldMind(StepMind):
        def __init__(self, step, reach, index):
            self.step, self.reach, self.index = step, reach, index

        def move(self, sight):
            return 0

        def error(self, sight):
            return self.reach.look(sight).to_goal

        def want(self, sight):
            return Want(np.ones(6), np.eye(6))

        def close_enough(self, sight):
            return self.reach.look(sight).to_goal < 2 * self.step.within

        def settle(self):
            return True

    real = kinds.step_kinds()
    monkeypatch.setattr(kinds, "step_kinds", lambda: {**real, "hold": Hold})
    return Hold


def test_a_step_kind_of_its_own_reads_runs_settles_plans_and_counts_in_the_floor(hold):
    from sctd.skill import Limits
    from sctd.task.writer import task_to_yaml
    from sctd_services.eval.suite import floor
    from sctd_services.teach.plan import plan_demonstration, scene_geometry

    task = read(hold_doc())
    stay = task.intent[1].action
    assert stay == hold(0.02, 0.5) and stay.frame() == "hand"  # (the reach's frame, from the steps before)
    assert task_to_yaml(task)["intent"][1] == {"name": "stay", "hold": {"within": 0.02, "turn": 0.5}}
    assert read(task_to_yaml(task)).intent == task.intent
    first = hold_doc()
    first["intent"] = first["intent"][1:]
    with pytest.raises(TaskError, match=r"intent\[0\]\.hold: a hold step moves the frame of a reach before"):
        read(first)
    # its mind runs in the task's intent, sharing the reach's look of the goal
    it = TaskIntent(task)
    T_obj = task.scene.bodies["light_switch"].T_world
    T_goal = np.eye(4)
    T_goal[:3, 3] = T_obj[:3, :3] @ [0.1, 0.0, 0.0] + T_obj[:3, 3]
    obs = Observation(0.0, T_goal, {"light_switch": T_obj}, {"readings": {}})
    d = it.desire(obs)  # the reach is done at its goal: on to the hold
    assert (it.phase, d.error, d.close_enough, d.twist.tolist()) == ("stay", 0.0, True, [1.0] * 6)
    it.settle()  # its kind says a person settles: on past it
    assert it.phase == "done"
    # the demonstrator plans it by its legs (the default plan), the floor adds its turn
    p = plan_demonstration(scene_geometry(task), 0, 1)
    assert [(s.kind, s.frame) for s in p.steps] == [("reach", "hand"), ("hold", "hand")]
    lim = Limits(max_linear_speed=0.1, max_angular_speed=0.5)
    without = dataclasses.replace(task, intent=task.intent[:1])
    assert floor(task, lim) == pytest.approx(floor(without, lim) + 1.0)
