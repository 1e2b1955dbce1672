"""The runtime's gripper (sctd.runtime.gripper through the tick driver): grasp presses
of the device that owns the motion close and open the hand, an open of a hand that
holds something needs the button held, a stop, fault, stale input, a released deadman
or a swap never opens it, the newest command is repeated with its number, and a
skill's entry action is sent once per entry. Every assertion is on the messages the
driver hands out and its status, in simulated time."""

from __future__ import annotations

import itertools
from pathlib import Path

import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd.runtime.controller import RuntimeConfig
from sctd.runtime.driver import TickDriver
from sctd.runtime.gripper import REPEAT
from sctd.skill import Bundle, load_skill, skill_from_bundle
from sctd.wire.codec import GripperCmd, GripperReading, InputMsg, StateMsg

ROOT = Path(__file__).resolve().parents[1]
TELEOP = load_skill(ROOT / "skills" / "teleop.yaml")
START = [0.4, 0.1, 0.9, 0.0, 0.0, 0.0, 1.0]
PERIOD = 1e-3
HELD = (0, 1, 0, 0, 0)  # the deadman held, nothing pressed (the five positions: grasp is 4)
GRASP = (0, 1, 0, 0, 1)  # ... and grasp held
EMPTY = GripperReading(0.08, False)  # open, holding nothing
HOLDING = GripperReading(0.03, True)  # closed on something
START_CMD = 7000


class Rig:
    """A tick driver with a robot that follows every target and reports ``reading``;
    messages arrive at given times, ticks every millisecond."""

    def __init__(self, skill=TELEOP, reading: GripperReading | None = EMPTY, **cfg):
        self.drv = TickDriver(skill, RuntimeConfig(**cfg), gripper_start=START_CMD)
        self.t, self.k = 0.0, 0
        self.pose = list(START)
        self.reading = reading
        self.fault: str | None = None
        self.state_on = True
        self.seq: dict[str, int] = {}
        self.sent: list[tuple[float, GripperCmd]] = []  # (tick time, message)
        self.tick()

    def send(self, device: str, u=(0.0, 0.0, 0.0), buttons=HELD, stop=False) -> int:
        """One message from ``device`` arriving now; its seq."""
        seq = self.seq[device] = self.seq.get(device, 0) + 1
        self.drv.take_input(device, InputMsg(seq, self.t, tuple(map(float, u)), tuple(buttons), stop), self.t)
        return seq

    def tick(self):
        self.k += 1
        self.t = self.k * PERIOD
        if self.state_on:
            self.drv.take_state(StateMsg(self.k, self.t, list(self.pose), None, fault=self.fault,
                                         gripper=self.reading), self.t)
        r = self.drv.tick(self.t, self.t)
        if r.pose is not None:
            self.pose = list(r.pose)
        if r.gripper is not None:
            self.sent.append((self.t, r.gripper))
        self.drv.after_tick()
        return r

    def run(self, seconds: float, device: str | None = None, buttons=HELD, every: float = 0.01, u=(0, 0, 0)):
        """Tick for ``seconds``; ``device`` sends ``buttons`` every ``every`` s meanwhile."""
        for k in range(round(seconds / PERIOD)):
            if device is not None and k % round(every / PERIOD) == 0:
                self.send(device, u, buttons)
            self.tick()

    def press(self, device: str = "pad", hold: float = 0.05, u=(0, 0, 0)) -> int:
        """Grasp pressed (and held ``hold`` s, a message every 10 ms), then released;
        the press's seq."""
        seq = self.send(device, u, GRASP)
        self.tick()
        self.run(hold - PERIOD, device, GRASP, u=u)
        self.send(device, u, HELD)
        self.tick()
        return seq

    def commands(self) -> list[GripperCmd]:
        """Each command once (its first message), in order."""
        seen: dict[int, GripperCmd] = {}
        for _, c in self.sent:
            seen.setdefault(c.cmd, c)
        return list(seen.values())

    def status(self) -> dict:
        return self.drv.gripper.status(self.t, self.drv.inputs.ignored_grasps)


def test_a_press_on_an_empty_open_hand_closes_it_with_the_default_force():
    rig = Rig(grasp_force=15.0)
    rig.run(0.2, "pad")
    assert rig.sent == []  # nothing is sent before anybody asks
    seq = rig.press()
    (c,) = rig.commands()
    assert (c.cmd, c.action, c.force, c.width) == (START_CMD, "close", 15.0, None)
    assert (c.in_seq, c.in_device, c.skill) == (seq, "pad", TELEOP.id)
    st = rig.status()
    assert (st["commands"], st["cmd"], st["action"], st["source"], st["presses"]) == \
        (1, START_CMD, "close", "input", 1)
    assert st["reading"] == {"width": 0.08, "grasped": False, "moving": False, "cmd": -1}


