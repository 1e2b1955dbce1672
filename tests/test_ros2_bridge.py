"""``sctd ros``'s rules (sctd_services.ros2.bridge) on real ROS 2 message classes (the
``ros2`` extra's rclpy message packages), without DDS: what each ROS message becomes on
sctd's keys, what is dropped and counted, the target out at its rate with its twist, a
zero twist once on hold, diagnostics; and, through the runtime's own input arbiter, that a
Joy repeated at 20 Hz drives while one at 10 Hz times out to zero between messages."""

from __future__ import annotations

import math

import numpy as np
import pytest

# the ros2 extra (tests/tiers.py: skipped naming it where it is missing, a failure under CI)
from geometry_msgs.msg import PoseStamped
from hypothesis import given, settings
from hypothesis import strategies as st
from sensor_msgs.msg import JointState, Joy

from sctd import se3
from sctd.wire import Keys, codec
from sctd_services.input.mapping import joy_function
from sctd_services.ros2.bridge import Bridge, BridgeOptions, ros_messages

KEYS = Keys("edan")
NOW = 1_800_000_000.0


class Rig:
    """A bridge with a settable clock, recording what it puts and publishes."""

    def __init__(self, **options):
        self.now = NOW
        self.puts: list[tuple[str, bytes]] = []
        self.published: list[tuple[str, object]] = []
        fk = options.pop("fk", None)
        self.bridge = Bridge(BridgeOptions(**options), lambda k, p: self.puts.append((k, p)),
                             lambda w, m: self.published.append((w, m)), lambda: self.now, ros_messages(),
                             joy_function(None), fk)

    def on(self, key: str) -> list[bytes]:
        return [p for k, p in self.puts if k == key]

    def out(self, what: str) -> list:
        return [m for w, m in self.published if w == what]

    @property
    def dropped(self) -> dict:
        return self.bridge.counts.as_dict()["dropped"]


def stamp(header, t: float, frame: str = "world") -> None:
    header.stamp.sec = math.floor(t)
    header.stamp.nanosec = round((t - math.floor(t)) * 1e9)
    header.frame_id = frame


def pose_msg(t: float, pose, frame: str = "world") -> PoseStamped:
    m = PoseStamped()
    stamp(m.header, t, frame)
    m.pose.position.x, m.pose.position.y, m.pose.position.z = (float(v) for v in pose[:3])
    q = m.pose.orientation
    q.x, q.y, q.z, q.w = (float(v) for v in pose[3:])
    return m


def joy_msg(t: float, axes, buttons) -> Joy:
    m = Joy()
    stamp(m.header, t, "joy")
    m.axes, m.buttons = [float(a) for a in axes], [int(b) for b in buttons]
    return m


def test_the_hands_pose_becomes_the_state_stamped_by_its_header():
    rig = Rig()
    rig.bridge.on_pose(pose_msg(NOW - 0.02, [0.4, 0.1, 0.7, 0, 0, 0, 0.995]))  # norm 0.995: normalised
    (payload,) = rig.on(KEYS.state)
    state = codec.decode_state(payload)
    assert state.stamp == pytest.approx(NOW - 0.02, abs=1e-6) and state.seq == 1
    assert state.pose == pytest.approx([0.4, 0.1, 0.7, 0, 0, 0, 1.0])
    bad = {"wrong_frame": pose_msg(NOW, [0, 0, 0, 0, 0, 0, 1], frame="base_link"),
           "stale_stamp": pose_msg(NOW - 0.2, [0, 0, 0, 0, 0, 0, 1]),
           "future_stamp": pose_msg(NOW + 0.2, [0, 0, 0, 0, 0, 0, 1]),
           "zero_stamp": pose_msg(0.0, [0, 0, 0, 0, 0, 0, 1]),
           "nonfinite": pose_msg(NOW, [math.nan, 0, 0, 0, 0, 0, 1]),
           "bad_quaternion": pose_msg(NOW, [0, 0, 0, 0, 0, 0, 1.5]),
           "far": pose_msg(NOW, [5000.0, 0, 0, 0, 0, 0, 1])}
    for m in bad.values():
        rig.bridge.on_pose(m)
    assert len(rig.on(KEYS.state)) == 1  # none of them reached sctd
    assert rig.dropped == {"pose": dict.fromkeys(bad, 1)}


