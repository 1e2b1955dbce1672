"""One tick, in the daemon and in the check: a recorded message stream (two input
devices, states, object poses, with their arrival ticks) replayed through the daemon's
path (bytes in its Zenoh rings, drained by its ingress into the tick driver) and through
the lockstep evaluation's path gives the same targets, to the bit."""

import math
from collections import deque
from pathlib import Path

import pytest

from sctd import se3
from sctd.runtime.controller import RuntimeConfig
from sctd.runtime.driver import TickDriver
from sctd.runtime.ingress import ANY_DEPTH, DEVICE_DEPTH, INPUT_BUDGET, Ingress
from sctd.runtime.loop import TickLoop
from sctd.runtime.swap import SkillSwap
from sctd.skill import load_skill
from sctd.wire import Keys, codec
from sctd_services.eval.lockstep import Feed

ROOT = Path(__file__).resolve().parents[1]
PERIOD = 1e-3
KEYS = Keys()


# --- a Zenoh session as the daemon's ingress sees it: rings filled by "arrivals" --------

class _Payload:
    def __init__(self, data: bytes):
        self.data = data

    def __len__(self):
        return len(self.data)

    def to_bytes(self):
        return self.data


class _Sample:
    def __init__(self, key: str, data: bytes):
        self.key_expr, self.payload = key, _Payload(data)


class _Sub:
    def __init__(self, key: str):
        self.key, self.ring = key, deque()
        self.live = True

    def try_recv(self):
        return self.ring.popleft() if self.ring else None

    def undeclare(self):
        self.live = False


class FakeSession:
    """Subscribers on exact keys and ``prefix/*``; :meth:`arrive` puts a message in
    every matching live ring (deep enough for the stream: the test keeps each ring's
    messages per period within the daemon's ring depths)."""

    def __init__(self):
        self.subs: list[_Sub] = []

    def declare_subscriber(self, key, handler):
        sub = _Sub(key)
        self.subs.append(sub)
        return sub

    def arrive(self, key: str, data: bytes):
        for sub in self.subs:
            wild = sub.key.endswith("/*") and key.rsplit("/", 1)[0] == sub.key[:-2]
            if sub.live and (sub.key == key or wild):
                sub.ring.append(_Sample(key, data))


# --- the stream ------------------------------------------------------------------------

