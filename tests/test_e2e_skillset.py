"""End to end: `sctd run --set skills/sets/kitchen.yaml` as a real process on a free
loopback port. The test is the robot (a perfect follower of the targets, publishing its
state), the perception (the cabinet door's handle and the light switch; the drawer is
not seen) and an input device. Verdicts rest on what the daemon reports: its status,
targets, summaries and replies."""

from __future__ import annotations

import threading
import time

import msgpack
import pytest
import zenoh

from sctd.skill import Bundle, bundle_from_file, skill_from_bundle
from sctd.skill.skillset import load_skill_set
from sctd.wire import Keys, client, codec
from sctd.wire.session import close_session, open_session
from tests.conftest import ROOT, free_port, sctd, wait_for

pytestmark = pytest.mark.slow  # the daemon as a process

KEYS = Keys("edan")
KITCHEN = ROOT / "skills" / "sets" / "kitchen.yaml"
START = [0.35, 0.25, 0.90, 0, 0, 0, 1]
SEEN = {"door_handle": [0.60, -0.20, 0.70, 0, 0, 0, 1], "light_switch": [0.70, 0.30, 1.00, 0, 0, 0, 1]}
REST, CHOOSE = [0, 1, 0, 0], [0, 1, 0, 1]


class Room:
    """Test side: a perfect-follower robot and the seen objects (a thread), an input
    device sending zero at 100 Hz with the buttons of :attr:`buttons`, and the targets
    and status messages captured."""

    def __init__(self, port: int):
        self.endpoint = f"tcp/127.0.0.1:{port}"
        self.session = open_session(connect=[self.endpoint])
        self.lock = threading.Lock()
        self.targets: list[dict] = []
        self.status: list[dict] = []
        self.pose = list(START)
        self.buttons = list(REST)
        self.stop = threading.Event()
        s = self.session
        self.subs = [s.declare_subscriber(KEYS.target, self._on_target),
                     s.declare_subscriber(KEYS.status, self._on_status)]
        self.pubs = {"state": s.declare_publisher(KEYS.state),
                     "input": s.declare_publisher(KEYS.input("pad")),
                     **{n: s.declare_publisher(KEYS.objects(n)) for n in SEEN}}
        self.threads = [threading.Thread(target=self._robot, daemon=True),
                        threading.Thread(target=self._pad, daemon=True)]
        for t in self.threads:
            t.start()

    def _on_target(self, sample: zenoh.Sample) -> None:
        msg = codec.decode_target(sample.payload.to_bytes())
        with self.lock:
            self.targets.append(msg)
            self.pose = msg["pose"]

    def _on_status(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.status.append(msgpack.unpackb(sample.payload.to_bytes(), raw=False))

    def _robot(self) -> None:
        k = 0
        while not self.stop.is_set():
            with self.lock:
                pose = list(self.pose)
            self.pubs["state"].put(codec.encode_state(k, time.time(), pose))
            if k % 10 == 0:
                for name, T_world_obj in SEEN.items():
                    self.pubs[name].put(codec.encode_object(k, time.time(), T_world_obj))
            k += 1
            time.sleep(0.002)

    def _pad(self) -> None:
        seq = 0
        while not self.stop.is_set():
            seq += 1
            self.pubs["input"].put(codec.encode_input(seq, time.time(), [0.0, 0.0, 0.0], list(self.buttons)))
            time.sleep(0.01)

    def last_status(self) -> dict:
        with self.lock:
            return self.status[-1] if self.status else {}

    def last_target(self) -> dict:
        with self.lock:
            return self.targets[-1] if self.targets else {}

    def choose(self, engaged: str) -> dict:
        """Press choose (button 3) until ``status.goals.engaged`` is ``engaged``; a press
        the daemon did not act on (a starved test's input went stale) is pressed again.
        The newest status."""
        for _ in range(5):
            before = self.choices()
            self.buttons = list(CHOOSE)
            time.sleep(0.05)
            self.buttons = list(REST)
            if wait_for(lambda b=before: self.choices() > b, 5):
                break
        assert wait_for(lambda: self.last_status()["goals"]["engaged"] == engaged, 5), \
            self.last_status()["goals"]
        return self.last_status()

    def choices(self) -> int:
        return self.last_status()["goals"]["counters"]["choices"]

    def close(self) -> None:
        self.stop.set()
        for t in self.threads:
            t.join()
        for d in (*self.subs, *self.pubs.values()):
            d.undeclare()
        close_session(self.session)


@pytest.fixture(scope="module")
def kitchen(tmp_path_factory):
    """The kitchen set's daemon and the room around it."""
    port = free_port()
    proc = sctd("run", "--set", str(KITCHEN), "--listen", f"tcp/127.0.0.1:{port}",
                log=tmp_path_factory.mktemp("daemon") / "daemon.log")
    room = Room(port)
    try:
        assert wait_for(lambda: len(room.targets) > 50 and "goals" in room.last_status()
                        and len(room.last_status()["goals"]["belief"]) == 2, 30), (
            f"{len(room.targets)} targets, last status {room.last_status()}; daemon log: {proc.output()}")
        yield proc, room, load_skill_set(KITCHEN)
    finally:
        room.close()
        proc.stop()


def _reply(got) -> tuple[bool, dict]:
    assert got is not None, "no daemon answered"
    return got


def test_the_set_runs_teleoperation_and_reads_every_members_object(kitchen):
    _proc, room, spec = kitchen
    status = room.last_status()
    goals = status["goals"]
    assert goals["name"] == "kitchen" and goals["engaged"] == "teleop" and goals["teleop"] == "teleop"
    assert goals["objects"] == {"drawer": "drawer_handle", "cabinet-vf": "door_handle",
                                "light_switch-vf": "light_switch"}
    assert set(goals["belief"]) == {"cabinet-vf", "light_switch-vf"}  # the objects seen
    # the target's skill is the running skill's id: teleoperation's, as the status says
    assert room.last_target()["skill"] == spec.teleop.id == status["skill"]
    assert status["skill_name"] == "teleop" and room.last_target()["state"] == "translate"
    summary = client.active_skill(room.session, KEYS, timeout=10.0)
    assert summary["id"] == spec.teleop.id and summary["set"]["name"] == "kitchen"
    assert [(m["name"], m["id"], m["object"]) for m in summary["set"]["members"]] == [
        (m.name, m.skill.id, m.skill.object) for m in spec.members]
    ok, body = _reply(client.query(room.session, KEYS.skill_bundle, None, 10.0))
    assert ok and body["id"] == spec.teleop.id and Bundle.unpack(body["bundle"]).id == spec.teleop.id
    ok, body = _reply(client.query(room.session, KEYS.skill_bundle, None, 10.0, parameters="member=drawer"))
    assert ok and body["id"] == spec.members[0].skill.id and body["state"] is None
    assert Bundle.unpack(body["bundle"]).id == spec.members[0].skill.id


def test_choose_engages_a_seen_member_and_a_swap_replaces_the_member_it_names(kitchen):
    _proc, room, spec = kitchen
    cabinet, switch = spec.members[1].skill, spec.members[2].skill
    # choose: the first member whose object is fresh (the drawer is not seen)
    status = room.choose("cabinet-vf")
    assert status["skill"] == cabinet.id and status["skill_name"] == "cabinet-vf"
    assert wait_for(lambda: room.last_target().get("skill") == cabinet.id, 5), room.last_target()
    # a skill of a member's name replaces that member: the engaged one, so it runs
    b = bundle_from_file(ROOT / "skills" / "cabinet-vf.yaml")
    cabinet2 = Bundle(b.name, b.yaml_text.replace("\ndescription:", "\ndescription: Relearned.", 1), b.files)
    ok, body = client.swap(room.session, KEYS, cabinet2, timeout=30.0)
    assert ok and body["id"] == cabinet2.id and body["member"] == "cabinet-vf", body
    assert wait_for(lambda: room.last_target().get("skill") == cabinet2.id, 5), room.last_target()
    # another name: refused, unless the request names the member it replaces
    drawer_vf = bundle_from_file(ROOT / "skills" / "drawer-vf.yaml")
    start = skill_from_bundle(drawer_vf).start
    ok, body = client.swap(room.session, KEYS, drawer_vf, timeout=30.0)
    assert not ok and "name the member it replaces" in body["error"], body
    ok, body = client.swap(room.session, KEYS, drawer_vf, timeout=30.0, member="light_switch-vf")
    assert ok and body["member"] == "light_switch-vf" and body["state"] == start, body
    summary = client.active_skill(room.session, KEYS, timeout=10.0)
    assert summary["id"] == cabinet2.id and summary["set"]["engaged"] == "cabinet-vf"
    assert [m["id"] for m in summary["set"]["members"]] == [spec.members[0].skill.id, cabinet2.id,
                                                            skill_from_bundle(drawer_vf).id]
    assert switch.id not in {m["id"] for m in summary["set"]["members"]}
    assert wait_for(lambda: room.last_status()["goals"]["objects"].get("drawer-vf") == "drawer_handle", 5)
    status = room.last_status()
    assert status["counters"]["swaps_refused"] >= 1 and status["goals"]["engaged"] == "cabinet-vf"
    ok, body = _reply(client.query(room.session, KEYS.skill_bundle, None, 10.0,
                                   parameters="member=drawer-vf"))
    assert ok and body["id"] == skill_from_bundle(drawer_vf).id
    # choose again: the next member's object (the drawer handle) is not seen: teleoperation
    status = room.choose("teleop")
    assert wait_for(lambda: room.last_target().get("skill") == spec.teleop.id, 5), room.last_target()
    assert status["goals"]["counters"]["choices"] >= 2


def test_sctd_swap_names_the_member_it_replaces(kitchen, tmp_path):
    _proc, room, spec = kitchen
    members = {m["name"]: m for m in client.active_skill(room.session, KEYS, timeout=10.0)["set"]["members"]}
    target = next(n for n in ("drawer-vf", "light_switch-vf") if n in members)  # (the test above's swap)
    switch = spec.members[2].skill
    swap = sctd("swap", str(ROOT / "skills" / "light_switch-vf.yaml"), "--member", target,
                "--connect", room.endpoint, log=tmp_path / "swap.log")
    assert swap.p.wait(30) == 0, swap.output()
    assert swap.output().strip().splitlines()[-1] == switch.id
    summary = client.active_skill(room.session, KEYS, timeout=10.0)
    assert [m["id"] for m in summary["set"]["members"]][2] == switch.id
    bad = sctd("swap", "drawer", "--member", "a;b", "--connect", room.endpoint, log=tmp_path / "bad.log")
    assert bad.p.wait(30) == 2 and "--member: 'a;b': a member named in a selector" in bad.output()
