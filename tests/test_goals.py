"""A skill set on the tick driver (sctd.runtime.goals): the belief over the tasks
whose objects are present, engagement only at rest, escape and choose, and nothing
moving without input."""

import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd.runtime.arbiter import Command
from sctd.runtime.controller import RuntimeConfig
from sctd.runtime.driver import TickDriver
from sctd.runtime.goals import TELEOP, Belief, BeliefModel, GoalSet, Member
from sctd.skill import load_skill
from sctd.skill.loader import Bundle, skill_from_bundle
from sctd.wire import codec

ROOT = Path(__file__).resolve().parents[1]
PERIOD = 1e-3
OBJECTS = {"obj_a": (0.60, 0.30, 0.50), "obj_b": (0.60, -0.30, 0.50), "obj_c": (0.85, 0.0, 0.90)}
START = (0.30, 0.0, 0.50)


def member_skill(name: str, obj: str, upright: bool = False) -> object:
    """A one-state skill on ``obj`` (x, y, z in its frame); ``upright``: its start state
    keeps the hand's z within 0.1 rad of the object's (a start region with a shape)."""
    cone = ("\n    active_constraints:\n      - {type: tilt_cone, frame: ee, axis: [0, 0, 1], "
            "reference: [0, 0, 1], max_angle: 0.1}") if upright else ""
    text = f"""
sctd_skill: 1
name: {name}
object: {obj}
limits: {{max_linear_speed: 0.1, max_angular_speed: 0.5}}
fsm: {{start: free, end: free, min_dwell: 0.0, transitions: []}}
states:
  free:
    input_mapping: [{{type: linear, frame: ee, axes: [tx, ty, tz]}}]{cone}
"""
    return skill_from_bundle(Bundle(f"{name}.yaml", text, {}))


def goal_set(model: BeliefModel | None = None, upright_a: bool = False) -> GoalSet:
    members = [Member(member_skill("skill_a", "obj_a", upright_a), reach=0.15),
               Member(member_skill("skill_b", "obj_b"), reach=0.15),
               Member(member_skill("skill_c", "obj_c"), reach=0.15)]
    return GoalSet(members, load_skill(ROOT / "skills" / "teleop.yaml"), model)


def towards(pose, point) -> tuple[float, float, float]:
    """Full input straight at ``point`` (teleoperation's translation: world axes for a
    hand that is not turned)."""
    v = [g - x for g, x in zip(point, pose[:3], strict=True)]
    n = math.sqrt(sum(x * x for x in v)) or 1.0
    return (v[0] / n, v[1] / n, v[2] / n)


class Room:
    """The tick driver with a robot that follows each target at once, the objects
    published every tick (those in ``present``), and one input device."""

    def __init__(self, goals: GoalSet, start=START, tilt: float = 0.0, objects=None):
        self.objects = OBJECTS if objects is None else objects
        self.driver = TickDriver(None, RuntimeConfig(stamp_check=False), goals=goals)
        self.goals = goals
        c, s = math.cos(tilt / 2), math.sin(tilt / 2)
        self.pose = [*start, s, 0.0, 0.0, c]  # (a tilt about x)
        self.k = 0
        self.seq = 0
        self.present = set(self.objects)
        self.newest: tuple[tuple[float, ...], tuple[int, ...]] | None = None
        self.changes: list[tuple[str, str, tuple, tuple]] = []  # (from, to, newest u, buttons)
        self.poses: list[list[float]] = []

    def tick(self, u=(0.0, 0.0, 0.0), buttons=(0, 1, 0, 0), send: bool = True):
        t = self.k * PERIOD
        d = self.driver
        d.take_state(codec.StateMsg(self.k, t, list(self.pose), None), t)
        for name in self.present:
            d.take_object(name, codec.ObjectMsg(self.k, t, [*self.objects[name], 0.0, 0.0, 0.0, 1.0]), t)
        if send:
            self.seq += 1
            d.take_input("pad", codec.InputMsg(self.seq, t, tuple(u), tuple(buttons), False), t)
            self.newest = (tuple(u), tuple(buttons))
        before = d.skill.name
        res = d.tick(t, t)
        if d.skill.name != before:
            assert self.newest is not None
            self.changes.append((before, d.skill.name, *self.newest))
        if res.pose is not None:
            self.pose = list(res.pose)
            self.poses.append(list(res.pose))
        self.k += 1
        return res

    def push_towards(self, point, ticks: int):
        for _ in range(ticks):
            self.tick(towards(self.pose, point))

    def rest(self, ticks: int = 1):
        for _ in range(ticks):
            self.tick()

    def press(self, button: int):
        b = [0, 1, 0, 0]
        b[button] = 1
        self.tick(buttons=tuple(b))
        self.tick()  # released


