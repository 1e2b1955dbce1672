"""End to end, the audit's findings: with zero input nothing a message says moves the
target or the arm; oversized messages and bad bundles are counted and answered; the
simulated arm refuses targets that jump.

Real `sctd run` and `sctd sim` processes on a free loopback port; every assertion is on
what they publish (targets by seq, status and scene counters, the arm's state).
"""

from __future__ import annotations

import itertools
import math
import os
import signal
import threading
import time

import msgpack
import numpy as np
import pytest
import zenoh

from sctd.bench.bundles import malformed_bundles
from sctd.skill import bundle_from_file
from sctd.wire import Keys, codec
from sctd.wire.session import close_session, open_session
from tests.conftest import ROOT, Proc, free_port, must_centre, sctd, wait_for

pytestmark = pytest.mark.slow  # the daemon and the simulator as processes

KEYS = Keys("edan")
POUR = str(ROOT / "skills" / "pour.yaml")
POUR_VF = ROOT / "skills" / "pour-vf.yaml"
BOUND = 0.1 * 0.001 * (1 + 1e-9) + 1e-12  # the pour skill's 0.1 m/s, per 1 kHz tick


class Listener:
    """Targets (by seq), the newest status, and the newest state and scene."""

    def __init__(self, session: zenoh.Session):
        self.lock = threading.Lock()
        self.targets: dict[int, dict] = {}
        self.last: dict[str, dict] = {}
        self.states: list | None = None  # (stamp, position) of every state, once started
        self.subs = [session.declare_subscriber(KEYS.target, self._on_target),
                     session.declare_subscriber(KEYS.status, self._on("status")),
                     session.declare_subscriber(KEYS.state, self._on("state")),
                     session.declare_subscriber(KEYS.scene, self._on("scene"))]

    def _on_target(self, sample: zenoh.Sample) -> None:
        m = codec.decode_target(sample.payload.to_bytes())
        with self.lock:
            self.targets[m["seq"]] = m

    def _on(self, key: str):
        def on(sample: zenoh.Sample) -> None:
            m = msgpack.unpackb(sample.payload.to_bytes(), raw=False)
            with self.lock:
                self.last[key] = m
                if key == "state" and self.states is not None:
                    self.states.append((m["stamp"], m["pose"][:3]))
        return on

    def get(self, key: str) -> dict | None:
        with self.lock:
            return self.last.get(key)

    def newest(self) -> dict | None:
        with self.lock:
            return self.targets[max(self.targets)] if self.targets else None

    def by_seq(self) -> list[dict]:
        with self.lock:
            return [self.targets[k] for k in sorted(self.targets)]

    def close(self) -> None:
        for s in self.subs:
            s.undeclare()


def steps_above_bound(targets: list[dict]) -> list[tuple[int, float]]:
    """(seq, step) of published targets further than the per-tick bound from the one
    before them (allowing for targets not received: compared by seq)."""
    out = []
    for a, b in itertools.pairwise(targets):
        d = math.dist(a["pose"][:3], b["pose"][:3])
        if d > BOUND * (b["seq"] - a["seq"]):
            out.append((b["seq"], d))
    return out


def held_for(lis: Listener, ticks: int) -> bool:
    """Whether the newest targets span at least `ticks` seqs and all have the same pose."""
    with lis.lock:
        seqs = sorted(lis.targets)[-ticks:]
        if len(seqs) < 2 or seqs[-1] - seqs[0] < ticks - 1:
            return False
        pose = lis.targets[seqs[-1]]["pose"]
        return all(lis.targets[k]["pose"] == pose for k in seqs)


def counters(lis: Listener) -> dict:
    st = lis.get("status") or {}
    return {**st.get("counters", {}), **st.get("dropped", {})}


