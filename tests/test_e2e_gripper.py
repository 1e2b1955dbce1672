"""End to end, the gripper against `sctd run` (a real process on a free loopback port,
multicast scouting off): a fake robot that reports a gripper reading and carries out
each command number once, a pad that presses grasp, another device that sends a stop.
Assertions are on the gripper messages the daemon publishes and on its status, never on
the test's clock."""

from __future__ import annotations

import threading
import time

import msgpack
import pytest
import yaml
import zenoh

from sctd.wire import Keys, codec
from sctd.wire.session import close_session, open_session
from tests.conftest import free_port, sctd, wait_for

pytestmark = [pytest.mark.slow, pytest.mark.realtime]  # a hold of 0.5 s judged at a live daemon's pace

KEYS = Keys("edan")
START = [0.35, 0.25, 0.90, 0, 0, 0, 1]
HELD, GRASP, MODE = [0, 1, 0, 0, 0], [0, 1, 0, 0, 1], [1, 1, 0, 0, 0]

PICK = {
    "sctd_skill": 1, "name": "pick", "object": "world",
    "fsm": {"start": "free", "end": "grasp", "transitions": [
        {"from": "free", "to": "grasp", "type": "button", "button": 0}]},
    "states": {"free": {"input_mapping": [{"type": "linear", "axes": ["tx", "ty", "tz"]}]},
               "grasp": {"gripper": {"action": "close", "force": 12.5}}},
}


