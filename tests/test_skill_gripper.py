"""A skill and the gripper (sctd.skill.gripper, the ``gripper`` transition, the engine's
entry actions): what a state asks at its entry, once per entry by a transition and
never at a start, a swap or an escape; ``grasped`` transitions on the newest reading,
never on an unknown one; errors that name the field."""

from __future__ import annotations

import pytest
import yaml

from sctd import se3
from sctd.skill import Bundle, GripperAction, SkillEngine, SkillError, skill_from_bundle
from sctd.skill import gripper as skill_gripper
from sctd.wire import codec

F0 = se3.flat_from_pose([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])


def pick_doc() -> dict:
    """approach (opens) -> grasp (closes) -> carry (when grasped), carry -> approach on
    button 0 (a re-try), grasp -> approach when the close found nothing."""
    return {
        "sctd_skill": 1, "name": "pick", "object": "world",
        "fsm": {"start": "approach", "end": "carry", "min_dwell": 0.0, "transitions": [
            {"from": "approach", "to": "grasp", "type": "button", "button": 0},
            {"from": "grasp", "to": "carry", "type": "gripper", "grasped": True},
            {"from": "grasp", "to": "approach", "type": "button", "button": 3},
            {"from": "carry", "to": "approach", "type": "gripper", "grasped": False},
        ]},
        "states": {"approach": {"gripper": {"action": "open"}},
                   "grasp": {"gripper": {"action": "close", "force": 20, "speed": 0.05}},
                   "carry": {}},
    }


def load(doc: dict):
    return skill_from_bundle(Bundle("pick.yaml", yaml.safe_dump(doc), {}))


def test_a_state_entered_by_a_transition_asks_once_per_entry():
    eng = SkillEngine(load(pick_doc()))
    assert eng.state == "approach" and eng.take_entry_action() is None  # the start asks nothing
    assert eng.update(F0, 0.0, pressed={0})
    assert eng.take_entry_action() == GripperAction(action="close", force=20.0, speed=0.05)
    assert eng.take_entry_action() is None  # once
    assert not eng.update(F0, 0.1)
    assert eng.take_entry_action() is None
    assert eng.update(F0, 0.2, pressed={3})  # back: approach opens again (a new entry)
    assert eng.take_entry_action() == GripperAction(action="open")
    assert eng.update(F0, 0.3, pressed={0})
    assert eng.take_entry_action().action == "close"  # and grasp closes again


def test_an_escape_a_reset_and_a_state_without_an_action_ask_nothing():
    eng = SkillEngine(load(pick_doc()))
    eng.update(F0, 0.0, pressed={0})
    eng.take_entry_action()
    assert eng.update(F0, 0.1, pressed={2}, escape=2) and eng.escaped and eng.state == "approach"
    assert eng.take_entry_action() is None  # escape went back to approach: it opens nothing
    eng.update(F0, 0.2, pressed={0})
    eng.take_entry_action()
    assert eng.update(F0, 0.3, grasped=True) and eng.state == "carry"
    assert eng.take_entry_action() is None  # carry has no action
    eng.reset(0.4, "grasp")
    assert eng.take_entry_action() is None  # a restart (a swap, a set's engagement) is no entry


@pytest.mark.parametrize(("reading", "fires"), [(True, True), (False, False), (None, False)])
def test_a_grasped_transition_fires_on_the_reading_and_never_on_an_unknown_one(reading, fires):
    eng = SkillEngine(load(pick_doc()))
    eng.update(F0, 0.0, pressed={0})
    assert eng.state == "grasp"
    assert eng.update(F0, 1.0, grasped=reading) is fires
    assert eng.state == ("carry" if fires else "grasp")


