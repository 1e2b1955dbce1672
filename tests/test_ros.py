"""ROS 2 over rmw_zenoh (docs/ros2.md): the key, hash, token and attachment formats
against known answers, the CDR payloads through rosbags' Jazzy typestore, and a real
``sctd run --ros`` daemon joined through a router-mode session (as an rmw_zenohd on
tcp/127.0.0.1:7447 would be) that publishes its target as PoseStamped and takes Joy."""

from __future__ import annotations

import json
import math
import threading
import time

import numpy as np
import pytest
import zenoh
from hypothesis import given
from hypothesis import strategies as st

from sctd.wire import codec, ros
from sctd.wire.session import close_session, open_session
from tests.conftest import ROOT, free_port, sctd, wait_for
from tests.test_e2e_runtime import KEYS, Rig

# Published RIHS01 hashes of the Jazzy interfaces (as `ros2 topic info -v` prints them,
# found in other projects' sources: docs/ros2.md).
POSE_STAMPED_HASH = "RIHS01_10f3786d7d40fd2b54367835614bff85d4ad3b5dab62bf8bca0cc232d73b4cd8"
JOY_HASH = "RIHS01_0d356c79cad3401e35ffeb75a96a96e08be3ef896b8b83841d73e890989372c5"


def test_type_names_hashes_and_data_keys_match_rmw_zenoh():
    assert ros.dds_type(ros.POSE_STAMPED) == "geometry_msgs::msg::dds_::PoseStamped_"
    assert ros.dds_type(ros.JOY) == "sensor_msgs::msg::dds_::Joy_"
    assert ros.type_hash(ros.POSE_STAMPED) == POSE_STAMPED_HASH
    assert ros.type_hash(ros.JOY) == JOY_HASH
    assert ros.data_key(0, "/sctd/target_pose", ros.POSE_STAMPED) == (
        f"0/sctd/target_pose/geometry_msgs::msg::dds_::PoseStamped_/{POSE_STAMPED_HASH}")
    assert ros.data_key(7, "/joy", ros.JOY) == f"7/joy/sensor_msgs::msg::dds_::Joy_/{JOY_HASH}"
    with pytest.raises(ros.RosError, match="pkg/msg/Name"):
        ros.dds_type("PoseStamped")


def test_liveliness_tokens_of_a_node_and_its_publisher():
    zid = "1f2e3d4c5b6a79880123456789abcdef"
    assert ros.liveliness_token(0, zid, 0, 0, ros.NODE, "/sctd", "sctd_run") == (
        f"@ros2_lv/0/{zid}/0/0/NN/%/%sctd/sctd_run")
    assert ros.liveliness_token(3, zid, 0, 1, ros.PUBLISHER, "/sctd", "sctd_run",
                                "/sctd/target_pose", ros.POSE_STAMPED) == (
        f"@ros2_lv/3/{zid}/0/1/MP/%/%sctd/sctd_run/%sctd%target_pose/"
        f"geometry_msgs::msg::dds_::PoseStamped_/{POSE_STAMPED_HASH}/::,:,:,:,,")
    with pytest.raises(ros.RosError, match="topic and a type"):
        ros.liveliness_token(0, zid, 0, 1, ros.SUBSCRIPTION, "/", "n")


def test_namespaces_are_checked_and_normalized():
    assert ros.check_namespace("sctd/") == "/sctd"
    assert ros.topic_name("/", "joy") == "/joy"
    assert ros.topic_name("/a/b", "joy") == "/a/b/joy"
    for bad in ("/1x", "/a b", "/a-b", "/ä"):
        with pytest.raises(ValueError, match="not a ROS name"):
            ros.check_namespace(bad)


def test_gid_is_xxh3_128_of_the_token_low_half_first():
    # XXH3-128 of no bytes is 0x99aa06d3014798d8_6001c324468d497f (the xxHash test vector)
    assert ros.gid("").hex() == "7f498d4624c30160" + "d8984701d306aa99"
    assert len(ros.gid("@ros2_lv/0/x/0/0/NN/%/%/n")) == 16


def test_attachment_layout_known_answer():
    a = ros.attachment(1, 2, bytes(range(16)))
    assert a.hex() == "0100000000000000" "0200000000000000" "10" + bytes(range(16)).hex()


@given(st.integers(-2**63, 2**63 - 1), st.integers(-2**63, 2**63 - 1), st.binary(min_size=16, max_size=16))
def test_attachment_round_trips(seq, stamp, g):
    assert ros.parse_attachment(ros.attachment(seq, stamp, g)) == (seq, stamp, g)


finite = st.floats(-1e3, 1e3, allow_nan=False)


@given(st.floats(0, 2**31 - 2, allow_nan=False), st.lists(finite, min_size=3, max_size=3),
       st.lists(st.floats(-1, 1, allow_nan=False), min_size=4, max_size=4))
