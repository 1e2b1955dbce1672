"""End to end, several input devices against `sctd run` (a real process on a free
loopback port): a release sent 0.2 ms after the last push is never lost, and the first
device to push owns the motion. Assertions are on what the daemon publishes (targets
with their seq, in_seq and in_device; status counters), never on the test's clock."""

from __future__ import annotations

import itertools
import threading
import time

import msgpack
import pytest
import zenoh

from sctd.wire import Keys, codec
from sctd.wire.session import close_session, open_session
from tests.conftest import ROOT, free_port, sctd, wait_for

pytestmark = [pytest.mark.slow, pytest.mark.realtime]  # the release within 2 ticks of a live daemon

KEYS = Keys("edan")
T_WORLD_MUG = [0.6, 0.0, 0.78, 0, 0, 0, 1]
START = [0.35, 0.25, 0.90, 0, 0, 0, 1]
ENABLE = [0, 1, 0]


class Rig:
    """A robot that follows every target, two input devices, and what the daemon says."""

    def __init__(self, port: int):
        self.session = s = open_session(connect=[f"tcp/127.0.0.1:{port}"])
        self.lock = threading.Lock()
        self.targets: list[dict] = []
        self.status: dict = {}
        self.pose = list(START)
        self.stop = threading.Event()
        self.decls = [s.declare_subscriber(KEYS.target, self._on_target),
                      s.declare_subscriber(KEYS.status, self._on_status)]
        self.pub = {name: s.declare_publisher(KEYS.input(name), express=True) for name in ("A", "B")}
        self.pub_state = s.declare_publisher(KEYS.state)
        self.pub_obj = s.declare_publisher(KEYS.objects("mug"))
        self.decls += [*self.pub.values(), self.pub_state, self.pub_obj]
        self.seq = {"A": 0, "B": 0}
        self.thread = threading.Thread(target=self._robot, daemon=True)
        self.thread.start()

    def _on_target(self, sample: zenoh.Sample) -> None:
        m = codec.decode_target(sample.payload.to_bytes())
        with self.lock:
            self.targets.append(m)
            self.pose = m["pose"]

    def _on_status(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.status = msgpack.unpackb(sample.payload.to_bytes(), raw=False)

    def _robot(self) -> None:
        k = 0
        while not self.stop.is_set():
            with self.lock:
                pose = list(self.pose)
            self.pub_state.put(codec.encode_state(k, time.time(), pose))
            if k % 10 == 0:
                self.pub_obj.put(codec.encode_object(k, time.time(), T_WORLD_MUG))
            k += 1
            time.sleep(0.002)

    def send(self, device: str, u, buttons=ENABLE, stop: bool = False) -> int:
        self.seq[device] += 1
        self.pub[device].put(codec.encode_input(self.seq[device], time.time(), u, buttons, stop))
        return self.seq[device]

    def pace(self, period: float, steps: int, fn) -> None:
        """Call ``fn(k)`` every ``period`` s on absolute deadlines (sub-ms offsets inside
        ``fn`` are busy-waited)."""
        due = time.monotonic()
        for k in range(steps):
            due += period
            while time.monotonic() < due - 0.0005:
                time.sleep(0.0002)
            while time.monotonic() < due:
                pass
            fn(k)

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        for d in self.decls:
            d.undeclare()
        close_session(self.session)


def _after(t: float) -> None:
    while time.monotonic() < t:
        pass


@pytest.fixture
def rig(tmp_path):
    port = free_port()
    proc = sctd("run", "--skill", str(ROOT / "skills" / "pour.yaml"), "--listen",
                f"tcp/127.0.0.1:{port}", log=tmp_path / "daemon.log")
    r = Rig(port)
    try:
        assert wait_for(lambda: len(r.targets) > 50, 20), proc.output()
        yield r
    finally:
        r.close()
        proc.stop()


def test_a_release_right_after_the_last_push_stops_the_target(rig):
    """Pushes at 1 kHz for 0.6 s, the release 0.2 ms after the last push, then silence:
    every target from the release's seq on is the same pose."""
    releases = []
    for _ in range(3):
        last = [0.0]
        first: list[int] = []

        def push(k, last=last, first=first):
            seq = rig.send("A", [1, 0, 0])
            first[:] = first or [seq]
            last[0] = time.monotonic()

        rig.pace(0.001, 600, push)
        _after(last[0] + 0.0002)
        release = rig.send("A", [0, 0, 0])
        assert wait_for(lambda r=release: any(m["in_seq"] >= r and m["in_device"] == "A"
                                              for m in list(rig.targets)), 5)
        time.sleep(0.3)  # silence: the input goes stale meanwhile
        with rig.lock:
            after = [m for m in rig.targets if m["in_device"] == "A" and m["in_seq"] >= release]
            before = [m for m in rig.targets if m["in_device"] == "A" and first[0] <= m["in_seq"] < release]
        # each is the one before, or a re-seed at the measured pose (the robot's state went
        # stale on a loaded host and came back): nothing the input moved
        assert len(after) > 200 and all(b["pose"] == a["pose"] or b.get("seed")
                                        for a, b in itertools.pairwise(after))
        # it was moving (pour maps u0 to the mug's x); how many targets the pushes drove
        # depends on the machine's load, not on the release
        assert len(before) >= 2 and before[-1]["pose"][0] > before[0]["pose"][0]
        releases.append(release)
    assert len(releases) == 3


def test_the_first_device_to_push_owns_the_motion(rig):
    """A pushes alone for 50 ms; then B sends 0.2 ms before A every millisecond: zeros
    (A moves at full speed on every tick), then -x (ignored and counted: A still moves
    forwards), then B's stop halts the motion until A comes to rest and pushes again."""
    rig.pace(0.001, 50, lambda k: rig.send("A", [1, 0, 0]))
    first = len(rig.targets)

    def both(u_b, stop=False):
        def step(k):
            rig.send("B", u_b, stop=stop)
            _after(time.monotonic() + 0.0002)
            rig.send("A", [1, 0, 0])
        return step

    rig.pace(0.001, 300, both([0, 0, 0]))
    rig.pace(0.001, 300, both([-1, 0, 0]))
    time.sleep(0.05)
    with rig.lock:
        during = rig.targets[first:]
        ignored = rig.status.get("counters", {}).get("ignored_input", 0)
    assert {m["in_device"] for m in during} == {"A"}
    steps = [b["pose"][0] - a["pose"][0] for a, b in itertools.pairwise(during)
             if b["seq"] == a["seq"] + 1 and not b.get("seed")]
    full = 0.1 * 0.001  # pour's carry state: 0.1 m/s, u0 along the mug's x (world x)
    assert sum(abs(s - full) < 1e-9 for s in steps) >= 0.9 * len(steps)
    # B's 300 pushes are ignored and counted. On a stalled host several of B's messages
    # may share a drain and be coalesced in its ring (the newest kept), so the count can be
    # lower; the exact counting is tests/test_arbiter.py's, in process.
    assert all(s >= 0 for s in steps) and 0 < ignored <= 300
    # B's stop: A's pushes move nothing until A rests and pushes again
    rig.pace(0.001, 100, both([0, 0, 0], stop=True))
    assert wait_for(lambda: rig.status.get("counters", {}).get("stops", 0) == 1, 5)
    held_seq = rig.targets[-1]["seq"]
    rig.pace(0.001, 200, both([0, 0, 0]))
    with rig.lock:
        halted = [m for m in rig.targets if m["seq"] > held_seq]
    assert halted and all(b["pose"] == a["pose"] or b.get("seed") for a, b in itertools.pairwise(halted))
    # A centres its stick, then pushes again at 100 Hz: four pushes fill its ring, so the
    # zero is only lost (and A, never re-armed, stays still: the safe side) if the daemon
    # stalls 40 ms; at 1 kHz a 4 ms stall of a loaded host lost it (a flake, not a fault)
    owners = []

    def push(k):
        rig.send("A", [1, 0, 0])
        with rig.lock:
            owners.append(rig.status.get("input", {}).get("owner"))

    rig.pace(0.001, 20, lambda k: rig.send("A", [0, 0, 0]))
    rig.pace(0.01, 40, push)
    assert wait_for(lambda: rig.targets[-1]["pose"] != halted[-1]["pose"], 2)
    assert "A" in owners  # the daemon's status said so while A pushed
