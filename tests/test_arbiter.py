"""Several input devices and one motion (sctd.runtime.arbiter, through the tick driver):
a release is never lost, the first device to push owns the motion, buttons per device,
stop, and a bounded device table."""

from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd.runtime.arbiter import InputArbiter
from sctd.runtime.controller import Counters, RuntimeConfig
from sctd.runtime.driver import TickDriver
from sctd.skill import load_skill
from sctd.wire.codec import InputMsg, StateMsg

ROOT = Path(__file__).resolve().parents[1]
TELEOP = load_skill(ROOT / "skills" / "teleop.yaml")  # world frame, translate on axes 0-2
START = [0.4, 0.1, 0.9, 0.0, 0.0, 0.0, 1.0]
ENABLE, OFF, MODE = (0, 1, 0), (0, 0, 0), (1, 1, 0)
PERIOD = 1e-3
V = min(TELEOP.limits.max_linear_speed, RuntimeConfig().max_linear_speed)  # full speed, m/s


class Rig:
    """A tick driver on teleop with a robot that follows every target exactly; messages
    arrive at given times, ticks every millisecond."""

    def __init__(self, **cfg):
        self.drv = TickDriver(TELEOP, RuntimeConfig(**cfg))
        self.t = 0.0
        self.k = 0
        self.pose = list(START)
        self.seq: dict[str, int] = {}
        self.targets: list[tuple[int, list[float], int, str]] = []  # (tick, pose, in_seq, device)
        self.tick()  # seeds the target at START

    def send(self, device, u, buttons=ENABLE, stop=False, at=None, seq=None, stamp=None):
        """One message from ``device`` arriving at ``at`` (default: now); returns its seq."""
        seq = self.seq.get(device, 0) + 1 if seq is None else seq
        self.seq[device] = seq
        at = self.t if at is None else at
        self.drv.take_input(device, InputMsg(seq, at if stamp is None else stamp, tuple(map(float, u)),
                                             tuple(buttons), stop), at)
        return seq

    def tick(self):
        """The next tick: the robot's state first (it followed the last target)."""
        self.k += 1
        self.t = self.k * PERIOD
        self.drv.take_state(StateMsg(self.k, self.t, list(self.pose), None), self.t)
        r = self.drv.tick(self.t, self.t)
        if r.pose is not None:
            self.pose = list(r.pose)
            self.targets.append((self.k, list(r.pose), r.in_seq, r.device))
        self.drv.after_tick()
        return r

    def x(self):
        return self.pose[0]


def test_a_release_right_after_a_push_stops_the_target_at_once():
    """The audit's case: pushes at 1 kHz for 0.6 s, the release 0.2 ms after the last
    push, then silence. Every target from the release's seq on is the same, and the
    release reaches a target within 2 ticks of its arrival."""
    rig = Rig()
    for _ in range(600):
        rig.send("pad", [1, 0, 0], at=rig.t + 0.0003)
        rig.tick()
    release = rig.send("pad", [0, 0, 0], at=rig.t + 0.0005)  # 0.2 ms after the last push
    arrived = rig.t + 0.0005
    for _ in range(300):
        rig.tick()
    after = [(k, pose) for k, pose, in_seq, _ in rig.targets if in_seq >= release]
    assert after and all(pose == after[0][1] for _, pose in after)
    assert after[0][0] * PERIOD - arrived <= 2 * PERIOD
    assert rig.x() > START[0] + 0.05  # it did move before