class Rig:
    """A robot that follows every target and keeps a gripper (closing on something:
    ``grasped``), a pad sending at 100 Hz, and what the daemon says."""

    def __init__(self, port: int):
        self.session = s = open_session(connect=[f"tcp/127.0.0.1:{port}"])
        self.lock = threading.Lock()
        self.pose = list(START)
        self.targets = 0
        self.gripper: list[codec.GripperCmd] = []  # every gripper message, as received
        self.carried: list[codec.GripperCmd] = []  # each command number once
        self.status: dict = {}
        self.reading = codec.GripperReading(0.08, False)
        self.buttons = list(HELD)
        self.seq = 0
        self.stop = threading.Event()
        self.decls = [s.declare_subscriber(KEYS.target, self._on_target),
                      s.declare_subscriber(KEYS.gripper, self._on_gripper),
                      s.declare_subscriber(KEYS.status, self._on_status)]
        self.pub_state = s.declare_publisher(KEYS.state)
        self.pub_pad = s.declare_publisher(KEYS.input("pad"), express=True)
        self.pub_other = s.declare_publisher(KEYS.input("other"), express=True)
        self.decls += [self.pub_state, self.pub_pad, self.pub_other]
        self.threads = [threading.Thread(target=self._robot, daemon=True),
                        threading.Thread(target=self._pad, daemon=True)]
        for t in self.threads:
            t.start()

    def _on_target(self, sample: zenoh.Sample) -> None:
        m = codec.decode_target(sample.payload.to_bytes())
        with self.lock:
            self.pose, self.targets = m["pose"], self.targets + 1

    def _on_gripper(self, sample: zenoh.Sample) -> None:
        c = codec.decode_gripper(sample.payload.to_bytes())  # a refused one would fail the test
        with self.lock:
            self.gripper.append(c)
            if not self.carried or c.cmd != self.carried[-1].cmd:  # carried out once per number
                self.carried.append(c)
                self.reading = codec.GripperReading(0.03 if c.action == "close" else 0.08,
                                                    c.action == "close", False, c.cmd)

    def _on_status(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.status = msgpack.unpackb(sample.payload.to_bytes(), raw=False)

    def _robot(self) -> None:
        k = 0
        while not self.stop.is_set():
            with self.lock:
                pose, reading = list(self.pose), self.reading
            self.pub_state.put(codec.encode_state(k, time.time(), pose, gripper=reading))
            k += 1
            time.sleep(0.002)

    def _pad(self) -> None:
        while not self.stop.is_set():
            with self.lock:
                self.seq += 1
                seq, buttons = self.seq, list(self.buttons)
            self.pub_pad.put(codec.encode_input(seq, time.time(), [0.0, 0.0, 0.0], buttons))
            time.sleep(0.01)

    def hold(self, buttons: list[int], seconds: float) -> int:
        """The pad sends ``buttons`` for ``seconds``, then HELD again (for a few messages
        at least: a release); the seq of its first message with them."""
        with self.lock:
            self.buttons = list(buttons)
            first = self.seq + 1
        time.sleep(seconds)
        with self.lock:
            self.buttons = list(HELD)
            released = self.seq + 1
        wait_for(lambda: self.seq >= released + 3, 5, 0.005)
        return first

    def commands(self) -> list[codec.GripperCmd]:
        with self.lock:
            return list(self.carried)

    def close(self) -> None:
        self.stop.set()
        for t in self.threads:
            t.join()
        for d in self.decls:
            d.undeclare()
        close_session(self.session)


@pytest.fixture
def daemon(tmp_path):
    skill = tmp_path / "pick.yaml"
    skill.write_text(yaml.safe_dump(PICK))
    port = free_port()
    proc = sctd("run", "--skill", str(skill), "--listen", f"tcp/127.0.0.1:{port}",
                log=tmp_path / "daemon.log")
    rig = Rig(port)
    try:
        assert wait_for(lambda: rig.targets > 50 and rig.status.get("gripper") is not None, 20), proc.output()
        yield proc, rig
    finally:
        rig.close()
        if proc.p.poll() is None:
            proc.stop()


def test_grasp_presses_a_hold_to_open_and_a_skills_entry_close(daemon):
    proc, rig = daemon
    assert rig.commands() == []  # nothing is sent before anybody asks
    # a press closes the empty hand with the default force (sctd/app/defaults.yaml)
    pressed = rig.hold(GRASP, 0.05)
    assert wait_for(lambda: len(rig.commands()) == 1, 10), proc.output()
    close = rig.commands()[0]
    assert (close.action, close.force, close.in_device) == ("close", 20.0, "pad")
    assert pressed <= close.in_seq <= pressed + 2  # the message that pressed (the first that arrived)
    # the fake robot closed on something: a short press opens nothing
    rig.hold(GRASP, 0.1)
    assert wait_for(lambda: rig.status["gripper"]["cancelled"] >= 1, 10), rig.status["gripper"]
    # nor does a stop from another device during a hold, nor its release
    with rig.lock:
        rig.buttons = list(GRASP)
    time.sleep(0.2)
    rig.pub_other.put(codec.encode_input(1, time.time(), [0.0, 0.0, 0.0], HELD, stop=True))
    time.sleep(0.6)
    rig.pub_other.put(codec.encode_input(2, time.time(), [0.0, 0.0, 0.0], HELD))
    rig.hold(HELD, 0.0)
    assert wait_for(lambda: rig.status["gripper"]["cancelled"] >= 2 and rig.status["counters"]["stops"] == 1,
                    10), rig.status["gripper"]
    assert [c.action for c in rig.commands()] == ["close"]
    # held long enough, it opens: the message names the press
    pressed = rig.hold(GRASP, 0.9)
    assert wait_for(lambda: len(rig.commands()) == 2, 10), rig.status
    opened = rig.commands()[1]
    assert (opened.action, opened.in_device, opened.cmd) == ("open", "pad", close.cmd + 1)
    assert pressed <= opened.in_seq <= pressed + 2
    # the repeats carry each command's number
    with rig.lock:
        repeats = [m for m in rig.gripper if m.cmd == close.cmd]
    assert len(repeats) >= 3 and all(m.action == "close" and m.in_seq == close.in_seq for m in repeats)
    assert len({m.seq for m in rig.gripper}) == len(rig.gripper)
    # the skill's own: mode enters grasp, whose entry closes (in_seq -1), once
    rig.hold(MODE, 0.05)
    assert wait_for(lambda: len(rig.commands()) == 3, 10), rig.status
    entry = rig.commands()[2]
    assert (entry.action, entry.force, entry.in_seq, entry.in_device) == ("close", 12.5, -1, "")
    assert wait_for(lambda: rig.status["state"] == "grasp" and rig.status["gripper"]["messages"] > 0, 10)
    s = rig.status
    assert entry.skill == s["skill"] and s["gripper"]["source"] == "skill"
    assert s["gripper"]["cmd"] == entry.cmd
    assert s["gripper"]["reading"]["grasped"] is True and s["gripper"]["ignored_presses"] == 0
    # the daemon's end sends nothing new: the hand keeps what it holds
    assert proc.stop() == 0
    time.sleep(0.3)
    assert [c.action for c in rig.commands()] == ["close", "open", "close"]
