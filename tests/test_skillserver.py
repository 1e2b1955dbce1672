"""The skill queryables served by the daemon's skill server (sctd.runtime.skillserver),
on real processes: an 8 MiB bundle swaps and is answered, two at once are taken one
after the other, and the summary is the new skill's; a validator killed mid-swap is an
error reply; a skill server killed mid-swap ends the query without an ok reply, the
daemon ticks on and another skill server answers again."""

from __future__ import annotations

import json
import os
import signal
import threading
import time
from pathlib import Path

import msgpack
import pytest
import zenoh

from sctd.bench.bundles import big_bundle
from sctd.skill import Bundle, bundle_from_file, skill_from_bundle, skill_summary
from sctd.skill.loader import MAX_BUNDLE_BYTES
from sctd.wire import Keys, client, codec
from sctd.wire.session import close_session, make_config, open_session
from tests.conftest import ROOT, free_port, sctd, wait_for

POUR_VF = ROOT / "skills" / "pour-vf.yaml"

KEYS = Keys("edan")
pytestmark = pytest.mark.slow


def _children(pid: int) -> list[int]:
    """The processes ``pid`` started (Linux /proc)."""
    out: list[int] = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        try:
            out += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            pass
    return out


class Rig:
    """A daemon on a free port with no robot (it ticks and swaps all the same), a session
    connected to it and its status messages."""

    def __init__(self, tmp_path: Path):
        self.port = free_port()
        self.proc = sctd("run", "--skill", str(ROOT / "skills" / "pour.yaml"), "--listen",
                         f"tcp/127.0.0.1:{self.port}", log=tmp_path / "daemon.log")
        self.session = open_session(connect=[f"tcp/127.0.0.1:{self.port}"])
        self.status: list[dict] = []
        self._lock = threading.Lock()
        self.sub = self.session.declare_subscriber(KEYS.status, self._on_status)

    def _on_status(self, sample) -> None:
        with self._lock:
            self.status.append(codec.unpack_map(sample.payload.to_bytes()))

    def last(self) -> dict:
        with self._lock:
            return self.status[-1] if self.status else {}

    def summary(self, find: float = 30.0) -> dict | None:
        return client.active_skill(self.session, KEYS, timeout=10.0, find=find)

    def skill_server(self) -> int:
        """The skill server's pid (the daemon's one child)."""
        kids = wait_for(lambda: _children(self.proc.p.pid), 30)
        assert len(kids) == 1, kids
        return kids[0]

    def close(self) -> None:
        self.sub.undeclare()
        close_session(self.session)
        self.proc.stop()


@pytest.fixture
def rig(tmp_path):
    r = Rig(tmp_path)
    try:
        assert r.summary() is not None, r.proc.output()
        yield r
    finally:
        r.close()


def _json(x):
    return json.loads(json.dumps(x))