def test_pose_stamped_decodes_with_rosbags_to_the_same_pose(stamp, xyz, q):
    pose = [*xyz, *q]
    data = ros.encode_pose_stamped(stamp, pose)
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR, little-endian (the encapsulation header)
    m = ros.STORE.deserialize_cdr(data, ros.POSE_STAMPED)
    assert m.header.frame_id == "world"
    got_stamp = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
    assert 0 <= m.header.stamp.nanosec < 10**9 and abs(got_stamp - stamp) < 1e-6
    p, o = m.pose.position, m.pose.orientation
    assert [p.x, p.y, p.z, o.x, o.y, o.z, o.w] == pose


def test_a_stamp_past_int32_seconds_is_refused():
    with pytest.raises(ros.RosError, match="int32"):
        ros.encode_pose_stamped(2.0**31, [0, 0, 0, 0, 0, 0, 1])


def test_joy_decoding_and_what_is_dropped():
    """A Joy's stamp is its header's, judged against the input timeout (0.1 s): an old
    Joy is not fresh because it arrived now."""
    now = 1000.0
    stamp, axes, buttons = ros.decode_joy(ros.encode_joy(now - 0.05, [0.5, -1.0], [0, 1, 2]), now, 0.1)
    assert stamp == pytest.approx(now - 0.05) and axes == (0.5, -1.0) and buttons == (0, 1, 1)
    good = ros.encode_joy(now, [0.5], [1])
    cases = {"bad_cdr": good[:-3], "too_large": bytes(ros.MAX_JOY_BYTES + 1),
             "nonfinite": ros.encode_joy(now, [math.nan], []),
             "too_many": ros.encode_joy(now, [0.0] * (ros.MAX_JOY_VALUES + 1), []),
             "stale_stamp": ros.encode_joy(now - 0.2, [0.5], [1]),
             "future_stamp": ros.encode_joy(now + 0.2, [0.5], [1]),
             "zero_stamp": ros.encode_joy(0.0, [0.5], [1])}
    for reason, data in cases.items():
        with pytest.raises(ros.JoyError) as e:
            ros.decode_joy(data, now, 0.1)
        assert e.value.reason == reason


def test_pose_out_is_rate_limited(monkeypatch):
    sent: list[bytes] = []
    clock = [1000.0]
    monkeypatch.setattr(ros.time, "monotonic", lambda: clock[0])

    class Fake:
        def put(self, payload: bytes) -> None:
            sent.append(payload)

    out = ros.PoseOut(Fake(), 100.0)  # type: ignore[arg-type]
    pose = [0, 0, 0, 0, 0, 0, 1]
    offered = []
    for _ in range(1000):  # 1 s of 1 kHz targets
        offered.append(out.offer(1.0, pose))
        clock[0] += 1e-3
    assert out.sent == len(sent) == sum(offered)
    assert 99 <= out.sent <= 101
    clock[0] += 10.0  # a pause: one pose, then the rate again (no burst)
    assert out.offer(1.0, pose) is True and out.offer(1.0, pose) is False
    with pytest.raises(ros.RosError, match="ros-rate"):
        ros.PoseOut(Fake(), 0.0)  # type: ignore[arg-type]


# --- a real daemon --------------------------------------------------------------------