def record_stream(skill_path: Path, ticks: int):
    """A closed-loop run through the lockstep path with a robot that follows each target
    one tick late: the messages (tick of arrival, kind, fields) and the targets."""
    skill = load_skill(skill_path)
    feed = Feed(TickDriver(skill, RuntimeConfig()))
    T_obj = se3.transform_from_pose([0.6, 0.1, 0.75, 0, 0, 0, 1])
    pose = se3.pose_from_transform(T_obj @ se3.transform_from_pose([-0.25, 0.05, 0.12, 0, 0, 0, 1])).tolist()
    msgs, targets = [], []
    seq = {"user": 0, "second": 0}
    for k in range(ticks):
        t = k * PERIOD
        state = {"pose": list(pose), "wrench": [0.0, 0.0, 0.5 * math.sin(k * 0.01), 0.0, 0.0, 0.0]}
        if k == 700:  # an injected jump: the fault, then a re-seed after zero input
            state["pose"] = [pose[0] + 0.2, *pose[1:]]
        msgs.append((k, "state", (k, t, state)))
        if k % 20 == 0:
            obj = se3.pose_from_transform(
                T_obj @ se3.transform_from_pose([0.0002 * (k // 100), 0, 0, 0, 0, 0, 1])).tolist()
            msgs.append((k, "object", (k, t, {"mug": obj, "bottle": obj})))
        if k % 10 == 0:  # the user, 100 Hz: a slow push, a mode press, a pause
            u = (0.8 * math.sin(k * 0.004), 0.6, 0.5 * math.cos(k * 0.003)) if (k // 400) % 2 == 0 \
                else (0.0, 0.0, 0.0)
            b = (1, 1, 0) if k % 600 == 300 else (0, 1, 0)
            seq["user"] += 1
            msgs.append((k, "input", ("user", seq["user"], t, u, b, False)))
        if k % 4 == 1:  # a second device at 250 Hz: zeros, a push while the user holds, a stop
            u = (-1.0, 0.0, 0.0) if 100 <= k < 200 else (0.0, 0.0, 0.0)
            seq["second"] += 1
            msgs.append((k, "input", ("second", seq["second"], t, u, (0, 1, 0), 500 <= k < 520)))
        for _, kind, args in (m for m in msgs if m[0] == k):
            _feed(feed, kind, args)
        r = feed.tick(t)
        targets.append((k, r.pose, r.in_seq, r.device, r.state, r.mode, r.seed))
        if r.pose is not None:
            pose = list(r.pose)
    return skill, msgs, targets


def _feed(feed: Feed, kind: str, args):
    if kind == "state":
        feed.state(*args)
    elif kind == "object":
        feed.objects(*args)
    else:
        feed.input(*args)


def replay_lockstep(skill, msgs, ticks):
    feed = Feed(TickDriver(skill, RuntimeConfig()))
    out = []
    by_tick = _by_tick(msgs)
    for k in range(ticks):
        for kind, args in by_tick.get(k, []):
            _feed(feed, kind, args)
        r = feed.tick(k * PERIOD)
        out.append((k, r.pose, r.in_seq, r.device, r.state, r.mode, r.seed))
    return out, feed.driver.counters


def replay_daemon(skill, msgs, ticks):
    """The daemon's own tick loop around its tick: drain (ingress into the driver), step,
    after-tick; the messages as bytes in its rings, arriving before each drain. Returns
    what it published, by tick: ``(tick, pose, in_seq, device, state, seed)``."""
    fake = FakeSession()
    driver = TickDriver(skill, RuntimeConfig())
    ingress = Ingress(fake, KEYS, driver)  # type: ignore[arg-type]
    out: list = []
    sent: list = []
    loop = TickLoop(driver, ingress, SkillSwap(driver), sent.append)
    by_tick = _by_tick(msgs)
    for k in range(ticks):
        t = k * PERIOD
        per_ring: dict[str, int] = {}
        for kind, args in by_tick.get(k, []):
            key, data = _wire(kind, args)
            per_ring[key] = per_ring.get(key, 0) + 1
            fake.arrive(key, data)
        assert max(per_ring.values(), default=0) <= min(DEVICE_DEPTH, ANY_DEPTH)
        before = len(sent)
        loop.before_tick(t)
        loop.step(t, t)
        loop.after_tick()
        # a queued target: (seq, stamp, pose, state, skill id, in_seq, in_device, seed)
        out += [(k, item[2], item[5], item[6], item[3], item[7]) for item in sent[before:]]
        assert [item[0] for item in sent[before:]] == list(range(before + 1, len(sent) + 1))
    return out, driver.counters


def _by_tick(msgs):
    by: dict[int, list] = {}
    for k, kind, args in msgs:
        by.setdefault(k, []).append((kind, args))
    return by


def _wire(kind: str, args):
    """A message as its sender puts it on the wire: key and msgpack bytes."""
    if kind == "state":
        seq, t, m = args
        return KEYS.state, codec.encode_state(seq, t, m["pose"], wrench=m["wrench"])
    if kind == "object":
        seq, t, poses = args
        name = "mug"  # the daemon subscribes its skill's object by name only
        return KEYS.objects(name), codec.encode_object(seq, t, poses[name])
    device, seq, t, u, b, stop = args
    return KEYS.input(device), codec.encode_input(seq, t, u, b, stop)


@pytest.mark.parametrize("skill", ["pour.yaml", "pour-vf.yaml"])
def test_the_daemon_and_lockstep_give_the_same_targets_to_the_bit(skill):
    ticks = 1600
    sk, msgs, recorded = record_stream(ROOT / "skills" / skill, ticks)
    lock, lock_counters = replay_lockstep(sk, msgs, ticks)
    assert lock == recorded  # the lockstep path is deterministic
    daemon, daemon_counters = replay_daemon(sk, msgs, ticks)
    lock_published = [(k, pose, in_seq, device, state, seed)
                      for k, pose, in_seq, device, state, _, seed in lock if pose is not None]
    assert daemon == lock_published
    moved = {tuple(p[:3]) for _, p, *_ in lock_published}
    assert sum(t[-1] for t in lock_published) >= 2  # the first target and the re-seed
    assert len(moved) > 200  # the stream really moves the target
    # the stream exercised what it is meant to: two devices, the ignored push, the stop,
    # the press, the injected jump and its re-seed
    assert {t[3] for t in lock_published} == {"user", "second"}
    c = lock_counters
    assert c.ignored_input > 0 and c.stops == 1 and c.presses >= 1
    assert c.state_discontinuity == 2 and c.reseeds >= 1  # the jump away and back
    assert daemon_counters.as_dict() == lock_counters.as_dict()


def test_a_new_device_loses_nothing_while_its_own_ring_is_declared():
    """A device's first message comes through the catch-all ring; its own ring is
    declared after that tick. What arrives in between is only in the catch-all, what
    arrives after is in both: each message is taken once, in order."""
    fake = FakeSession()
    drv = TickDriver(load_skill(ROOT / "skills" / "teleop.yaml"), RuntimeConfig())
    ingress = Ingress(fake, KEYS, drv)  # type: ignore[arg-type]
    taken = []
    offer = drv.inputs.offer
    drv.inputs.offer = lambda name, m, now: taken.append((name, m.seq)) or offer(name, m, now)

    def arrive(seq):
        fake.arrive(KEYS.input("pad"), codec.encode_input(seq, 0.0, [0, 0, 0], [0, 0, 0]))

    arrive(1)
    ingress.drain(0.0)
    arrive(2)  # before the device's ring exists
    ingress.after_tick()
    arrive(3)  # in both rings
    ingress.drain(0.001)
    arrive(4)
    ingress.drain(0.002)
    assert taken == [("pad", 1), ("pad", 2), ("pad", 3), ("pad", 4)]
    assert drv.counters.disabled_input == 4 and list(ingress.devices) == [KEYS.input("pad")]


@pytest.mark.parametrize("devices", [2, 3 * INPUT_BUDGET // 2, 40])
def test_a_flood_on_many_devices_costs_a_drain_at_most_its_budget_and_loses_nothing(devices):
    """Every device's ring full (DEVICE_DEPTH messages each): a drain decodes at most
    INPUT_BUDGET of them, a message from each ring in turn, the first ring another each
    drain; what is left is taken by the next drains, each device's in order, none twice
    or lost, and every device's first message within the drains one pass takes."""
    fake = FakeSession()
    drv = TickDriver(load_skill(ROOT / "skills" / "teleop.yaml"), RuntimeConfig())
    ingress = Ingress(fake, KEYS, drv)  # type: ignore[arg-type]
    names = [f"pad{k:02d}" for k in range(devices)]
    for name in names:  # each name learned through the catch-all, its ring declared after
        fake.arrive(KEYS.input(name), codec.encode_input(1, 0.0, [0, 0, 0], [0, 0, 0]))
        ingress.drain(0.0)
        ingress.after_tick()
    ingress.drain(0.0)  # the last ring's hand-over done: every device reads its own ring
    assert len(ingress.devices) == devices
    taken: list[tuple[str, int]] = []
    offer = drv.inputs.offer
    drv.inputs.offer = lambda name, m, now: taken.append((name, m.seq)) or offer(name, m, now)
    for name in names:
        for seq in range(2, 2 + DEVICE_DEPTH):
            fake.arrive(KEYS.input(name), codec.encode_input(seq, 0.0, [0, 0, 0], [0, 0, 0]))
    per_drain, first_seen = [], {}
    for k in range(devices * DEVICE_DEPTH):
        before = len(taken)
        ingress.drain(0.001 * (k + 1))
        per_drain.append(len(taken) - before)
        for name, _ in taken[before:]:
            first_seen.setdefault(name, k)
        if len(taken) == devices * DEVICE_DEPTH:
            break
    total = devices * DEVICE_DEPTH
    assert sorted(taken) == sorted((n, s) for n in names for s in range(2, 2 + DEVICE_DEPTH))
    for name in names:  # each device's messages in its order
        assert [s for n, s in taken if n == name] == list(range(2, 2 + DEVICE_DEPTH))
    assert max(per_drain) == min(INPUT_BUDGET, total) and len(per_drain) == -(-total // INPUT_BUDGET)
    assert max(first_seen.values()) < -(-devices // INPUT_BUDGET)
    stopped = sum(n == INPUT_BUDGET for n in per_drain)  # drains that stopped at the budget
    assert drv.counters.input_deferred == stopped and (stopped > 0) == (total > INPUT_BUDGET)
    assert drv.counters.as_dict()["input_deferred"] == stopped  # on status


@pytest.mark.parametrize("budget", range(1, DEVICE_DEPTH + 1))
def test_one_devices_ring_is_drained_by_the_same_rule_as_many(monkeypatch, budget):
    """A lone device's ring (drained without the turns the rule takes round several
    rings) gives what the rule gives it beside a second, silent device: the same
    messages, in order, and the same drains counted as stopped at the budget, for every
    budget up to the ring's depth and every number of messages in it."""
    import sctd.runtime.ingress as ingress_module

    monkeypatch.setattr(ingress_module, "INPUT_BUDGET", budget)

    def drained(names, messages):
        fake = FakeSession()
        drv = TickDriver(load_skill(ROOT / "skills" / "teleop.yaml"), RuntimeConfig())
        ingress = Ingress(fake, KEYS, drv)  # type: ignore[arg-type]
        for name in names:  # learned through the catch-all, its ring declared after the tick
            fake.arrive(KEYS.input(name), codec.encode_input(1, 0.0, [0, 0, 0], [0, 0, 0]))
            ingress.drain(0.0)
            ingress.after_tick()
        ingress.drain(0.0)
        assert len(ingress.devices) == len(names)
        taken: list[tuple[str, int]] = []
        offer = drv.inputs.offer
        drv.inputs.offer = lambda name, m, now: taken.append((name, m.seq)) or offer(name, m, now)
        for seq in range(2, 2 + messages):
            fake.arrive(KEYS.input("pad"), codec.encode_input(seq, 0.0, [0, 0, 0], [0, 0, 0]))
        per_drain = []
        for k in range(DEVICE_DEPTH + 1):  # enough drains to take every message at a budget of 1
            before = len(taken)
            ingress.drain(0.001 * (k + 1))
            per_drain.append(len(taken) - before)
        return taken, per_drain, drv.counters.input_deferred

    for messages in range(DEVICE_DEPTH + 1):
        alone = drained(["pad"], messages)
        assert alone == drained(["pad", "quiet"], messages), (budget, messages)
        assert alone[0] == [("pad", s) for s in range(2, 2 + messages)]
        assert alone[1][0] == min(messages, budget)


def test_the_tick_wakes_ahead_by_the_drains_usual_time_not_its_outliers():
    """The wake-up lead settles near the drain's 95th percentile (drains of 20-60 us and
    one in fifty of 200 us), one slow drain moves it by at most a microsecond, and it
    never leaves [0, MAX_LEAD]."""
    import random

    from sctd.runtime.loop import LEAD_STEP, MAX_LEAD, next_lead

    rng = random.Random(3)
    drains = [rng.uniform(20e-6, 60e-6) if rng.random() > 0.02 else 2e-4 for _ in range(20_000)]
    lead = 0.0
    for d in drains:
        before, lead = lead, next_lead(lead, d)
        assert abs(lead - before) <= LEAD_STEP and 0.0 <= lead <= MAX_LEAD
    p95 = sorted(drains)[int(0.95 * len(drains))]
    assert abs(lead - p95) < 5e-6
    assert next_lead(MAX_LEAD, 1.0) == MAX_LEAD and next_lead(0.0, 0.0) == 0.0