def test_restarted_sim_is_not_moved_by_the_runtime(tmp_path):
    """The audit's case: drive the Pinocchio arm, stop the input, kill -9 the sim and
    start it again. The runtime sees the state stream restart (seq backwards, the arm
    elsewhere), publishes nothing until the state has been continuous with zero input,
    then re-seeds at the restarted arm's pose: the new arm does not move."""
    hub = f"tcp/127.0.0.1:{free_port()}"  # the test's session: outlives the sims
    session = open_session(listen=[hub])

    def start_sim(log: str) -> Proc:
        return sctd("sim", "--task", "pour", "--connect", hub, "--listen",
                    f"tcp/127.0.0.1:{free_port()}", log=tmp_path / log)

    sim = start_sim("sim1.log")
    daemon = sctd("run", "--skill", POUR, "--connect", hub, "--listen", f"tcp/127.0.0.1:{free_port()}",
                  log=tmp_path / "daemon.log")
    lis = Listener(session)
    pub = session.declare_publisher(KEYS.input("test"))
    sim2 = None
    try:
        assert wait_for(lambda: len(lis.targets) > 100, 90), daemon.output() + sim.output()
        seq = 0
        first = lis.newest()["pose"]
        end = time.monotonic() + 60
        # drive until the published target is 0.15 m away (1.5 s at the skill's 0.1 m/s
        # on a quiet machine; longer under load)
        while math.dist(lis.newest()["pose"][:3], first[:3]) < 0.15 and time.monotonic() < end:
            seq += 1
            u = [0.0, 0.0, 0.0] if must_centre(lis.get("status"), "test") else [0.0, 1.0, 0.0]
            pub.put(codec.encode_input(seq, time.time(), u))
            time.sleep(0.005)
        # Zero input from here on, until the runtime has published the same target for 200
        # ticks running (by seq): on a loaded machine the daemon may still be finishing the
        # push when the test's zeros are sent, and "the old target" must be the held one.
        end = time.monotonic() + 60
        while not held_for(lis, 200) and time.monotonic() < end:
            seq += 1
            pub.put(codec.encode_input(seq, time.time(), [0.0, 0.0, 0.0]))
            time.sleep(0.005)
        assert held_for(lis, 200), lis.by_seq()[-3:]
        last = lis.newest()
        moved = last["pose"]
        t_killed = lis.get("scene")["t"]
        os.killpg(sim.p.pid, signal.SIGKILL)
        sim.p.wait()
        sim.stop()
        sim2 = start_sim("sim2.log")
        # the new sim's arm starts at the scene's start pose, ~0.15 m from the target
        assert wait_for(lambda: lis.get("scene")["t"] < t_killed, 90), sim2.output()
        start = list(lis.get("state")["pose"])
        assert math.dist(start[:3], moved[:3]) > 0.1
        with lis.lock:
            lis.states = []
        stop_zero = threading.Event()

        def zero_input():
            k = seq
            while not stop_zero.is_set():
                k += 1
                pub.put(codec.encode_input(k, time.time(), [0.0, 0.0, 0.0]))
                time.sleep(0.01)

        t = threading.Thread(target=zero_input, daemon=True)
        t.start()
        try:
            assert wait_for(lambda: counters(lis).get("reseeds", 0) >= 1, 20), counters(lis)
            assert wait_for(lambda: lis.get("scene")["t"] > 3.0, 30)
        finally:
            stop_zero.set()
            t.join()
        c = counters(lis)
        assert c["state_discontinuity"] >= 1
        # The new arm stayed put: it only settles under the bottle's weight (3.3 mm at the
        # impedance controller's 3000 N/m, once at start and once more when the re-seeded
        # target is its sagged pose), slowly. Before the fix it moved 5 cm at 0.74 m/s.
        with lis.lock:
            states = list(lis.states)
        far = max(math.dist(p, start[:3]) for _, p in states)
        speed = max(math.dist(p, q) / (t2 - t1) for (t1, p), (t2, q) in zip(states, states[10:], strict=False)
                    if t2 > t1)
        assert far < 0.008 and speed < 0.05, (far, speed)
        # after the re-seed, targets are at the new arm's pose, not the old one's
        newest = lis.newest()["pose"]
        assert math.dist(newest[:3], start[:3]) < 0.003
        # Until the old state went stale the runtime held the old target; the first target
        # that differs from it is the re-seed at the new arm's pose, and every later one
        # is a bounded step from the one before.
        after = [m for m in lis.by_seq() if m["seq"] > last["seq"]]
        k = next(i for i, m in enumerate(after) if m["pose"] != moved)
        assert math.dist(after[k]["pose"][:3], start[:3]) < 0.003, after[k]
        assert steps_above_bound(after[k:]) == []
    finally:
        lis.close()
        pub.undeclare()
        close_session(session)
        for p in (daemon, sim2, sim):
            if p is not None:
                p.stop()