def test_joint_states_become_the_state_by_forward_kinematics():
    """The shipped arm's URDF: the pose is Pinocchio's forward kinematics to the
    end-effector frame, the same as the simulator's; ``q`` goes along."""
    import pinocchio as pin

    from sctd_services.ros2.kinematics import ForwardKinematics, KinematicsError
    from sctd_sim.robot import EE_FRAME, FORWARD_POSTURE, URDF_PATH, load_arm_model

    fk = ForwardKinematics(URDF_PATH, EE_FRAME)
    rig = Rig(fk=fk)
    q = [float(x) for x in FORWARD_POSTURE]
    m = JointState()
    stamp(m.header, NOW - 0.01, "")
    m.name = list(reversed(fk.joint_names))  # by name, in any order
    m.position = list(reversed(q))
    rig.bridge.on_joint_state(m)
    state = codec.decode_state(rig.on(KEYS.state)[0])
    assert state.q == pytest.approx(q)
    arm = load_arm_model()  # the simulator's own model of the arm
    data = arm.model.createData()
    pin.framesForwardKinematics(arm.model, data, np.asarray(q))
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = data.oMf[arm.ee_frame_id].rotation, data.oMf[arm.ee_frame_id].translation
    assert state.pose == pytest.approx(se3.pose_from_transform(T).tolist(), abs=1e-9)
    m.name = m.name[1:]
    m.position = m.position[1:]
    rig.bridge.on_joint_state(m)
    assert rig.dropped == {"joint_state": {"missing_joint": 1}}
    with pytest.raises(KinematicsError, match="no frame 'nowhere'"):
        ForwardKinematics(URDF_PATH, "nowhere")


def test_objects_and_joy_become_sctd_messages_and_nothing_else():
    rig = Rig(objects=("mug",))
    rig.bridge.on_object("mug", pose_msg(NOW - 0.01, [0.6, 0.1, 0.75, 0, 0, 0, 1]))
    obj = codec.decode_object(rig.on(KEYS.objects("mug"))[0])
    assert obj.pose == pytest.approx([0.6, 0.1, 0.75, 0, 0, 0, 1]) and obj.stamp == pytest.approx(NOW - 0.01)
    # the xbox map: axis 0 is u0, 1 is -u1; button 10 (right shoulder) is enable
    buttons = [0] * 11
    buttons[10] = 1
    rig.bridge.on_joy(joy_msg(NOW - 0.03, [0.5, -0.8, 0, 0, 0, 0], buttons))
    msg = codec.decode_input(rig.on(KEYS.input("ros"))[0])
    assert msg.stamp == pytest.approx(NOW - 0.03, abs=1e-6)
    assert msg.u[0] > 0 and msg.u[1] > 0 and msg.buttons == (0, 1, 0, 0, 0)  # stick y down is + on ROS
    rig.bridge.on_joy(joy_msg(NOW - 1.0, [1, 0, 0, 0, 0, 0], buttons))  # an old push
    rig.bridge.on_joy(joy_msg(NOW, [math.inf], buttons))
    assert len(rig.on(KEYS.input("ros"))) == 1
    assert rig.dropped == {"joy": {"stale_stamp": 1, "nonfinite": 1}}
    assert {k for k, _ in rig.puts} == {KEYS.objects("mug"), KEYS.input("ros")}


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["pose", "object", "joy", "joint_state"]),
                          st.floats(-2.0, 2.0),
                          st.one_of(st.floats(-1e4, 1e4), st.sampled_from([math.nan, math.inf, -math.inf]))),
                max_size=30))