def test_a_grasp_lost_fires_grasped_false_and_no_reading_keeps_the_state():
    eng = SkillEngine(load(pick_doc()))
    eng.update(F0, 0.0, pressed={0})
    eng.update(F0, 0.1, grasped=True)
    assert eng.state == "carry"
    assert not eng.update(F0, 0.2, grasped=None)  # the robot stopped reporting: nothing
    assert not eng.update(F0, 0.3, grasped=True)
    assert eng.update(F0, 0.4, grasped=False) and eng.state == "approach"
    assert eng.take_entry_action() == GripperAction(action="open")


def test_the_min_dwell_holds_a_grasped_transition_as_any_condition():
    doc = pick_doc()
    doc["fsm"]["min_dwell"] = 0.5
    eng = SkillEngine(load(doc))
    eng.update(F0, 0.0, pressed={0})
    assert not eng.update(F0, 0.2, grasped=True)
    assert eng.update(F0, 0.6, grasped=True)


@pytest.mark.parametrize(("gripper", "where", "what"), [
    ({"action": "grab"}, "states.grasp.gripper.action", "expected one of open, close, width, got 'grab'"),
    ({"action": "close"}, "states.grasp.gripper.force", "action close needs a force bound"),
    ({"action": "close", "force": -5}, "states.grasp.gripper.force", "must be > 0.0, got -5.0"),
    ({"action": "close", "force": 0}, "states.grasp.gripper.force", "must be > 0.0"),
    ({"action": "width"}, "states.grasp.gripper.width", "action width needs a width"),
    ({"action": "width", "width": 0.6}, "states.grasp.gripper.width", "must be <= 0.5, got 0.6"),
    ({"action": "open", "width": -0.01}, "states.grasp.gripper.width", "must be >= 0.0"),
    ({"action": "open", "speed": 2}, "states.grasp.gripper.speed", "must be <= 1.0"),
    ({"action": "open", "force": "hard"}, "states.grasp.gripper.force", "expected a number, got str"),
    ({"action": "open", "grip": 1}, "states.grasp.gripper.grip", "unknown field"),
    ("close", "states.grasp.gripper", "expected a mapping, got str"),
])
def test_a_bad_gripper_action_names_its_field(gripper, where, what):
    doc = pick_doc()
    doc["states"]["grasp"]["gripper"] = gripper
    with pytest.raises(SkillError) as e:
        load(doc)
    assert f"pick.yaml: {where}: " in str(e.value) and what in str(e.value)


@pytest.mark.parametrize(("transition", "where", "what"), [
    ({}, "fsm.transitions[1].grasped", "needs grasped: true or false"),
    ({"grasped": "yes"}, "fsm.transitions[1].grasped", "expected true or false, got str"),
    ({"grasped": 1}, "fsm.transitions[1].grasped", "expected true or false, got int"),
    ({"grasped": True, "width": 0.1}, "fsm.transitions[1].width", "unknown field"),
])
def test_a_bad_gripper_transition_names_its_field(transition, where, what):
    doc = pick_doc()
    doc["fsm"]["transitions"][1] = {"from": "grasp", "to": "carry", "type": "gripper", **transition}
    with pytest.raises(SkillError) as e:
        load(doc)
    assert f"pick.yaml: {where}: " in str(e.value) and what in str(e.value)


def test_the_skills_ranges_are_the_wire_contracts():
    """A skill can ask for nothing a robot would refuse (decode_gripper's ranges)."""
    assert skill_gripper.GRIPPER_ACTIONS == codec.GRIPPER_ACTIONS
    assert skill_gripper.MAX_WIDTH == codec.MAX_GRIPPER_WIDTH
    assert skill_gripper.MAX_FORCE == codec.MAX_GRIPPER_FORCE
    assert skill_gripper.MAX_SPEED == codec.MAX_GRIPPER_SPEED


def test_the_summary_shows_a_states_gripper_action():
    from sctd.skill import skill_summary

    states = {s["name"]: s for s in skill_summary(load(pick_doc()))["states"]}
    assert states["grasp"]["gripper"] == {"action": "close", "force": 20.0, "speed": 0.05}
    assert "gripper" not in states["carry"]