class FakeRobot:
    """A robot that follows the target exactly (state every 2 ms) and the mug."""

    def __init__(self, session: zenoh.Session, start: list[float]):
        self.pose = list(start)
        self.lock = threading.Lock()
        self.seq = 0
        self.stop = threading.Event()
        self.pub_state = session.declare_publisher(KEYS.state)
        self.pub_obj = session.declare_publisher(KEYS.objects("mug"))
        self.sub = session.declare_subscriber(KEYS.target, self._on_target)
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _on_target(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.pose = codec.decode_target(sample.payload.to_bytes())["pose"]

    def publish(self, pose: list[float]) -> None:
        with self.lock:
            self.seq += 1
            self.pub_state.put(codec.encode_state(self.seq, time.time(), pose))

    def _run(self) -> None:
        k = 0
        while not self.stop.is_set():
            with self.lock:
                pose = list(self.pose)
            self.publish(pose)
            if k % 10 == 0:
                self.pub_obj.put(codec.encode_object(k, time.time(), [0.6, 0.0, 0.78, 0, 0, 0, 1]))
            k += 1
            time.sleep(0.002)

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        for d in (self.sub, self.pub_state, self.pub_obj):
            d.undeclare()


def daemon_rig(tmp_path, *flags: str):
    port = free_port()
    proc = sctd("run", "--skill", POUR, "--listen", f"tcp/127.0.0.1:{port}", *flags,
                log=tmp_path / "daemon.log")
    session = open_session(connect=[f"tcp/127.0.0.1:{port}"])
    lis = Listener(session)
    robot = FakeRobot(session, [0.35, 0.25, 0.90, 0, 0, 0, 1])
    return proc, session, lis, robot


def close_rig(proc: Proc, session, lis: Listener, robot: FakeRobot) -> None:
    robot.close()
    lis.close()
    close_session(session)
    proc.stop()


def test_one_far_state_with_zero_input_never_moves_the_target(tmp_path):
    """The audit's 0.955 m jump: one well-formed state 1.1 m away. Now no published target
    steps more than the per-tick bound; the runtime faults, then re-seeds where the arm
    is (the same place), and counts both."""
    proc, session, lis, robot = daemon_rig(tmp_path)
    try:
        assert wait_for(lambda: len(lis.targets) > 200, 30), proc.output()
        before = lis.newest()
        with robot.lock:
            far = [robot.pose[0] + 1.1, *robot.pose[1:]]
        # one far state; sent again only if Zenoh's rate limit on the state key (4000/s,
        # shared with the robot's own states) dropped it on arrival
        for _ in range(40):
            robot.publish(far)
            if wait_for(lambda: counters(lis).get("state_discontinuity", 0) >= 1, 0.1):
                break
        assert wait_for(lambda: counters(lis).get("reseeds", 0) >= 1, 10), counters(lis)
        assert wait_for(lambda: lis.newest()["seq"] > before["seq"] + 200, 10)
        c = counters(lis)
        assert c["state_discontinuity"] >= 2  # there and back
        got = [m for m in lis.by_seq() if m["seq"] >= before["seq"]]
        assert steps_above_bound(got) == []
        assert math.dist(got[-1]["pose"][:3], before["pose"][:3]) < 1e-6
        assert proc.p.poll() is None
    finally:
        close_rig(proc, session, lis, robot)


def test_oversized_and_malformed_state_parts_are_counted_before_decoding(tmp_path):
    proc, session, lis, robot = daemon_rig(tmp_path)
    block = zenoh.CongestionControl.BLOCK  # every message delivered, however big
    pub_in = session.declare_publisher(KEYS.input("big"), congestion_control=block)
    pub_state = session.declare_publisher(KEYS.state, congestion_control=block)
    pub_obj = session.declare_publisher(KEYS.objects("mug"), congestion_control=block)
    try:
        assert wait_for(lambda: len(lis.targets) > 200, 30), proc.output()
        before = lis.newest()
        big_u = codec.pack({"seq": 1, "stamp": time.time(), "u": [1.0] * 1_000_000})  # 9 MB
        for _ in range(5):
            pub_in.put(big_u)
            time.sleep(0.05)
        assert wait_for(lambda: counters(lis).get("input_too_large", 0) == 5, 10), counters(lis)

        def counted(pub, reason: str, **fields) -> bool:
            """Send until counted: the state key shares Zenoh's rate limit (4000/s) with
            the robot's own states, so one that comes right after a robot state is dropped
            on arrival (not decoded, not counted)."""
            for _ in range(40):
                pub.put(codec.pack({"seq": 10**6, "stamp": time.time(), **fields}))
                if wait_for(lambda: counters(lis).get(reason, 0) >= 1, 0.1):
                    return True
            return False

        pose = before["pose"]
        assert counted(pub_state, "state_too_large", pose=pose, q=[0.0] * 20000)  # 180 kB
        assert counted(pub_obj, "object_too_large", pose=[0.6, 0, 0.78, 0, 0, 0, 1], pad="x" * 8000)
        assert counted(pub_state, "state_bad_dq", pose=pose, q=[0.0] * 7, dq=[0.0] * 6)
        assert counted(pub_state, "state_nonfinite_q", pose=pose, q=[math.nan] * 7)
        after = lis.newest()
        assert after["seq"] > before["seq"] and np.allclose(after["pose"], before["pose"], atol=1e-9)
        assert lis.get("status")["skipped_ticks"] == 0 or proc.p.poll() is None
    finally:
        for d in (pub_in, pub_state, pub_obj):
            d.undeclare()
        close_rig(proc, session, lis, robot)


def test_every_bad_bundle_gets_an_error_reply_and_the_old_skill_runs_on(tmp_path):
    proc, session, lis, robot = daemon_rig(tmp_path)
    try:
        assert wait_for(lambda: len(lis.targets) > 200, 30), proc.output()
        old = lis.newest()["skill"]
        errors = {}
        for name, payload in malformed_bundles(ROOT / "skills" / "pour.yaml", POUR_VF):
            replies = list(session.get(KEYS.skill, payload=payload, timeout=30.0))
            assert len(replies) == 1 and replies[0].err is not None, (name, replies)
            errors[name] = msgpack.unpackb(replies[0].err.payload.to_bytes(), raw=False)["error"]
        assert len(errors) == 20
        assert "BadZipFile" in errors["corrupt npz"]
        assert "inflates to" in errors["npz zip bomb"]
        assert "nesting depth" in errors["deeply nested yaml"]
        assert "duplicate key 'name'" in errors["duplicate keys"]
        assert "'../x.npz'" in errors["escaping file name"]
        assert "exceeds 8388608" in errors["10 MB yaml (too big)"]
        assert "at most 10000" in errors["7 MB yaml (parsed)"]
        assert wait_for(lambda: lis.get("status")["counters"]["swaps_refused"] == len(errors), 5)
        assert lis.newest()["skill"] == old and proc.p.poll() is None
        # and a good one still swaps
        good = bundle_from_file(ROOT / "skills" / "pour-vf.yaml")
        replies = list(session.get(KEYS.skill, payload=good.pack(), timeout=30.0))
        assert replies[0].ok is not None
        assert wait_for(lambda: lis.newest()["skill"] == good.id, 5)
    finally:
        close_rig(proc, session, lis, robot)


def test_only_the_skills_objects_are_subscribed(tmp_path):
    """Poses on other object names cost the daemon nothing: it never receives them, so
    the mug's own updates keep coming and nothing is counted."""
    proc, session, lis, robot = daemon_rig(tmp_path)
    try:
        assert wait_for(lambda: len(lis.targets) > 200, 30), proc.output()
        for k in range(3000):
            session.put(KEYS.objects(f"thing{k}"), codec.encode_object(k, time.time(), [0, 0, 0, 0, 0, 0, 1]))
        flooded = time.time()
        # a status the daemon stamped 0.3 s after the flood
        assert wait_for(lambda: lis.get("status")["stamp"] > flooded + 0.3, 10)
        st = lis.get("status")
        # (the mode may be hold when this test's own robot thread is starved of CPU and its
        # state goes stale: that is the robot, not the objects)
        assert st["mode"] != "fault" and st["object_age"] < 0.5
        assert not any(k.startswith("object_") for k in st["dropped"])
    finally:
        close_rig(proc, session, lis, robot)


def test_sim_refuses_a_target_far_from_the_arm(tmp_path):
    port = free_port()
    sim = sctd("sim", "--task", "pour", "--listen", f"tcp/127.0.0.1:{port}", log=tmp_path / "sim.log")
    session = open_session(connect=[f"tcp/127.0.0.1:{port}"])
    lis = Listener(session)
    pub = session.declare_publisher(KEYS.target)
    try:
        assert wait_for(lambda: lis.get("scene") and lis.get("state"), 90), sim.output()
        p0 = list(lis.get("state")["pose"])
        far = [p0[0] + 0.2, *p0[1:]]
        old = [p0[0], p0[1], p0[2] + 0.01, *p0[3:]]
        def reasons() -> dict:
            return lis.get("scene")["target_rejected_reasons"]

        # The sim judges the newest target of each cycle, so how many of these it judges
        # is the loaded machine's; each kind is sent (every 5 ms) until the sim's scene
        # has counted 20 of it refused, or for 30 s.
        for reason, pose, age in (("offset", far, 0.0), ("before_start", old, 3600.0)):
            k, end = 0, time.monotonic() + 30
            while reasons().get(reason, 0) < 20 and time.monotonic() < end:
                k += 1
                pub.put(codec.encode_target(k, time.time() - age, pose, "x", "x", -1))
                time.sleep(0.005)
        assert wait_for(lambda: reasons().get("offset", 0) >= 20 and reasons().get("before_start", 0) >= 20,
                        30), lis.get("scene")
        assert lis.get("scene")["target_rejected"] == sum(reasons().values())
        assert np.allclose(lis.get("state")["pose"][:3], p0[:3], atol=0.002)
    finally:
        lis.close()
        pub.undeclare()
        close_session(session)
        sim.stop()