def test_nothing_from_ros_is_put_on_the_target_or_undecodable(events):
    """Whatever ROS sends (any stamps, any values), the bridge puts only state, objects
    and input, and every message it puts decodes on sctd's side."""
    rig = Rig(objects=("mug",))
    for kind, dt, x in events:
        t = NOW + dt
        if kind == "pose":
            rig.bridge.on_pose(pose_msg(t, [x, 0, 0, 0, 0, 0, 1]))
        elif kind == "object":
            rig.bridge.on_object("mug", pose_msg(t, [0, x, 0, 0, 0, 0, 1]))
        elif kind == "joy":
            rig.bridge.on_joy(joy_msg(t, [x, 0, 0], [0] * 11))
        else:
            m = JointState()
            stamp(m.header, t, "")
            m.name, m.position = ["j1"], [x]
            rig.bridge.on_joint_state(m)  # no model: dropped
    for key, payload in rig.puts:
        assert key in (KEYS.state, KEYS.objects("mug"), KEYS.input("ros")), key
        {KEYS.state: codec.decode_state, KEYS.objects("mug"): codec.decode_object,
         KEYS.input("ros"): codec.decode_input}[key](payload)
    assert not rig.published


@pytest.mark.parametrize(("rate", "drives"), [(20.0, True), (8.0, False)])
def test_a_joy_at_20_hz_drives_and_a_slower_one_times_out_between_messages(rate, drives):
    """The daemon's input arbiter (input timeout 0.1 s), fed the bridge's input messages
    at their stamps, ticked at 1 kHz for 1 s of a held push: at 20 Hz (the joy
    package's autorepeat) every tick follows the push; at 8 Hz the input is stale before
    the next Joy and the command is zero in between (10 Hz is the edge: 20 Hz leaves the
    margin a real source needs)."""
    from sctd.runtime.arbiter import InputArbiter
    from sctd.runtime.controller import Counters, RuntimeConfig

    cfg = RuntimeConfig()
    rig = Rig()
    arbiter = InputArbiter(cfg.input_timeout, cfg.deadband, True, Counters())
    buttons = [0] * 11
    buttons[10] = 1
    zero = moving = 0
    sent = 0
    for k in range(1000):
        t = NOW + k * 1e-3
        rig.now = t
        if k * 1e-3 * rate >= sent:
            axes = [0.0] * 6 if sent == 0 else [0.9, 0, 0, 0, 0, 0]  # centred first: the zero-start rule
            rig.bridge.on_joy(joy_msg(t, axes, buttons))
            arbiter.offer("ros", codec.decode_input(rig.on(KEYS.input("ros"))[-1]), t)
            sent += 1
        if k * 1e-3 < 1.5 / rate:
            continue  # until the first push has arrived
        cmd = arbiter.select(t, t)
        moving += cmd.u[0] > 0
        zero += cmd.u[0] == 0
    if drives:
        assert zero == 0 and moving > 0
    else:
        assert zero > 0.1 * (zero + moving), (zero, moving)


def test_the_target_goes_out_at_its_rate_with_its_twist_and_a_zero_twist_once_on_hold():
    rig = Rig(twist=True, target_rate=100.0)
    v = np.array([0.05, -0.02, 0.01])
    w = np.array([0.0, 0.0, 0.3])  # rad/s about z
    for k in range(1000):  # 1 s of targets at 1 kHz
        t = NOW + k * 1e-3
        rig.now = t
        p = np.array([0.4, 0.0, 0.7]) + v * (k * 1e-3)
        q = se3.quaternion_from_rotvec(w * (k * 1e-3))
        rig.bridge.on_target(codec.encode_target(k, t, [*p, *q], "carry", "abc", k))
    poses, twists = rig.out("target"), rig.out("twist")
    assert 99 <= len(poses) <= 101  # 100 Hz of 1 kHz
    last = poses[-1]
    assert last.header.frame_id == "world"
    assert last.pose.position.x == pytest.approx(0.4 + v[0] * 0.999, abs=0.011 * v[0])  # the newest at 10 ms
    assert len(twists) == len(poses) - 1
    for tw in twists:
        # (stamps near 1.8e9 s are exact to 0.24 us: 2.4e-5 of a 10 ms interval)
        assert [tw.twist.linear.x, tw.twist.linear.y, tw.twist.linear.z] == pytest.approx(v, rel=1e-4)
        assert [tw.twist.angular.x, tw.twist.angular.y, tw.twist.angular.z] == pytest.approx(w, abs=1e-4)
    status = {"mode": "hold", "state": "carry", "skill": "abc", "skill_name": "pour", "counters": {}}
    rig.bridge.on_status(codec.pack(status))
    rig.bridge.on_status(codec.pack(status))
    zeros = rig.out("twist")[len(twists):]
    assert len(zeros) == 1 and zeros[0].twist.linear.x == 0.0 and zeros[0].twist.angular.z == 0.0
    (diag,) = rig.out("diagnostics")  # the second status in the same half second: none
    assert diag.status[0].level == diag.status[0].ERROR and "holding" in diag.status[0].message
    assert rig.bridge.counts.sent["twist_zero_hold"] == 1