def test_first_device_to_push_owns_the_motion_and_zeros_of_another_do_not_stop_it():
    """A pushes +x alone, then B sends zeros 0.2 ms before A every millisecond: A drives
    every tick (B's zeros neither slow nor stop it); B pushing -x meanwhile is ignored
    and counted, and B must come to rest before it can take the motion."""
    rig = Rig()
    for _ in range(50):
        rig.send("A", [1, 0, 0])
        rig.tick()
    speed = []
    for _ in range(200):
        x0 = rig.x()
        rig.send("B", [0, 0, 0])
        rig.send("A", [1, 0, 0], at=rig.t + 0.0002)
        r = rig.tick()
        speed.append((rig.x() - x0) / PERIOD)
        assert r.device == "A"
    assert min(speed) == pytest.approx(V)  # full speed, every tick
    c = rig.drv.counters
    for _ in range(100):
        x0 = rig.x()
        rig.send("B", [-1, 0, 0])
        rig.send("A", [1, 0, 0], at=rig.t + 0.0002)
        rig.tick()
        assert rig.x() > x0
    assert c.ignored_input == 100 and rig.drv.inputs.owner.name == "A"
    # A releases; B still deflected does not take over ...
    rig.send("A", [0, 0, 0])
    for _ in range(20):
        x0 = rig.x()
        rig.send("B", [-1, 0, 0])
        rig.tick()
        assert rig.x() == x0
    assert rig.drv.inputs.owner is None
    # ... until it has been at rest once
    rig.send("B", [0, 0, 0])
    rig.tick()
    for _ in range(20):
        rig.send("B", [-1, 0, 0])
        rig.tick()
    assert rig.drv.inputs.owner.name == "B" and rig.x() < x0


def test_a_deadman_released_on_the_other_device_does_not_stop_the_owner_but_stop_does():
    """Two devices 0.2 ms apart: A pushes, B holds still with its deadman. B releasing
    its deadman is B's business; B's stop halts the motion until A comes to rest and
    pushes again."""
    rig = Rig()
    for _ in range(100):
        rig.send("A", [1, 0, 0])
        rig.send("B", [0, 0, 0], at=rig.t + 0.0002)
        rig.tick()
    for _ in range(100):
        x0 = rig.x()
        rig.send("A", [1, 0, 0])
        rig.send("B", [0, 0, 0], OFF, at=rig.t + 0.0002)
        rig.tick()
        assert rig.x() - x0 == pytest.approx(V * PERIOD)
    rig.send("B", [0, 0, 0], ENABLE, stop=True)
    rig.send("A", [1, 0, 0], at=rig.t + 0.0002)
    rig.tick()
    held = rig.x()
    for k in range(100):  # A keeps pushing; B lets go of stop halfway
        rig.send("A", [1, 0, 0])
        rig.send("B", [0, 0, 0], stop=k < 50)
        rig.tick()
    assert rig.x() == held and rig.drv.counters.stops == 1
    rig.send("A", [0, 0, 0])
    rig.tick()
    for _ in range(10):
        rig.send("A", [1, 0, 0])
        rig.tick()
    assert rig.x() > held and rig.drv.inputs.owner.name == "A"


def test_buttons_are_tracked_per_device():
    """Two devices interleaved 0.2 ms apart, one holding button 0: one press, not one per
    alternation."""
    rig = Rig()
    for _ in range(40):
        rig.send("A", [0, 0, 0], MODE)
        rig.send("B", [0, 0, 0], ENABLE, at=rig.t + 0.0002)
        rig.tick()
    assert rig.drv.counters.presses == 1 and rig.drv.engine.state == "rotate"


def test_a_press_from_a_device_that_does_not_own_the_motion_is_ignored():
    rig = Rig()
    for _ in range(5):
        rig.send("A", [1, 0, 0])
        rig.tick()
    for b in (MODE, ENABLE):
        rig.send("A", [1, 0, 0])
        rig.send("B", [0, 0, 0], b)
        rig.tick()
    c = rig.drv.counters
    assert c.presses == 0 and c.ignored_presses == 1 and rig.drv.engine.state == "translate"


def test_a_device_without_buttons_is_always_enabled_and_takes_part_in_the_rule():
    rig = Rig()
    for _ in range(10):
        rig.send("script", [0, 1, 0], buttons=())
        rig.send("pad", [1, 0, 0], at=rig.t + 0.0002)
        rig.tick()
    assert rig.drv.inputs.owner.name == "script" and rig.pose[1] > START[1] and rig.pose[0] == START[0]
    assert rig.drv.counters.ignored_input == 10