def test_the_belief_follows_the_boltzmann_model_to_the_number():
    """Known answer: from the origin, 1 cm straight at goal A (1, 0, 0) costs A nothing
    and costs B (0, 1, 0) beta * (1 cm - (1 - sqrt(1 + 1e-4))) nats."""
    model = BeliefModel(beta=40.0)
    b = Belief(2, model)
    b.update((0.0, 0.0, 0.0), (0.01, 0.0, 0.0), [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)])
    pa, pb = b.probabilities([True, True])
    expected = model.beta * (0.01 - (1.0 - math.sqrt(1.0 + 1e-4)))
    assert math.log(pa / pb) == pytest.approx(expected, rel=1e-9)
    # no motion, no evidence
    b.update((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), [(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)])
    assert b.probabilities([True, True]) == [pa, pb]


def test_a_rest_near_one_goal_point_is_evidence_against_the_others_to_the_number():
    """Known answer: the hand rests 5 cm from obj_a (its goal point the object's origin),
    20 cm and more from the others: after 0.5 s of rest each other candidate has lost
    beta * rest_speed * 0.5 = 2 nats against obj_a. Motion restarts the count; a rest
    far from every goal point, or with rest_speed 0, is no evidence."""
    model = BeliefModel(beta=40.0, rest_speed=0.1, rest_radius=0.1, threshold=0.99)
    goals = goal_set(model)
    goals.see({n: (1, 0, 0, 0, 1, 0, 0, 0, 1, *p) for n, p in OBJECTS.items()})
    near = (1, 0, 0, 0, 1, 0, 0, 0, 1, 0.60, 0.25, 0.50)
    rest = Command((0.0, 0.0, 0.0), True, 1, "pad", frozenset())
    for k in range(501):  # the target has not moved yet: a hand found there says nothing
        goals.decide(rest, near, True, k * 1e-3)
    assert goals.belief.probabilities(goals.candidates) == pytest.approx([1 / 3] * 3, rel=1e-12)
    goals.observe((0.60, 0.24, 0.50), (0.60, 0.25, 0.50))  # 1 cm towards obj_a: it stopped here
    goals.decide(rest, near, True, 10.0)
    qa, qb, qc = goals.belief.probabilities(goals.candidates)
    for k in range(1, 501):  # 10 .. 10.5 s at 1 kHz
        goals.decide(rest, near, True, 10.0 + k * 1e-3)
    pa, pb, pc = goals.belief.probabilities(goals.candidates)
    assert math.log(pa / pb) - math.log(qa / qb) == pytest.approx(2.0, rel=1e-9)
    assert math.log(pa / pc) - math.log(qa / qc) == pytest.approx(2.0, rel=1e-9)
    assert goals.engaged is None  # 0.787 < 0.99
    push = rest._replace(u=(0.5, 0.0, 0.0))
    goals.decide(push, near, False, 11.0)
    goals.decide(rest, near, True, 20.0)  # (the 9 s since the last rest are not a rest)
    assert goals.belief.probabilities(goals.candidates) == pytest.approx([pa, pb, pc], rel=1e-12)
    far = (1, 0, 0, 0, 1, 0, 0, 0, 1, 0.30, 0.0, 0.50)
    for t, F, m in ((21.0, far, model), (22.0, far, model), (0.0, near, BeliefModel(rest_speed=0.0)),
                    (1.0, near, BeliefModel(rest_speed=0.0))):
        goals.model = goals.belief.model = m
        goals.decide(rest, F, True, t)
        assert goals.belief.probabilities(goals.candidates) == pytest.approx([pa, pb, pc], rel=1e-12)