def test_targets_that_stop_end_the_twist_with_a_zero_once():
    rig = Rig(twist=True, target_rate=100.0)
    for k in range(100):
        rig.now = NOW + k * 0.01
        pose = [0.4 + 0.001 * k, 0, 0.7, 0, 0, 0, 1]
        rig.bridge.on_target(codec.encode_target(k, rig.now, pose, "s", "a", k))
    n = len(rig.out("twist"))
    rig.now += 0.05
    rig.bridge.watch()  # within the timeout: nothing
    rig.now += 0.1
    rig.bridge.watch()
    rig.bridge.watch()
    zeros = rig.out("twist")[n:]
    assert len(zeros) == 1 and zeros[0].twist.linear.x == 0.0


def feed_targets(rig: Rig, first: int, last: int, moves_from: int, rests_from: int = 10**9) -> None:
    """Targets at 1 kHz, seq ``first`` to ``last`` - 1, the bridge's clock at each one's
    stamp; at rest until seq ``moves_from``, then moving 1 mm a millisecond in x until
    seq ``rests_from``."""
    for k in range(first, last):
        rig.now = NOW + k * 1e-3
        x = 0.4 + 1e-3 * max(0, min(k, rests_from - 1) - moves_from + 1)
        rig.bridge.on_target(codec.encode_target(k, rig.now, [x, 0, 0.7, 0, 0, 0, 1], "carry", "abc", k))


def test_a_target_that_moves_after_rest_goes_out_at_once_and_the_rate_cap_holds():
    """At rest the targets go out at 100 Hz; the first that moves goes out as it comes
    (not up to a period later, so once within a period of the last one at rest), the
    schedule restarts from it, and the stream stays capped at 100 Hz: no two targets
    out closer than a period otherwise (by their stamps), about 50 in the half second
    after."""
    rig = Rig(twist=True, target_rate=100.0)
    feed_targets(rig, 0, 705, moves_from=203)  # moves mid-period, 3 ms after a scheduled one
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 - NOW for m in rig.out("target")]
    first = [s for s in stamps if s > 0.2025]
    assert first[0] == pytest.approx(0.203, abs=1e-6)  # the first moved target, at once
    assert rig.bridge.counts.sent["target_at_once"] == 1
    gaps = np.diff(stamps)
    at_once = stamps.index(first[0]) - 1  # the gap that ends at the first moved target
    assert gaps[at_once] == pytest.approx(0.003, abs=1e-6)
    assert np.delete(gaps, at_once).min() >= 0.0095  # the cap holds around it (targets are 1 ms apart)
    assert 49 <= len(first) <= 51  # 100 Hz from the first motion on (0.203-0.704 s)
    twists = rig.out("twist")
    assert twists[-1].twist.linear.x == pytest.approx(1.0, rel=1e-3)  # 1 mm/ms