def test_an_8_mib_bundle_swaps_and_is_answered_one_swap_at_a_time(rig):
    bundles = [big_bundle(POUR_VF, seed) for seed in (1, 2)]
    assert all(MAX_BUNDLE_BYTES - 8192 < len(b.pack()) <= MAX_BUNDLE_BYTES for b in bundles)
    got: dict[int, list] = {}

    def swap(k: int) -> None:
        got[k] = list(rig.session.get(KEYS.skill_swap, payload=bundles[k].pack(), timeout=60.0))

    threads = [threading.Thread(target=swap, args=(k,)) for k in (0, 1)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(90)
    for k, b in enumerate(bundles):
        assert len(got[k]) == 1 and got[k][0].ok is not None, got[k]
        body = msgpack.unpackb(got[k][0].ok.payload.to_bytes(), raw=False)
        assert body == {"ok": True, "id": b.id, "name": "pour-vf", "state": skill_from_bundle(b).start}
    last = rig.summary()
    assert last is not None and last["id"] in {b.id for b in bundles}
    # the summary is exactly skill_summary of the skill that runs, plus its state
    running = next(b for b in bundles if b.id == last["id"])
    skill = skill_from_bundle(Bundle.unpack(running.pack()))
    want = {**skill_summary(skill), "state": skill.start}
    assert _json(last) == _json(want)
    assert wait_for(lambda: rig.last().get("skill") == last["id"], 5)
    counters = rig.last()["counters"]
    assert counters["swaps"] == 2 and counters["swaps_refused"] == 0


def test_a_validator_killed_mid_swap_is_an_error_reply(rig):
    server = rig.skill_server()
    validator = wait_for(lambda: _children(server), 30)
    assert len(validator) == 1
    os.kill(validator[0], signal.SIGSTOP)  # it takes the bundle and never answers...
    replies: list = []
    asker = threading.Thread(target=lambda: replies.extend(rig.session.get(
        KEYS.skill_swap, payload=bundle_from_file(ROOT / "skills" / "pour-vf.yaml").pack(), timeout=60.0)))
    asker.start()
    time.sleep(0.5)
    os.kill(validator[0], signal.SIGKILL)  # ...until it is killed mid-swap
    asker.join(90)
    assert len(replies) == 1 and replies[0].err is not None
    error = msgpack.unpackb(replies[0].err.payload.to_bytes(), raw=False)["error"]
    assert error == "<bundle>: the validating process died (exit code -9)", error
    assert wait_for(lambda: rig.last().get("counters", {}).get("swaps_refused") == 1, 5)
    # another validator takes the next bundle
    ok, body = client.swap(rig.session, KEYS, big_bundle(POUR_VF, 4), timeout=60.0)
    assert ok, body
    assert _children(server) not in ([], validator)


def test_a_skill_server_killed_mid_swap_ends_the_query_and_comes_back(rig):
    server = rig.skill_server()
    ticks0 = wait_for(lambda: rig.last().get("ticks"), 10)
    replies: list = []
    done = threading.Event()

    def ask() -> None:
        replies.extend(rig.session.get(KEYS.skill_swap, payload=big_bundle(POUR_VF, 5).pack(),
                                       timeout=20.0))
        done.set()

    t0 = time.monotonic()
    threading.Thread(target=ask, daemon=True).start()
    time.sleep(0.1)  # the bundle is on its way or being validated
    os.kill(server, signal.SIGKILL)
    assert done.wait(40), "the query never ended"
    ended = time.monotonic() - t0
    # no reply (the process holding the query died: the get ends at the latest at its
    # timeout) or an error reply; never a reply saying it swapped
    assert all(r.ok is None for r in replies) and len(replies) <= 1, (replies, ended)
    # the daemon ticks on, and another skill server serves the queryables
    assert rig.proc.p.poll() is None
    assert wait_for(lambda: rig.last().get("ticks", 0) > ticks0 + 1000, 10)
    assert wait_for(lambda: _children(rig.proc.p.pid) not in ([], [server]), 30)
    assert rig.summary() is not None
    ok, body = client.swap(rig.session, KEYS, big_bundle(POUR_VF, 6), timeout=60.0)
    assert ok, body


def test_the_active_bundle_is_read_byte_for_byte_across_swaps_and_restarts(rig):
    """``get skill/bundle`` answers the bundle the daemon runs (the id it reports), the
    file it started with, then each one swapped in; a skill server started again after
    one was killed still has it; the summary stays a summary."""
    started = bundle_from_file(ROOT / "skills" / "pour.yaml")
    got = client.active_bundle(rig.session, KEYS)
    assert not isinstance(got, str), got
    bundle, meta = got
    assert bundle.pack() == started.pack() and meta == {"v": 1, "id": started.id, "name": "pour",
                                                         "state": "carry"}
    assert "bundle" not in rig.summary()
    # the same answer on the summary's key with the selector parameter (as first shipped)
    same = client.query(rig.session, KEYS.skill, None, 10.0, parameters="bundle")
    assert same is not None and same[0] and same[1]["bundle"] == started.pack(), same
    # skill/bundle only reads: a bundle sent there is refused and swaps nothing
    vf = bundle_from_file(ROOT / "skills" / "drawer-vf.yaml")
    refused = client.query(rig.session, KEYS.skill_bundle, vf.pack(), 10.0)
    assert refused == (False, {"error": f"{KEYS.skill_bundle} is read-only: ask with no payload"}), \
        refused
    assert rig.summary()["id"] == started.id

    ok, body = client.swap(rig.session, KEYS, vf, timeout=30.0)
    assert ok, body
    bundle, meta = client.active_bundle(rig.session, KEYS)  # type: ignore[misc]
    assert bundle.pack() == vf.pack() and meta["id"] == vf.id == rig.summary()["id"]
    assert set(bundle.files) == {"drawer-vf.npz"}  # the field model comes with it

    server = rig.skill_server()
    os.kill(server, signal.SIGKILL)
    assert wait_for(lambda: _children(rig.proc.p.pid) not in ([], [server]), 30)
    assert wait_for(lambda: rig.summary(find=5.0) is not None, 30)
    again = client.active_bundle(rig.session, KEYS)
    assert not isinstance(again, str), again
    assert again[0].pack() == vf.pack()


def test_a_peer_that_listens_nowhere_reaches_the_skill_queryables_through_the_daemon_alone(rig):
    """The skill server listens on an ephemeral loopback port (the loopback defaults), so
    a peer connected to the daemon alone, listening nowhere itself, opens the link to it
    once the daemon's gossip names it: it reads the summary and swaps. (Listening nowhere
    too, the skill server was out of that peer's reach: neither side could open a link.)"""
    conf = make_config(connect=[f"tcp/127.0.0.1:{rig.port}"])
    conf.insert_json5("listen/endpoints", "[]")
    lone = zenoh.open(conf)
    try:
        summary = client.active_skill(lone, KEYS, timeout=10.0, find=30.0)
        assert summary is not None and summary["name"] == "pour", rig.proc.output()
        vf = bundle_from_file(ROOT / "skills" / "drawer-vf.yaml")
        ok, body = client.swap(lone, KEYS, vf, timeout=30.0)
        assert ok and body["id"] == vf.id, body
    finally:
        close_session(lone)
    assert rig.summary()["id"] == vf.id