def test_a_hand_that_stops_at_a_task_on_the_way_to_another_engages_it_after_a_rest():
    """obj_b lies straight beyond obj_a: the way to obj_a is the way to obj_b, and the
    belief stays split between them; resting at obj_a engages skill_a (about 0.35 s at
    the defaults: odds of 4 to 1 at 4 nats/s), which it would not without the rest's
    evidence."""
    objects = {"obj_a": (0.50, 0.0, 0.50), "obj_b": (0.80, 0.0, 0.50), "obj_c": (0.30, 0.50, 0.50)}
    for rest_speed, engaged in ((0.1, "skill_a"), (0.0, "teleop")):
        room = Room(goal_set(BeliefModel(rest_speed=rest_speed)), objects=objects)
        room.push_towards(objects["obj_a"], 1950)  # 0.195 m: 5 mm short of obj_a
        b = room.goals.status()["belief"]
        assert b["skill_a"] == pytest.approx(b["skill_b"], abs=1e-3) and b["skill_c"] < 0.01
        room.rest(200)
        assert room.driver.skill.name == "teleop"  # 0.2 s: not yet
        room.rest(2800)
        assert room.driver.skill.name == engaged
        assert all(u == (0.0, 0.0, 0.0) for _, _, u, _ in room.changes)


def test_no_belief_falls_below_the_floor_and_a_stale_object_leaves_the_candidates():
    b = Belief(3, BeliefModel(beta=40.0, floor=1e-3))
    goals = [(1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]
    for _ in range(1000):  # 10 m straight at the first: the second would be e^-800
        b.update((0.0, 0.0, 0.0), (0.01, 0.0, 0.0), goals)
    p = b.probabilities([True, True, True])
    assert p[1] == pytest.approx(1e-3, rel=1e-6) and p[0] > 0.99
    p = b.probabilities([False, True, True])
    assert p[0] == 0.0 and sum(p) == pytest.approx(1.0)


def test_pushing_at_a_task_engages_its_skill_once_the_stick_is_released():
    room = Room(goal_set())
    room.rest(5)
    assert room.driver.skill.name == "teleop" and room.goals.status()["engaged"] == TELEOP
    room.push_towards(OBJECTS["obj_a"], 3000)  # 0.1 m/s: there and held against it
    st = room.goals.status()
    assert st["belief"]["skill_a"] > 0.99
    assert room.driver.skill.name == "teleop", "engaged under a held stick"
    room.rest()
    assert room.driver.skill.name == "skill_a"
    assert room.changes == [("teleop", "skill_a", (0.0, 0.0, 0.0), (0, 1, 0, 0))]
    assert room.goals.status()["counters"]["engagements"] == 1


def test_a_hand_outside_the_start_region_does_not_engage():
    """The belief is sure, the hand is near, but tilted 0.3 rad where skill_a's start
    state allows 0.1: it stays in teleoperation."""
    room = Room(goal_set(upright_a=True), tilt=0.3)
    room.push_towards(OBJECTS["obj_a"], 3000)
    room.rest(3)
    assert room.goals.status()["belief"]["skill_a"] > 0.99
    assert room.driver.skill.name == "teleop"
    room2 = Room(goal_set(upright_a=True), tilt=0.05)
    room2.push_towards(OBJECTS["obj_a"], 3000)
    room2.rest()
    assert room2.driver.skill.name == "skill_a"


def test_escape_disengages_lowers_the_belief_and_waits_for_new_motion():
    room = Room(goal_set())
    room.push_towards(OBJECTS["obj_a"], 3000)
    room.rest()
    assert room.driver.skill.name == "skill_a"
    goals = room.goals
    before = goals.belief.probabilities(goals.candidates)[0]
    room.press(codec.BUTTON_ESCAPE)
    assert room.driver.skill.name == "teleop"
    after = goals.belief.probabilities(goals.candidates)[0]
    odds = lambda p: p / (1 - p)  # noqa: E731
    assert odds(after) == pytest.approx(odds(before) * goals.model.escape_factor, rel=1e-9)
    assert after < goals.model.threshold
    room.rest(100)
    assert room.driver.skill.name == "teleop"  # not taken straight back
    assert room.goals.status()["counters"]["escapes"] == 1


def test_choosing_teleoperation_is_not_taken_back_by_the_belief():
    """The belief engaged skill_a; the person cycles choose to teleoperation, at rest in
    skill_a's start region with the belief still sure of it: teleoperation stays until
    the person has moved rearm_travel, as after an escape; then the belief engages
    again."""
    room = Room(goal_set())
    room.push_towards(OBJECTS["obj_a"], 3000)
    room.rest()
    assert room.driver.skill.name == "skill_a"
    for _ in range(3):  # skill_b, skill_c, teleoperation
        room.press(codec.BUTTON_CHOOSE)
    assert room.driver.skill.name == "teleop"
    room.rest(1000)
    assert room.driver.skill.name == "teleop"
    assert room.goals.status()["belief"]["skill_a"] > 0.99
    room.push_towards(OBJECTS["obj_a"], 300)  # 3 cm, held against it
    room.rest()
    assert room.driver.skill.name == "skill_a"
    assert room.goals.status()["counters"]["engagements"] == 2


def test_escape_under_a_held_stick_waits_for_the_release():
    room = Room(goal_set())
    room.push_towards(OBJECTS["obj_a"], 3000)
    room.rest()
    room.tick((0.0, 0.5, 0.0), (0, 1, 1, 0))  # escape while pushing
    room.push_towards((0.6, 0.45, 0.5), 50)
    assert room.driver.skill.name == "skill_a"
    room.rest()
    assert room.driver.skill.name == "teleop"
    assert room.goals.status()["counters"]["deferred"] == 1


def test_choose_cycles_through_the_present_tasks_and_back_to_teleoperation():
    room = Room(goal_set())
    room.present = {"obj_a", "obj_c"}  # obj_b is not seen
    room.rest(3)
    names = []
    for _ in range(4):
        room.press(codec.BUTTON_CHOOSE)
        names.append(room.driver.skill.name)
    assert names == ["skill_a", "skill_c", "teleop", "skill_a"]
    assert set(room.goals.status()["belief"]) == {"skill_a", "skill_c"}
    assert room.goals.status()["counters"]["choices"] == 4


def test_engagement_keeps_the_target_where_it_is():
    room = Room(goal_set())
    room.push_towards(OBJECTS["obj_a"], 3000)
    held = list(room.pose)
    room.rest(3)
    assert room.driver.skill.name == "skill_a"
    assert room.poses[-1] == held


AXIS = st.sampled_from([0.0, 0.0, 0.01, -0.01, 0.3, -0.7, 1.0])  # zeros, within the dead band, pushes
STEP = st.tuples(
    st.one_of(st.tuples(AXIS, AXIS, AXIS), st.sampled_from(sorted(OBJECTS))),  # or: towards it
    st.sampled_from([(0, 1, 0, 0)] * 6 + [(0, 0, 0, 0), (0, 1, 1, 0), (0, 1, 0, 1), (0, 0, 0, 1)]),
    st.booleans(),  # a message this tick (else the newest stays, and may go stale)
    st.sampled_from([frozenset(OBJECTS)] * 4 + [frozenset({"obj_a"}), frozenset({"obj_b", "obj_c"})]),
    st.integers(1, 40),  # ticks it lasts
)


@given(st.lists(STEP, min_size=1, max_size=30))
@settings(max_examples=60, deadline=None)
def test_the_running_skill_changes_only_while_the_newest_input_is_at_rest(steps):
    """Random input streams (pushes, releases, the dead band, disabled input, escape and
    choose presses, gaps and objects coming and going): every change of the running
    skill happens at a tick whose newest input is zero (within the dead band) or
    disabled; no target step exceeds the per-tick bound of the skill it ran under; and
    a tick with zero input never moves the target."""
    model = BeliefModel(beta=200.0, threshold=0.6)  # quick to engage: many changes to judge
    room = Room(goal_set(model), start=(0.55, 0.2, 0.5))
    deadband = room.driver.config.deadband
    for u, buttons, send, present, ticks in steps:
        room.present = set(present)
        for k in range(ticks):
            before = list(room.pose)
            name = room.driver.skill.name
            push = towards(room.pose, OBJECTS[u]) if isinstance(u, str) else u
            res = room.tick(push, buttons if k == 0 else (0, buttons[1], 0, 0), send=send or k == 0)
            moved = math.dist(before[:3], room.pose[:3])
            if res.pose is not None and not res.seed:
                assert moved <= 0.1 * PERIOD * (1 + 1e-6) + 1e-12, (name, moved)
                newest_u = room.newest[0] if room.newest else (0.0, 0.0, 0.0)
                if all(abs(x) <= deadband for x in newest_u) or room.newest[1][1] == 0:
                    assert moved == 0.0
    for _, _, u, b in room.changes:
        assert all(abs(x) <= deadband for x in u) or b[1] == 0, room.changes


def test_a_set_needs_distinct_members():
    a = member_skill("skill_a", "obj_a")
    teleop = load_skill(ROOT / "skills" / "teleop.yaml")
    with pytest.raises(ValueError, match="differ"):
        GoalSet([Member(a), Member(a)], teleop)
    with pytest.raises(ValueError, match="at least one"):
        GoalSet([], teleop)
    with pytest.raises(ValueError, match="threshold"):
        BeliefModel(threshold=0.4)


def test_a_stick_whose_messages_stopped_while_held_is_not_at_rest():
    """A held push whose messages stop goes stale (zero command, nothing moves), but the
    stick may come back deflected: the change the belief asks for waits for a message
    at rest."""
    room = Room(goal_set())
    room.push_towards(OBJECTS["obj_a"], 3000)
    for _ in range(300):
        room.tick(send=False)
    assert room.driver.skill.name == "teleop"
    room.tick((0.0, 0.0, 0.0))
    assert room.driver.skill.name == "skill_a"


def test_the_choose_button_is_taken_out_of_the_command():
    goals = goal_set()
    cmd = Command((0.0, 0.0, 0.0), True, 1, "pad", frozenset({codec.BUTTON_CHOOSE, codec.BUTTON_MODE}))
    goals.see({n: (1, 0, 0, 0, 1, 0, 0, 0, 1, *p) for n, p in OBJECTS.items()})
    out, changed = goals.decide(cmd, None, True, 0.0)
    assert changed and out.pressed == frozenset({codec.BUTTON_MODE})


def test_a_swap_replaces_the_member_it_names_engaged_or_not():
    room = Room(goal_set())
    room.push_towards(OBJECTS["obj_a"], 3000)
    room.rest()
    assert room.driver.skill.name == "skill_a"
    d = room.driver
    d.swap_member("skill_b", member_skill("skill_b2", "obj_b"), room.k * PERIOD)
    assert d.skill.name == "skill_a"
    assert [m.name for m in room.goals.members] == ["skill_a", "skill_b2", "skill_c"]
    d.swap_member("skill_a", member_skill("skill_a2", "obj_a"), room.k * PERIOD)
    assert d.skill.name == "skill_a2" and room.goals.status()["engaged"] == "skill_a2"
    assert d.counters.swaps == 2
    with pytest.raises(KeyError, match="no member 'skill_x'"):
        d.swap_member("skill_x", member_skill("skill_x", "obj_a"), 0.0)
    with pytest.raises(ValueError, match="another member"):
        d.swap_member("skill_a2", member_skill("skill_c", "obj_c"), 0.0)