def test_while_nothing_is_grasped_a_press_toggles():
    rig = Rig()
    rig.press()
    rig.run(0.3, "pad")  # closed on nothing: the reading still says not grasped
    rig.press(hold=0.01)  # a short press opens: there is nothing to drop
    rig.run(0.3, "pad")
    rig.press()
    assert [(c.cmd, c.action) for c in rig.commands()] == \
        [(START_CMD, "close"), (START_CMD + 1, "open"), (START_CMD + 2, "close")]


def test_the_newest_command_is_repeated_at_10_hz_with_its_number():
    rig = Rig()
    rig.press()
    rig.run(2.0)  # the input goes stale meanwhile: the repeats go on, nothing new
    (c,) = rig.commands()
    times = [t for t, m in rig.sent]
    assert all(m.cmd == c.cmd and m.action == "close" and m.in_seq == c.in_seq for _, m in rig.sent)
    assert [m.seq for _, m in rig.sent] == list(range(len(rig.sent)))  # each message numbered
    # every 0.1 s of the driver's clock (absolute deadlines: within a tick, no drift), not every tick
    gaps = [b - a for a, b in itertools.pairwise(times)]
    assert len(gaps) >= 19 and all(abs(g - REPEAT) <= PERIOD + 1e-9 for g in gaps)
    assert abs((times[-1] - times[0]) - REPEAT * len(gaps)) <= PERIOD + 1e-9
    assert rig.status()["messages"] == len(rig.sent) and rig.status()["commands"] == 1


def test_a_device_that_does_not_own_the_motion_cannot_grasp():
    rig = Rig()
    for _ in range(50):  # A pushes: it owns the motion
        rig.send("A", (1, 0, 0))
        rig.send("B", (0, 0, 0), GRASP if _ == 10 else HELD)
        rig.tick()
    assert rig.drv.inputs.summary()["owner"] == "A"
    assert rig.sent == [] and rig.status()["ignored_presses"] == 1
    rig.send("A", (0, 0, 0))  # A lets go: nobody owns the motion, B's press acts
    rig.tick()
    seq = rig.press("B")
    (c,) = rig.commands()
    assert (c.action, c.in_device, c.in_seq) == ("close", "B", seq)
    assert rig.status()["ignored_presses"] == 1


def test_the_owner_grasps_while_it_moves():
    rig = Rig()
    seq = rig.press("A", u=(0.5, 0, 0))
    (c,) = rig.commands()
    assert (c.action, c.in_device, c.in_seq) == ("close", "A", seq)


def test_opening_a_hand_that_holds_something_needs_the_button_held():
    rig = Rig(reading=HOLDING, grasp_open_hold=0.5)
    rig.run(0.1, "pad")
    rig.press(hold=0.3)  # a tremor: released before the hold time
    rig.run(1.0, "pad")
    assert rig.sent == [] and rig.status()["cancelled"] == 1 and rig.status()["holding"] is None
    seq = rig.send("pad", buttons=GRASP)
    pressed_at = rig.t
    rig.tick()
    rig.run(0.3, "pad", GRASP)
    assert rig.sent == [] and rig.status()["holding"]["device"] == "pad"
    rig.run(0.3, "pad", GRASP)
    (c,) = rig.commands()
    assert (c.action, c.in_seq, c.in_device, c.force) == ("open", seq, "pad", None)
    opened_at = rig.sent[0][0]
    assert 0.5 <= opened_at - pressed_at <= 0.5 + 2 * PERIOD
    assert rig.status()["holding"] is None
    rig.run(0.5, "pad", GRASP)  # still held: it does not open again
    assert len(rig.commands()) == 1


def test_a_hand_of_unknown_state_that_was_closed_opens_only_when_held():
    rig = Rig(reading=None)  # the robot reports no gripper
    rig.press()
    assert [c.action for c in rig.commands()] == ["close"]
    rig.run(0.3, "pad")
    rig.press(hold=0.2)
    assert [c.action for c in rig.commands()] == ["close"]  # what it holds is not known
    rig.press(hold=0.6)
    assert [c.action for c in rig.commands()] == ["close", "open"]


def _holding_rig() -> Rig:
    rig = Rig(reading=HOLDING)
    rig.run(0.1, "pad")
    rig.send("pad", buttons=GRASP)
    rig.tick()
    rig.run(0.2, "pad", GRASP)
    assert rig.status()["holding"] is not None
    return rig


def test_a_stop_ends_a_hold_and_opens_nothing():
    rig = _holding_rig()
    rig.send("other", (0, 0, 0), HELD, stop=True)
    rig.tick()
    rig.send("other", (0, 0, 0), HELD)  # the stop let go at once: the hold is over all the same
    rig.run(1.0, "pad", GRASP)
    assert rig.sent == [] and rig.status()["cancelled"] == 1