def test_two_pushes_between_the_same_ticks_do_not_depend_on_the_order_offered():
    """Messages of two devices between two ticks have no order the daemon can know: the
    owner is the same whichever is offered first (earlier arrival, then name)."""
    owners = set()
    for order in (("A", "B"), ("B", "A")):
        rig = Rig()
        for name in order:
            rig.send(name, [1, 0, 0] if name == "A" else [-1, 0, 0], at=rig.t + 0.0001)
        rig.tick()
        owners.add(rig.drv.inputs.owner.name)
    assert owners == {"A"}


def test_the_device_table_is_bounded_and_an_idle_device_makes_room():
    c = Counters()
    a = InputArbiter(0.1, 0.02, True, c, max_devices=3, evict_after=10.0)
    for k in range(3):
        assert a.offer(f"d{k}", InputMsg(1, 0.0, (0.0, 0.0, 0.0)), 0.0)
    assert not a.offer("late", InputMsg(1, 5.0, (0.0, 0.0, 0.0)), 5.0)
    assert c.drops == {"input_devices_full": 1} and set(a.devices) == {"d0", "d1", "d2"}
    a.offer("d2", InputMsg(2, 11.0, (0.0, 0.0, 0.0)), 11.0)
    assert a.offer("late", InputMsg(1, 11.0, (0.0, 0.0, 0.0)), 11.0)  # d0 or d1 made room
    assert len(a.devices) == 3 and "late" in a.devices and "d2" in a.devices


def test_fifty_thousand_device_names_cost_nothing_beyond_the_table():
    import tracemalloc

    c = Counters()
    a = InputArbiter(0.1, 0.02, True, c)
    msg = InputMsg(1, 0.0, (0.0, 0.0, 0.0))
    tracemalloc.start()
    before = tracemalloc.take_snapshot()
    for k in range(50_000):
        a.offer(f"flood{k}", msg, 0.0)
    grown = sum(s.size_diff for s in tracemalloc.take_snapshot().compare_to(before, "filename"))
    tracemalloc.stop()
    assert len(a.devices) == a.max_devices and c.drops["input_devices_full"] == 50_000 - a.max_devices
    assert grown < 5 * 1024 * 1024


# --- the release property over arbitrary interleavings ---------------------------------

REST = ("zero", "disabled", "nonfinite")
KINDS = st.sampled_from(["push", "push", "zero", "disabled", "nonfinite", "dead"])
MESSAGES = st.lists(st.tuples(st.sampled_from(["A", "B", "C"]), st.integers(0, 2000), KINDS,
                              st.sampled_from([(1, 0, 0), (0, -0.6, 0.3), (0.02, 0.5, -1)])),
                    min_size=1, max_size=80)


def _content(kind, u):
    if kind == "push":
        return u, ENABLE
    if kind == "disabled":
        return u, OFF
    if kind == "nonfinite":
        return (float("nan"), 1.0, 0.0), ENABLE
    if kind == "dead":
        return (0.01, -0.015, 0.0), ENABLE  # inside the dead band: zero
    return (0.0, 0.0, 0.0), ENABLE