def test_a_push_at_rest_makes_the_bridge_take_each_target_until_one_moved():
    """The node takes targets at the output rate, but when the person's Joy begins a
    push while the target rests (enable held, an axis off zero) the bridge asks for each
    one (``expects_motion``) until the first that moved went out, or for the timeout."""
    rig = Rig(target_rate=100.0)
    feed_targets(rig, 0, 95, moves_from=10_000)  # at rest (the last out at 90 ms, the next due at 100)
    enable = [0] * 10 + [1]
    assert not rig.bridge.on_joy(joy_msg(rig.now, [0.0] * 6, enable))  # centred: no push
    assert not rig.bridge.on_joy(joy_msg(rig.now, [0.8, 0, 0, 0, 0, 0], [0] * 11))  # not enabled
    assert rig.bridge.on_joy(joy_msg(rig.now, [0.8, 0, 0, 0, 0, 0], enable))  # the push begins
    assert not rig.bridge.on_joy(joy_msg(rig.now, [0.8, 0, 0, 0, 0, 0], enable))  # the same push
    assert rig.bridge.expects_motion()
    n = len(rig.out("target"))
    feed_targets(rig, 95, 98, moves_from=10_000)  # still at rest, not due: nothing out
    assert len(rig.out("target")) == n and rig.bridge.expects_motion()
    feed_targets(rig, 98, 99, moves_from=98)  # it moved: out at once, and no more expected
    assert len(rig.out("target")) == n + 1 and not rig.bridge.expects_motion()
    # a push that moves nothing is expected for the timeout (0.1 s) only
    feed_targets(rig, 99, 200, moves_from=98, rests_from=99)  # moved once, then at rest again
    assert rig.bridge.on_joy(joy_msg(rig.now, [0.0] * 6, enable)) is False
    assert rig.bridge.on_joy(joy_msg(rig.now, [-0.8, 0, 0, 0, 0, 0], enable))
    assert rig.bridge.expects_motion()
    rig.now += 0.11
    assert not rig.bridge.expects_motion()


def test_diagnostics_say_the_mode_at_once_when_it_changes():
    rig = Rig()
    for mode, level in (("running", "OK"), ("stopped", "WARN"), ("fault", "ERROR")):
        rig.bridge.on_status(codec.pack({"mode": mode, "state": "carry", "skill_name": "pour"}))
        d = rig.out("diagnostics")[-1].status[0]
        assert d.level == getattr(d, level) and d.name == "sctd/edan"
        assert {kv.key for kv in d.values} >= {"mode", "skill", "state", "counters", "bridge"}
    assert len(rig.out("diagnostics")) == 3
    rig.bridge.on_status(b"\xc1")
    assert rig.dropped == {"status": {"not_msgpack": 1}}


def test_sctd_ros_refuses_bad_flags_before_it_starts(capsys, tmp_path):
    from sctd.cli.main import main

    for argv, what in ((["--joint-states-topic", "js"], "needs --urdf and --ee-frame"),
                       (["--urdf", "x.urdf"], "go with --joint-states-topic"),
                       (["--object", "mug"], "expected NAME=TOPIC"),
                       (["--object", "mug=a", "--object", "mug=b"], "--object mug: given twice"),
                       (["--target-rate", "0"], "must be > 0"),
                       (["--ros-domain", "300"], "0-232"),
                       (["--joint-states-topic", "js", "--urdf", str(tmp_path / "none.urdf"),
                         "--ee-frame", "ee"], "none.urdf")):
        assert main(["ros", *argv]) == 2, argv
        assert what in capsys.readouterr().err, argv