def _session(mode: str, endpoints: str, port: int) -> zenoh.Session:
    """A loopback session in ``mode`` listening on or connecting to ``port``
    (``endpoints``: ``listen`` or ``connect``), multicast and shared memory off."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    conf.insert_json5(f"{endpoints}/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("transport/shared_memory/enabled", "false")
    return zenoh.open(conf)


def _router(port: int) -> zenoh.Session:
    """The router a ROS system runs (rmw_zenohd holds tcp/127.0.0.1:7447), on ``port``."""
    return _session("router", "listen", port)


def _client(port: int) -> zenoh.Session:
    """A client of the router, as a ROS node with rmw_zenoh is of rmw_zenohd."""
    return _session("client", "connect", port)


class RosSide:
    """The ROS side of the test: PoseStamped samples with their attachments, and a Joy
    publisher on rmw_zenoh's key with rmw_zenoh's attachment."""

    def __init__(self, session: zenoh.Session):
        self.session = session
        self.poses: list[tuple[bytes, bytes | None]] = []
        self.lock = threading.Lock()
        self.sub = session.declare_subscriber(
            ros.data_key(0, "/sctd/target_pose", ros.POSE_STAMPED), self._on_pose)
        self.joy_key = ros.data_key(0, "/sctd/joy", ros.JOY)
        self.joy_pub = session.declare_publisher(self.joy_key, encoding=ros.CDR)
        self.gid = ros.gid("@ros2_lv/0/test/0/1/MP/%/%/joy_node/%sctd%joy")
        self.seq = 0

    def _on_pose(self, sample: zenoh.Sample) -> None:
        att = sample.attachment.to_bytes() if sample.attachment is not None else None
        with self.lock:
            self.poses.append((sample.payload.to_bytes(), att))

    def joy(self, axes, buttons, raw: bytes | None = None) -> None:
        self.seq += 1
        payload = raw if raw is not None else ros.encode_joy(time.time(), axes, buttons)
        self.joy_pub.put(payload, attachment=ros.attachment(self.seq, time.time_ns(), self.gid))

    def drive(self, axes, buttons, seconds: float, rate: float = 100.0) -> None:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.joy(axes, buttons)
            time.sleep(1.0 / rate)

    def tokens(self) -> list[str]:
        return [str(r.ok.key_expr) for r in self.session.liveliness().get("@ros2_lv/0/**",
                                                                          timeout=5.0) if r.ok]

    def close(self) -> None:
        self.sub.undeclare()
        self.joy_pub.undeclare()


@pytest.fixture
def ros_daemon(tmp_path):
    port = free_port()
    router = _router(port)
    client = _client(port)
    proc = sctd("run", "--skill", str(ROOT / "skills" / "pour.yaml"), "--connect",
                f"tcp/127.0.0.1:{port}", "--rate", "1000", "--ros", "--ros-rate", "50",
                log=tmp_path / "daemon.log")
    rig = Rig(port)
    side = RosSide(client)
    try:
        assert wait_for(lambda: len(side.poses) > 10 and len(rig.targets) > 50, 30), (
            f"{len(side.poses)} ROS poses, {len(rig.targets)} targets; daemon log: {proc.output()}")
        yield proc, rig, side
    finally:
        side.close()
        rig.close()
        assert proc.stop() == 0, proc.output()
        close_session(client)
        close_session(router)


def _status_with(rig: Rig, pred, timeout: float = 20.0) -> dict:
    found = wait_for(lambda: [s for s in list(rig.status) if "ros" in s and pred(s)], timeout)
    assert found, rig.status[-1] if rig.status else "no status"
    return found[-1]


@pytest.mark.slow
def test_target_pose_is_the_target_with_rmw_zenohs_attachment_and_tokens(ros_daemon):
    _proc, rig, side = ros_daemon
    with rig.lock:
        targets = {round(m["stamp"], 6): m["pose"] for _, m in rig.targets}
    with side.lock:
        poses = list(side.poses)
    matched = 0
    seqs, gids = [], set()
    for payload, att in poses:
        stamp, frame, pose = ros.decode_pose_stamped(payload)
        assert frame == "world" and all(map(math.isfinite, pose))
        if round(stamp, 6) in targets:  # the target itself may have come before the rig joined
            assert np.allclose(pose, targets[round(stamp, 6)], rtol=0, atol=1e-12)
            matched += 1
        assert att is not None
        seq, stamp_ns, g = ros.parse_attachment(att)
        seqs.append(seq)
        gids.add(g)
        assert abs(stamp_ns * 1e-9 - stamp) < 5.0  # the send time, next to the target's stamp
    assert matched > 0  # (the rig may miss targets on a loaded machine: never a mismatch)
    assert seqs == sorted(seqs) and len(set(seqs)) == len(seqs) and seqs[0] >= 1
    tokens = side.tokens()
    node = [t for t in tokens if "/NN/" in t and t.endswith("/%/%sctd/sctd_run")]
    assert len(node) == 1, tokens
    zid = node[0].split("/")[2]
    assert node[0] == ros.liveliness_token(0, zid, 0, 0, ros.NODE, "/sctd", "sctd_run")
    pub = ros.liveliness_token(0, zid, 0, 1, ros.PUBLISHER, "/sctd", "sctd_run",
                               "/sctd/target_pose", ros.POSE_STAMPED)
    sub = ros.liveliness_token(0, zid, 0, 2, ros.SUBSCRIPTION, "/sctd", "sctd_run",
                               "/sctd/joy", ros.JOY)
    assert pub in tokens and sub in tokens, tokens
    assert gids == {ros.gid(pub)}


@pytest.mark.slow
def test_joy_moves_the_target_only_with_enable_held_and_bad_joy_is_counted(ros_daemon):
    _proc, rig, side = ros_daemon
    start = rig.last()["pose"]
    # the xbox map: axis 0 is u0, button 10 (right shoulder) is enable
    released = [0] * 11
    side.drive([0.8, 0, 0, 0, 0, 0], released, 0.5)
    _status_with(rig, lambda s: s["counters"]["disabled_input"] > 0)
    assert np.allclose(rig.last()["pose"][:3], start[:3], atol=1e-9)
    held = [0] * 10 + [1]
    # zero-start: the deadman pressed with the stick still deflected moves nothing ...
    side.drive([0.8, 0, 0, 0, 0, 0], held, 0.3)
    assert np.allclose(rig.last()["pose"][:3], start[:3], atol=1e-9)
    # ... until the stick has been centred: centred until a status says the device no
    # longer has to (a tick sees only the newest Joy, and on a busy machine the daemon's
    # ticks may miss a fixed 50 ms of zeros altogether)
    seen = len(rig.status)

    def centred() -> bool:
        side.drive([0.0, 0, 0, 0, 0, 0], held, 0.05)
        return any("input" in s and not s["input"]["rearm"] for s in list(rig.status)[seen:])

    assert wait_for(centred, 20), rig.status[-1]
    side.drive([0.8, 0, 0, 0, 0, 0], held, 1.0)
    assert wait_for(lambda: rig.last()["pose"][0] - start[0] > 0.01, 20), (rig.last(), start)
    moved = np.subtract(rig.last()["pose"][:3], start[:3])
    assert abs(moved[1]) < 1e-9 and abs(moved[2]) < 1e-9
    side.joy(None, None, raw=b"\x00\x01\x00\x00garbage")
    side.joy(None, None, raw=ros.encode_joy(time.time(), [math.nan], held))
    # an old Joy (the stick pushed 1 s ago) is stale, whenever it arrives: dropped, no motion
    time.sleep(0.3)  # the last fresh push has timed out: the target is still
    before = rig.last()["pose"]
    for _ in range(20):
        side.joy(None, None, raw=ros.encode_joy(time.time() - 1.0, [0.8, 0, 0, 0, 0, 0], held))
        time.sleep(0.01)
    s = _status_with(rig, lambda s: s["ros"]["joy_dropped"].get("bad_cdr", 0) >= 1
                     and s["ros"]["joy_dropped"].get("nonfinite", 0) >= 1
                     and s["ros"]["joy_dropped"].get("stale_stamp", 0) >= 20)
    assert np.allclose(rig.last()["pose"][:3], before[:3], atol=1e-9)
    assert s["ros"]["joy_received"] > 0 and s["ros"]["target_pose_sent"] > 0


@pytest.mark.slow
def test_sim_publishes_its_ee_pose_as_the_state_pose(tmp_path):
    port = free_port()
    sim = sctd("sim", "--task", "pour", "--listen", f"tcp/127.0.0.1:{port}", "--ros",
               "--ros-namespace", "/lab/sctd", "--ros-domain", "4", log=tmp_path / "sim.log")
    session = open_session(connect=[f"tcp/127.0.0.1:{port}"])
    states: dict[float, list[float]] = {}
    poses: list[bytes] = []
    lock = threading.Lock()

    def on_state(s: zenoh.Sample) -> None:
        m = codec.decode_state(s.payload.to_bytes())
        with lock:
            states[round(m.stamp, 6)] = m.pose

    def on_pose(s: zenoh.Sample) -> None:
        with lock:
            poses.append(s.payload.to_bytes())

    subs = [session.declare_subscriber(KEYS.state, on_state),
            session.declare_subscriber(ros.data_key(4, "/lab/sctd/ee_pose", ros.POSE_STAMPED), on_pose)]
    try:
        assert wait_for(lambda: len(poses) > 20, 90), sim.output()
        with lock:
            got = [ros.decode_pose_stamped(p) for p in poses]
            known = dict(states)
        same = [(pose, known[round(stamp, 6)]) for stamp, _, pose in got if round(stamp, 6) in known]
        assert same
        for pose, state_pose in same:
            assert np.allclose(pose, state_pose, rtol=0, atol=1e-12)
        assert {frame for _, frame, _ in got} == {"world"}
    finally:
        for sub in subs:
            sub.undeclare()
        close_session(session)
        assert sim.stop() == 0, sim.output()


@pytest.mark.parametrize(("flags", "message"), [
    (["--ros-namespace", "/1x"], "--ros-namespace"),
    (["--ros-domain", "300"], "--ros-domain"),
    (["--ros-rate", "0"], "--ros-rate"),
    (["--ros-joy-map", "/nonexistent/map.yaml"], "/nonexistent/map.yaml"),
])
@pytest.mark.slow
def test_bad_ros_flags_are_refused_naming_the_flag(tmp_path, flags, message):
    proc = sctd("run", "--skill", str(ROOT / "skills" / "pour.yaml"), "--listen",
                f"tcp/127.0.0.1:{free_port()}", "--ros", *flags, log=tmp_path / "run.log")
    assert proc.p.wait(60) == 2, proc.output()
    assert message in proc.output()
    proc.stop()