@given(MESSAGES, st.booleans())
@settings(max_examples=150, deadline=None)
def test_once_every_device_is_at_rest_or_stale_the_target_does_not_change(messages, stamp_gaps):
    """Up to three devices, messages 0-2 ms apart in any interleaving (pushes, zeros,
    released deadmen, non-finite input, dead-band noise): at every tick where each
    device's newest message is at rest or stale, the target is bitwise the one before."""
    rig = Rig()
    t = rig.t
    schedule = []
    for device, gap_us, kind, u in messages:
        t += gap_us * 1e-6
        schedule.append((t, device, kind, u))
    newest: dict[str, tuple[float, str]] = {}
    end = t + 0.3  # then silence: every device goes stale
    i = 0
    prev = list(rig.pose)
    while rig.t < end:
        tick_at = (rig.k + 1) * PERIOD
        while i < len(schedule) and schedule[i][0] <= tick_at:
            at, device, kind, u = schedule[i]
            values, buttons = _content(kind, u)
            # with stamp_gaps, some senders' clocks lag: stale on arrival
            stamp = at - 0.2 if stamp_gaps and device == "C" else at
            rig.send(device, values, buttons, at=at, stamp=stamp)
            newest[device] = (stamp, kind)
            i += 1
        r = rig.tick()
        quiet = all(kind in REST or kind == "dead" or rig.t - stamp > 0.1
                    for stamp, kind in newest.values())
        if quiet and r.pose is not None:
            assert r.pose == prev, f"moved at tick {rig.k} with every device at rest or stale"
        if r.pose is not None:
            prev = list(r.pose)


def test_enabling_again_with_the_stick_deflected_does_not_restart_motion():
    """Zero-start: the owner releases its deadman mid-push (motion stops at once);
    pressing it again with the stick still deflected moves nothing until the stick has
    been centred; a device whose deadman is released with the stick centred may push
    again at once."""
    rig = Rig()
    for _ in range(10):
        rig.send("A", [1, 0, 0])
        rig.tick()
    rig.send("A", [1, 0, 0], OFF)
    rig.tick()
    held = rig.x()
    for _ in range(20):
        rig.send("A", [1, 0, 0])
        rig.tick()
    assert rig.x() == held and rig.drv.inputs.owner is None
    rig.send("A", [0, 0, 0])
    rig.tick()
    for _ in range(5):
        rig.send("A", [1, 0, 0])
        rig.tick()
    assert rig.x() > held
    rig.send("A", [0, 0, 0], OFF)
    rig.tick()
    moved = rig.x()
    rig.send("A", [1, 0, 0])
    rig.tick()
    rig.tick()
    assert rig.x() > moved


GRACE = RuntimeConfig().stale_grace
TIMEOUT = RuntimeConfig().input_timeout


def test_a_push_held_through_a_stall_moves_nothing_after_it_until_a_zero():
    """Stale-disarm: A pushes, its messages stop for 0.5 s (a stalled link; the input
    timeout and the grace are 0.1 and 0.2 s), then come back with the stick still
    deflected: the target stands still, counted once (``stale_disarms``) and named on
    the status (``rearm``) until A sends a zero; A's next push moves the arm again."""
    rig = Rig()
    for _ in range(20):
        rig.send("A", [1, 0, 0])
        rig.tick()
    for _ in range(500):  # the stall: nothing arrives
        rig.tick()
    held = rig.x()
    assert rig.drv.inputs.owner is None and rig.drv.counters.stale_disarms == 1
    for _ in range(200):  # fresh messages, stick still deflected
        rig.send("A", [1, 0, 0])
        rig.tick()
    assert rig.x() == held and rig.drv.inputs.summary()["rearm"] == {"A": "stale"}
    rig.send("A", [0, 0, 0])
    rig.tick()
    assert rig.drv.inputs.summary()["rearm"] == {}
    for _ in range(20):
        rig.send("A", [1, 0, 0])
        rig.tick()
    assert rig.x() > held and rig.drv.counters.stale_disarms == 1


def test_a_stalled_backlog_of_old_pushes_then_fresh_ones_moves_nothing_until_a_zero():
    """The backlog a stall held arrives after it, one old message at a time (each 0.15 s
    old, stale by the stamp check, for 0.4 s: longer than the grace), then fresh ones,
    all deflected: none moves the arm, and the device is disarmed until it sends a
    zero."""
    rig = Rig()
    for _ in range(20):
        rig.send("A", [1, 0, 0])
        rig.tick()
    start = rig.t
    for _ in range(150):  # a stall shorter than the input timeout and the grace ...
        rig.tick()
    held = rig.x()
    for i in range(400):  # ... then each message sent in it arrives, 0.15 s late: the push
        rig.send("A", [1, 0, 0], stamp=start + i * PERIOD)  # stays stale past the grace
        rig.tick()
    for _ in range(100):
        rig.send("A", [1, 0, 0])
        rig.tick()
    assert rig.x() == held and rig.drv.inputs.summary()["rearm"] == {"A": "stale"}


