"""A state may name its own object (``states.<name>.object``): the reader, the writer,
the engine's active body, and the runtime's tick with two bodies, one of them stale."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml

from sctd import se3
from sctd.runtime.controller import RuntimeConfig
from sctd.runtime.driver import TickDriver
from sctd.skill import SkillEngine
from sctd.skill.errors import SkillError
from sctd.skill.loader import Bundle, skill_from_bundle
from sctd.skill.summary import skill_summary
from sctd.skill.writer import bundle_from_skill, dump_skill
from sctd.wire import codec

PERIOD = 1e-3


def pick_doc(carry_object: object = "tabletop", **carry) -> dict:
    """Reach relative to the cup (tx, ty, tz), carry relative to the table top (button 0
    on), back by button 3."""
    return {
        "sctd_skill": 1, "name": "pick", "object": "cup",
        "limits": {"max_linear_speed": 0.1, "max_angular_speed": 0.5},
        "fsm": {"start": "reach", "end": "carry", "min_dwell": 0.0,
                "transitions": [{"from": "reach", "to": "carry", "type": "button", "button": 0},
                                {"from": "carry", "to": "reach", "type": "button", "button": 3}]},
        "states": {
            "reach": {"input_mapping": [{"type": "linear", "frame": "ee", "axes": ["tx", "ty", "tz"]}]},
            "carry": {"object": carry_object, **carry,
                      "input_mapping": [{"type": "linear", "frame": "ee", "axes": ["tx", "ty", "tz"]}],
                      "active_constraints": [{"type": "band", "normal": [0, 0, 1], "point": [0, 0, 0],
                                              "lower": 0.05, "upper": 0.3}]},
        },
    }


def load(doc: dict):
    return skill_from_bundle(Bundle("pick.yaml", yaml.safe_dump(doc, sort_keys=False), {}))


# --- reading and writing ------------------------------------------------------------------


def test_a_state_reads_its_own_object_and_the_skill_lists_every_body():
    skill = load(pick_doc())
    assert skill.object == "cup"
    assert [s.object for s in skill.states] == [None, "tabletop"]
    assert [skill.state_object(i) for i in range(2)] == ["cup", "tabletop"]
    assert skill.objects() == ("cup", "tabletop")
    summary = skill_summary(skill)
    assert summary["objects"] == ["cup", "tabletop"]
    assert summary["states"][1]["object"] == "tabletop" and "object" not in summary["states"][0]


def test_a_state_without_an_object_is_in_the_skills_frame_and_writes_none():
    doc = pick_doc()
    del doc["states"]["carry"]["object"]
    skill = load(doc)
    assert skill.objects() == ("cup",)
    assert "object:" not in dump_skill(skill).split("states:")[1]


def test_a_state_naming_the_skills_object_or_the_world_reads():
    assert load(pick_doc("cup")).objects() == ("cup",)
    assert load(pick_doc("world")).objects() == ("cup", "world")


@pytest.mark.parametrize(("value", "problem"), [
    (None, "expected a non-empty string, got nothing"),
    ("", "expected a non-empty string"),
    (3, "expected a non-empty string, got int"),
    ("table/top", "expected a body's name"),
    ("tab*", "expected a body's name"),
    (".hidden", "starts with a dot"),
    ("x" * 65, "at most 64"),
])
def test_a_bad_state_object_is_an_error_naming_the_field(value, problem):
    with pytest.raises(SkillError) as e:
        load(pick_doc(value))
    assert "pick.yaml: states.carry.object: " in str(e.value)
    assert problem in str(e.value)


def test_the_writer_gives_back_the_states_object():
    skill = load(pick_doc())
    text = bundle_from_skill(skill).yaml_text
    assert yaml.safe_load(text)["states"]["carry"]["object"] == "tabletop"
    back = skill_from_bundle(Bundle("pick.yaml", text, {}))
    assert back.states == skill.states and back.objects() == skill.objects()


# --- the engine ---------------------------------------------------------------------------


def test_the_engines_object_follows_the_active_state():
    engine = SkillEngine(load(pick_doc()))
    F = se3.flat_from_pose([0.0, 0.0, 0.1, 0.0, 0.0, 0.0, 1.0])
    assert engine.object == "cup"
    assert engine.update(F, 0.0, pressed={0})
    assert (engine.state, engine.object) == ("carry", "tabletop")
    assert engine.update(F, 0.1, pressed={3})
    assert (engine.state, engine.object) == ("reach", "cup")
    engine.reset(0.2, "carry")
    assert engine.object == "tabletop"


# --- the runtime --------------------------------------------------------------------------

CUP = [0.6, 0.1, 0.8, 0.0, 0.0, 0.0, 1.0]
TABLE = [0.5, -0.2, 0.75, 0.0, 0.0, math.sin(0.3), math.cos(0.3)]  # turned: the frames differ
HAND = [0.55, 0.05, 0.9, 1.0, 0.0, 0.0, 0.0]


class Rig:
    """A tick driver fed as the daemon feeds it; the robot follows each target at once."""

    def __init__(self, doc: dict):
        self.driver = TickDriver(load(doc), RuntimeConfig(stamp_check=False))
        self.t, self.k = 0.0, 0
        self.hand = list(HAND)
        self.fresh = {"cup": True, "tabletop": True}

    def tick(self, u=(0.0, 0.0, 0.0), buttons=()):
        self.k += 1
        self.t = self.k * PERIOD
        drv, t, k = self.driver, self.t, self.k
        drv.receive("state", "", codec.encode_state(k, t, self.hand), t)
        for name, pose in (("cup", CUP), ("tabletop", TABLE), ("shelf", CUP)):
            if self.fresh.get(name, True):
                drv.receive("object", name, codec.encode_object(k, t, pose), t)
        drv.receive("input", "stick", codec.encode_input(k, t, u, buttons), t)
        res = drv.tick(t, t)
        if res.pose is not None:
            self.hand = list(res.pose)
        return res


def _distance(a, b) -> float:
    return float(np.linalg.norm(np.subtract(a[:3], b[:3])))


def test_the_driver_keeps_every_body_the_skill_names_and_no_other():
    rig = Rig(pick_doc())
    rig.tick()
    assert set(rig.driver.objects) == {"cup", "tabletop"}


def test_switching_to_a_state_in_another_bodys_frame_never_jumps_the_target():
    rig = Rig(pick_doc())
    for _ in range(20):
        rig.tick((1.0, 0.0, 0.0))
    before = rig.hand
    switched = rig.tick((1.0, 0.0, 0.0), buttons=(1, 1, 0, 0))  # mode switch pressed, enabled
    assert switched.state == "carry" and switched.state_changed
    # the tick that entered carry publishes the unchanged target (a pose in the world)
    assert switched.pose == pytest.approx(before, abs=1e-12)
    previous = switched.pose
    for _ in range(20):
        res = rig.tick((1.0, 0.0, 0.0), buttons=(1, 1, 0, 0))
        assert res.mode == "running" and res.state == "carry"
        assert _distance(res.pose, previous) <= 0.1 * PERIOD + 1e-9  # a step, never a jump
        previous = res.pose
    # carry's tx is the table top's x axis (turned 0.6 rad about z), not the cup's
    step = np.subtract(previous[:3], switched.pose[:3])
    R_table = se3.transform_from_pose(TABLE)[:3, :3]
    assert np.allclose(step / np.linalg.norm(step), R_table[:, 0], atol=1e-6)


def test_in_a_state_whose_object_is_stale_the_hand_holds():
    rig = Rig(pick_doc())
    rig.fresh["tabletop"] = False  # the table top was seen once, then never again
    rig.driver.receive("object", "tabletop", codec.encode_object(0, 0.0, TABLE), 0.0)
    for _ in range(10):
        assert rig.tick((1.0, 0.0, 0.0)).mode == "running"  # reach: the cup is fresh
    rig.t = 1.5
    rig.k = 1500  # past the object timeout (1 s) of the table top's one pose
    rig.tick((1.0, 0.0, 0.0))
    res = rig.tick((1.0, 0.0, 0.0), buttons=(1, 1, 0, 0))
    assert res.state == "carry"
    held = rig.hand
    for _ in range(50):
        res = rig.tick((1.0, 0.0, 0.0), buttons=(1, 1, 0, 0))
        assert res.mode == "hold" and res.pose == held  # the unchanged target, published
    assert rig.driver.counters.stale_object >= 1
    rig.fresh["tabletop"] = True  # seen again: the hand moves on from where it held
    res = rig.tick((1.0, 0.0, 0.0), buttons=(1, 1, 0, 0))
    assert res.mode == "running" and _distance(res.pose, held) <= 0.1 * PERIOD + 1e-9


def test_a_stale_object_of_another_state_does_not_hold_the_active_one():
    rig = Rig(pick_doc())
    rig.fresh["tabletop"] = False  # never seen at all
    start = None
    for _ in range(20):
        res = rig.tick((1.0, 0.0, 0.0))
        assert res.mode == "running" and res.state == "reach"
        start = start or res.pose
    assert _distance(rig.hand, start) > 0.001


def test_the_status_reports_each_bodys_age_and_the_active_one():
    from sctd.runtime.status import DaemonStatus, TickStats
    from sctd.runtime.swap import SkillSwap
    from sctd.timing import Ticker

    rig = Rig(pick_doc())
    rig.fresh["tabletop"] = False
    rig.tick()
    status = DaemonStatus(rig.driver, TickStats(0.0, "reach", 0.1), SkillSwap(rig.driver))
    st = status.map(Ticker(PERIOD), rig.t + 0.25, 0.0)
    assert st["object"] == "cup" and st["object_age"] == pytest.approx(0.25)
    assert st["objects"] == {"cup": pytest.approx(0.25), "tabletop": None}


@pytest.mark.parametrize("name", ["tabletop", "table_top-2", "a" * 64, "a" * 65, "", ".x", "a b", "a/b",
                                  "a\\b", "a*", "a$", "a?", "a#", "a@", "a\tb", "é"])
def test_a_states_object_follows_the_wires_name_rule(name):
    """The reader's rule for a state's object is the wire's for object names (the skill
    layer cannot import the wire's)."""
    try:
        load(pick_doc(name))
        read = True
    except SkillError:
        read = False
    assert read == (codec.name_problem(name) == "")