def test_the_twists_add_up_to_the_targets_motion_across_zeros():
    """Targets arrive stamped a little before the bridge's clock (the daemon stamped
    them earlier), and the daemon stops now and then: integrating every twist by its
    stamps from the first target ends exactly where the targets end. (A target stamped
    before a zero twist once had its motion dropped from the twists.)"""
    rig = Rig(twist=True, target_rate=100.0)
    rng = np.random.default_rng(3)
    p = np.array([0.4, 0.0, 0.7])
    first = None
    for k in range(600):
        t = NOW + k * 1e-3
        rig.now = t + 0.004  # the bridge's clock runs 4 ms ahead of the targets' stamps
        p = p + rng.normal(0.0, 1e-4, 3)
        q = se3.quaternion_from_rotvec([0.0, 0.0, 0.001 * k])
        rig.bridge.on_target(codec.encode_target(k, t, [*p, *q], "s", "a", k))
        if first is None:
            first = [*p, *q]
        if k % 97 == 50:  # the daemon stops: a zero twist, stamped by the bridge's clock
            rig.bridge.on_status(codec.pack({"mode": "stopped"}))
    T = se3.transform_from_pose(first)
    last: float | None = NOW  # the first target's stamp: the first twist ends the interval from it
    for tw in rig.out("twist"):
        t = tw.header.stamp.sec + tw.header.stamp.nanosec * 1e-9
        v = np.array([tw.twist.linear.x, tw.twist.linear.y, tw.twist.linear.z])
        w = np.array([tw.twist.angular.x, tw.twist.angular.y, tw.twist.angular.z])
        if last is not None and t > last:
            T[:3, 3] += v * (t - last)
            T[:3, :3] = se3.matrix_from_rotvec(w * (t - last)) @ T[:3, :3]
        last = t
    end = rig.out("target")[-1].pose
    assert T[:3, 3] == pytest.approx([end.position.x, end.position.y, end.position.z], abs=1e-6)
    assert rig.bridge.counts.sent["twist_zero"] >= 3


def test_the_active_state_is_drawn_for_rviz_at_the_hand():
    """With the daemon's skill set, a hand and the mug known, each status draws the
    active state as a MarkerArray (world frame): a DELETEALL first, an arrow per input
    axis from where the state's mapping frame is, the constraints' shapes, a label; at
    most every half second, and at once when the state changes."""
    from sctd.skill import load_skill
    from sctd.skill.catalog import shipped_folder
    from sctd_services.ros2.markers import marker_messages
    from sctd_services.view.skill_scene import state_scene, workspace

    skill = load_skill(shipped_folder() / "pour.yaml")
    rig = Rig(objects=("mug",))
    rig.bridge.set_skill(skill, marker_messages())
    mug = [0.6, 0.1, 0.75, 0.0, 0.0, 0.0, 1.0]
    hand = [0.55, 0.1, 0.95, 0.0, 0.0, 0.0, 1.0]
    rig.bridge.on_object("mug", pose_msg(NOW, mug))
    rig.bridge.on_pose(pose_msg(NOW, hand))
    status = {"mode": "running", "state": "carry", "skill": skill.id, "skill_name": "pour"}
    rig.bridge.on_status(codec.pack(status))
    (arr,) = rig.out("markers")
    m = arr.markers
    assert m[0].action == m[0].DELETEALL
    arrows = [k for k in m if k.ns == "axes"]
    assert len(arrows) == 3 and all(k.type == k.ARROW and k.header.frame_id == "world" for k in arrows)
    T_mug, T_hand = se3.transform_from_pose(mug), se3.transform_from_pose(hand)
    st = state_scene(skill, 0, se3.invert_transform(T_mug) @ T_hand, workspace(skill))
    start = T_mug[:3, :3] @ st.effects[0].origin + T_mug[:3, 3]  # the bottle's opening, in the world
    p = arrows[0].points[0]
    assert [p.x, p.y, p.z] == pytest.approx(start.tolist(), abs=1e-9)
    kinds = {(k.ns, k.type) for k in m}
    assert ("constraint", m[0].LINE_LIST) in kinds and ("constraint", m[0].CUBE) in kinds  # cone, band
    assert any(k.ns == "labels" and k.text == "pour: carry" for k in m)
    rig.now += 0.1
    rig.bridge.on_status(codec.pack(status))
    assert len(rig.out("markers")) == 1  # within half a second, the same state: not again
    rig.bridge.on_status(codec.pack({**status, "state": "approach"}))
    assert len(rig.out("markers")) == 2
    assert any(k.text == "pour: approach" for k in rig.out("markers")[-1].markers)
    rig.bridge.on_status(codec.pack({**status, "skill": "another"}))  # a skill not fetched yet: none
    rig.now += 1.0
    rig.bridge.on_status(codec.pack({**status, "skill": "another"}))
    assert len(rig.out("markers")) == 2