def test_the_status_says_why_each_disarmed_device_must_send_a_zero():
    """``status.input.rearm``: a push while another owns (ignored), a deadman released
    with the stick deflected (released), a stop (every device, until its zero)."""
    rig = Rig()
    rig.send("A", [1, 0, 0])
    rig.tick()
    rig.send("B", [0, 1, 0])
    rig.send("C", [0, 1, 0], OFF)
    rig.tick()
    assert rig.drv.inputs.summary()["rearm"] == {"B": "ignored", "C": "released"}
    rig.send("C", [0, 0, 0], stop=True)
    rig.tick()
    assert rig.drv.inputs.summary()["rearm"] == {"A": "stop", "B": "stop", "C": "stop"}
    rig.send("C", [0, 0, 0])
    rig.tick()
    assert rig.drv.inputs.summary()["rearm"] == {"A": "stop", "B": "stop"}


def test_within_the_grace_fresh_input_takes_the_motion_back_and_with_none_it_does_not():
    """A gap in a push shorter than the input timeout plus the grace (0.25 s): the arm
    stops while the push is stale and moves again on the fresh push that follows,
    without a zero (a sender's hiccup); with ``stale_grace`` 0 the same gap needs the
    zero."""
    for grace, resumes in ((GRACE, True), (0.0, False)):
        rig = Rig(stale_grace=grace)
        for _ in range(20):
            rig.send("A", [1, 0, 0])
            rig.tick()
        for _ in range(250):
            rig.tick()
        held = rig.x()
        for _ in range(20):
            rig.send("A", [1, 0, 0])
            rig.tick()
        assert (rig.x() > held) is resumes, grace
        assert rig.drv.counters.stale_disarms == (0 if resumes else 1), grace


STALL_MESSAGES = st.lists(st.tuples(st.sampled_from(["push", "zero"]),
                                    st.one_of(st.integers(500, 2000), st.integers(101_000, 600_000)),
                                    st.integers(-1, 1)), min_size=1, max_size=60)


@given(STALL_MESSAGES, st.booleans())
@settings(max_examples=100, deadline=None)
def test_after_a_stall_that_held_a_push_nothing_moves_until_a_zero_arrives(messages, late_stamps):
    """One device, pushes and zeros with gaps of 0.5-2 ms or stalls of 0.1-0.6 s (longer
    than the input timeout); with ``late_stamps`` the message after a stall is one the
    stall held (stamped when it was sent). Whenever a push stayed the newest message
    for longer than the input timeout and the grace, no target moves until a zero has
    arrived after it."""
    rig = Rig()
    t, must_zero, newest = rig.t, False, "zero"
    prev = list(rig.pose)
    for kind, gap_us, sign in messages:
        stalled = gap_us > 100_000
        while (rig.k + 1) * PERIOD < t + gap_us * 1e-6:  # the ticks until the message arrives
            r = rig.tick()
            if newest == "push" and rig.t - t > TIMEOUT + GRACE + 3 * PERIOD:
                must_zero = True  # the push went stale with the stick deflected
            if must_zero and r.pose is not None:
                assert r.pose == prev, f"moved at tick {rig.k} before a zero after the stall"
            if r.pose is not None:
                prev = list(r.pose)
        at = t + gap_us * 1e-6
        stamp = t if stalled and late_stamps else at
        rig.send("A", [sign or 1, 0, 0] if kind == "push" else [0, 0, 0], at=at, stamp=stamp)
        t, newest = at, kind
        if kind == "zero":
            must_zero = False