def test_a_press_during_a_stop_does_nothing():
    rig = Rig()
    rig.run(0.1, "pad")
    rig.send("pad", (0, 0, 0), GRASP, stop=True)
    rig.tick()
    rig.run(0.5, "pad", GRASP)
    assert rig.sent == [] and rig.status()["cancelled"] == 1


def test_a_released_deadman_ends_a_hold_and_opens_nothing():
    rig = _holding_rig()
    rig.run(1.0, "pad", (0, 0, 0, 0, 1))  # grasp still held, the deadman released
    assert rig.sent == [] and rig.status()["cancelled"] == 1


def test_stale_input_ends_a_hold_and_opens_nothing():
    rig = _holding_rig()
    rig.run(1.0)  # the pad falls silent with grasp held
    assert rig.sent == [] and rig.status()["cancelled"] == 1
    rig.run(0.5, "pad", GRASP)  # it comes back, still held: no new press, no open
    assert rig.sent == []


def test_a_fault_ends_a_hold_and_opens_nothing():
    rig = _holding_rig()
    rig.fault = "reflex"
    rig.run(0.1, "pad", GRASP)
    rig.fault = None
    rig.run(1.0, "pad", GRASP)
    assert rig.sent == [] and rig.status()["cancelled"] == 1


def test_another_device_taking_the_motion_ends_a_hold():
    rig = _holding_rig()
    for _ in range(600):
        rig.send("B", (1, 0, 0))
        if _ % 10 == 0:
            rig.send("pad", (0, 0, 0), GRASP)
        rig.tick()
    assert rig.sent == [] and rig.status()["cancelled"] == 1


def test_nothing_but_a_press_or_an_entry_makes_a_command():
    """Once closed: a stop, a fault, a released deadman, stale input and stale state,
    a swap, the bridge's zeros: only the close's repeats."""
    rig = Rig(reading=HOLDING)
    rig.reading = EMPTY
    rig.press()
    rig.reading = HOLDING  # it closed on something
    rig.run(0.2, "pad")
    rig.send("pad", stop=True)
    rig.run(0.2, "pad")
    rig.fault = "reflex"
    rig.run(0.2, "pad")
    rig.fault = None
    rig.run(0.2, "pad", (0, 0, 0, 0, 0))  # the deadman released, then the bridge's zeros
    rig.run(0.5)  # stale input
    rig.state_on = False
    rig.run(0.5, "pad")  # stale state
    rig.state_on = True
    rig.drv.swap(load_skill(ROOT / "skills" / "teleop.yaml"), rig.t)
    rig.run(0.5, "pad")
    assert [c.action for c in rig.commands()] == ["close"] and len(rig.sent) > 20


def test_presses_are_counted_by_message_not_by_tick():
    """Two presses arriving between two ticks are two presses (a toggle there and back);
    a held button over many messages and ticks is one."""
    rig = Rig()
    rig.run(0.1, "pad")
    for buttons in (GRASP, HELD, GRASP, HELD):
        rig.send("pad", buttons=buttons)
    rig.tick()
    assert rig.status()["presses"] == 2 and [c.action for c in rig.commands()] == ["open"]
    rig.run(0.5, "pad", GRASP)
    assert rig.status()["presses"] == 3 and [c.action for c in rig.commands()] == ["open", "close"]


def pick_skill():
    doc = {
        "sctd_skill": 1, "name": "pick", "object": "world",
        "fsm": {"start": "approach", "end": "carry", "min_dwell": 0.0, "transitions": [
            {"from": "approach", "to": "grasp", "type": "button", "button": 0},
            {"from": "grasp", "to": "approach", "type": "button", "button": 0},
            {"from": "grasp", "to": "carry", "type": "gripper", "grasped": True},
        ]},
        "states": {"approach": {"input_mapping": [{"type": "linear", "axes": ["tx", "ty", "tz"]}],
                                "gripper": {"action": "open", "width": 0.08}},
                   "grasp": {"gripper": {"action": "close", "force": 30}}, "carry": {}},
    }
    return skill_from_bundle(Bundle("pick.yaml", yaml.safe_dump(doc), {}))


def test_a_states_entry_close_is_sent_once_per_entry():
    skill = pick_skill()
    rig = Rig(skill)
    rig.run(0.2, "pad")
    assert rig.sent == [] and rig.drv.engine.state == "approach"  # the start asks nothing
    rig.send("pad", buttons=(1, 1, 0))  # mode: approach -> grasp
    rig.tick()
    rig.run(1.0, "pad")
    (c,) = rig.commands()
    assert (c.action, c.force, c.in_seq, c.in_device, c.skill) == ("close", 30.0, -1, "", skill.id)
    assert 10 <= len(rig.sent) <= 11 and rig.status()["source"] == "skill"
    rig.send("pad", buttons=(1, 1, 0))  # back to approach (opens), and into grasp again (closes)
    rig.tick()
    rig.send("pad")
    rig.tick()
    rig.send("pad", buttons=(1, 1, 0))
    rig.tick()
    assert [(c.cmd, c.action) for c in rig.commands()] == \
        [(START_CMD, "close"), (START_CMD + 1, "open"), (START_CMD + 2, "close")]


def test_a_grasped_transition_follows_the_readings_of_fresh_states_only():
    rig = Rig(pick_skill())
    rig.send("pad", buttons=(1, 1, 0))
    rig.tick()
    rig.run(0.2, "pad")
    assert rig.drv.engine.state == "grasp"
    rig.reading = None  # the robot stops reporting its gripper: nothing fires
    rig.run(0.2, "pad")
    assert rig.drv.engine.state == "grasp"
    rig.reading = HOLDING
    rig.state_on = False  # a stale state says nothing either
    rig.k += 1  # a state that says grasped, but arrived long ago
    rig.drv.take_state(StateMsg(rig.k, rig.t, list(rig.pose), None, gripper=HOLDING), rig.t - 1.0)
    rig.run(0.2, "pad")
    assert rig.drv.engine.state == "grasp"
    rig.state_on = True
    rig.run(0.2, "pad")
    assert rig.drv.engine.state == "carry"


# --- a property: only a held press opens a hand that holds something ------------------------

EVENTS = st.lists(st.tuples(st.sampled_from(("grasp", "held", "off", "stop", "silent")),
                            st.integers(1, 40)), min_size=1, max_size=25)


@settings(max_examples=80, deadline=None)
@given(events=EVENTS)
def test_an_open_is_sent_only_when_grasp_was_held_long_enough(events):
    """While the hand holds something, a random schedule of a pad's messages every 10 ms
    (grasp held, released, the deadman released, grasp with another device's stop, or
    silence): an open is sent only after a press whose device's messages all held grasp,
    fresh and enabled, with no stop, for the hold time, and it names that press; when
    such a hold happened, an open was sent."""
    hold, timeout = 0.2, RuntimeConfig().input_timeout
    rig = Rig(reading=HOLDING, grasp_open_hold=hold)
    log: list[tuple[float, int, str]] = []  # (arrival, seq, kind) of every pad message
    buttons = {"grasp": GRASP, "held": HELD, "off": (0, 0, 0, 0, 0), "stop": GRASP}
    for kind, periods in events:
        for _ in range(periods):
            if rig.sent:
                break
            if kind != "silent":
                log.append((rig.t, rig.send("pad", buttons=buttons[kind]), kind))
                if kind == "stop":
                    rig.send("other", stop=True)
            for _ in range(10):
                rig.tick()
                if rig.sent:
                    break
    if rig.sent:
        (c,) = rig.commands()
        assert c.action == "open"
        assert _held_through(log, c.in_seq, rig.sent[0][0], hold, timeout)
    else:
        assert not any(_held_for(log, k, hold) for k in range(len(log)))


def _edge(log, k: int) -> bool:
    """Whether pad message ``k`` pressed grasp (and held it: not with a stop)."""
    grasp_held = ("grasp", "stop")
    return log[k][2] == "grasp" and (k == 0 or log[k - 1][2] not in grasp_held)


def _held_through(log, seq: int, opened: float, hold: float, timeout: float) -> bool:
    """What must have been for an open at ``opened`` naming press ``seq`` (necessary)."""
    k = next(i for i, e in enumerate(log) if e[1] == seq)
    t0 = log[k][0]
    after = log[k:]
    times = [t for t, _, _ in after] + [opened]
    return (_edge(log, k) and all(kind == "grasp" for _, _, kind in after) and opened - t0 >= hold - 1e-9
            and all(b - a <= timeout + 1e-6 for a, b in itertools.pairwise(times))
            and not any(kind == "stop" and t >= t0 - (timeout - 0.002) for t, _, kind in log))


def _held_for(log, k: int, hold: float) -> bool:
    """Whether press ``k`` was surely held long enough to open (sufficient): grasp in
    every message 10 ms apart, no stop within 0.1 s before it, until 10 ms after the
    last of them reaches the hold time (a tick's rounding allowed)."""
    if not _edge(log, k) or any(kind == "stop" and log[k][0] - 0.102 <= t <= log[k][0] for t, _, kind in log):
        return False
    last = log[k][0]
    for t, _, kind in log[k + 1:]:
        if kind != "grasp" or t - last > 0.01 + 1e-6:
            break
        last = t
    return last + 0.010 >= log[k][0] + hold + 0.0015
