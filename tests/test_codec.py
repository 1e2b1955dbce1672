"""Wire contract v1 decoders: round trips, and every malformed message is a DecodeError
with a reason (never another exception)."""

import math

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd.wire import codec

POSE = [0.1, -0.2, 0.3, 0.0, 0.0, 0.6, 0.8]


def test_round_trips():
    m = codec.decode_input(codec.encode_input(3, 12.5, [0.1, -1, 0.5]))
    assert (m.seq, m.stamp, m.u) == (3, 12.5, (0.1, -1.0, 0.5))
    s = codec.decode_state(codec.encode_state(4, 1.0, POSE, q=[0.0] * 7, wrench=[1, 2, 3, 0, 0, 0]))
    assert s.pose == POSE and s.wrench == [1.0, 2.0, 3.0, 0.0, 0.0, 0.0] and s.q == [0.0] * 7
    assert all(type(x) is float for x in s.pose + s.wrench)
    o = codec.decode_object(codec.encode_object(5, 2.0, POSE))
    assert (o.seq, o.pose) == (5, POSE)
    t = codec.decode_target(codec.encode_target(6, 3.0, POSE, "carry", "abc", 2))
    assert t["in_seq"] == 2 and t["v"] == codec.WIRE_VERSION


def packed(**fields):
    return msgpack.packb({"seq": 1, "stamp": 1.0, **fields}, use_bin_type=True)


def test_buttons_round_trip_and_default_to_none_pressed():
    m = codec.decode_input(codec.encode_input(1, 1.0, [0.1, 0, 0], buttons=[1, 0, True]))
    assert m.buttons == (1, 0, 1) and m.u == (0.1, 0.0, 0.0)
    assert codec.decode_input(codec.encode_input(1, 1.0, [0, 0, 0])).buttons == ()
    assert codec.decode_input(packed(u=[0, 0, 0], buttons=[False, True])).buttons == (0, 1)


@pytest.mark.parametrize("data, reason", [
    (b"\xc1", "not_msgpack"),
    (msgpack.packb([1, 2]), "not_map"),
    (packed(u=[0.1, 0.2]), "bad_u"),
    (packed(u=[0.1, True, 0.2]), "bad_u"),       # a bool is not a number
    (packed(u=[0.1, "0.2", 0.3]), "bad_u"),
    (packed(u=[0.1, None, 0.3]), "bad_u"),
    (msgpack.packb({"seq": True, "stamp": 1.0, "u": [0, 0, 0]}), "bad_seq"),
    (msgpack.packb({"seq": 1, "stamp": float("nan"), "u": [0, 0, 0]}), "bad_stamp"),
    (msgpack.packb({"v": 0, "seq": 1, "stamp": 1.0, "u": [0, 0, 0]}), "bad_version"),
    (packed(u=[0, 0, 0], buttons=[0, 2]), "bad_buttons"),
    (packed(u=[0, 0, 0], buttons=[0.0, 1]), "bad_buttons"),   # a float is not a button
    (packed(u=[0, 0, 0], buttons="01"), "bad_buttons"),
    (packed(u=[0, 0, 0], buttons=[0] * 33), "bad_buttons"),   # more than MAX_BUTTONS
])
def test_malformed_input_reasons(data, reason):
    with pytest.raises(codec.DecodeError) as e:
        codec.decode_input(data)
    assert e.value.reason == reason


@pytest.mark.parametrize("pose, reason", [
    ([0, 0, 0, 0, 0, 0, float("nan")], "nonfinite_pose"),
    ([float("inf"), 0, 0, 0, 0, 0, 1], "nonfinite_pose"),
    ([float("inf"), float("-inf"), 0, 0, 0, 0, 1], "nonfinite_pose"),
    ([0, 0, 0, 0, 0, 0, 2.0], "bad_pose"),     # quaternion norm off by more than 1 %
    ([0, 0, 0, 0, 0, 1], "bad_pose"),
    ([0, 0, 0, 0, 0, False, 1], "bad_pose"),
    ([0, 0, 0, 1e300, 0, 0, 1], "bad_pose"),  # found by fuzzing: ** 2 raised OverflowError
    ([2000.0, 0, 0, 0, 0, 0, 1], "bad_pose"),  # beyond MAX_POSITION
])
def test_malformed_pose_reasons(pose, reason):
    for decode in (codec.decode_state, codec.decode_object):
        with pytest.raises(codec.DecodeError) as e:
            decode(packed(pose=pose))
        assert e.value.reason == reason


def test_bad_wrench_costs_only_the_wrench():
    s = codec.decode_state(packed(pose=POSE, wrench=[0, 0, float("nan"), 0, 0, 0]))
    assert s.wrench is None and s.pose == POSE and s.wrench_nonfinite
    with pytest.raises(codec.DecodeError):
        codec.decode_state(packed(pose=POSE, wrench=[0, 0, "x", 0, 0, 0]))


@given(st.binary(max_size=200))
@settings(max_examples=300, deadline=None)
def test_any_bytes_decode_or_raise_decode_error(data):
    for decode in (codec.decode_input, codec.decode_state, codec.decode_object):
        try:
            m = decode(data)
        except codec.DecodeError:
            continue
        assert math.isfinite(m.stamp)


json_values = st.recursive(
    st.none() | st.booleans() | st.integers(-2**63, 2**64 - 1) | st.floats() | st.text(max_size=5),
    lambda kids: st.lists(kids, max_size=8) | st.dictionaries(st.text(max_size=5), kids, max_size=4),
    max_leaves=20)


@given(st.dictionaries(st.sampled_from(["v", "seq", "stamp", "u", "pose", "wrench", "q"]), json_values))
@settings(max_examples=300, deadline=None)
def test_any_map_decodes_to_valid_fields_or_raises_decode_error(fields):
    data = msgpack.packb(fields, use_bin_type=True)
    try:
        s = codec.decode_state(data)
    except codec.DecodeError:
        pass
    else:
        assert len(s.pose) == 7 and all(math.isfinite(x) for x in s.pose)
        assert s.wrench is None or all(math.isfinite(x) for x in s.wrench)
    try:
        m = codec.decode_input(data)
    except codec.DecodeError:
        pass
    else:
        assert len(m.u) in (3, 6) and all(type(x) is float for x in m.u)


def _state_or_reason(decode, obj):
    try:
        return decode(obj)
    except codec.DecodeError as e:
        return e.reason


# A sender's state, each field of which a test may replace with anything
GOOD_STATE = {"seq": 7, "stamp": 2.5, "pose": POSE, "q": [0.1] * 7, "dq": [0.0] * 7,
              "wrench": [1.0, 0.0, -2.0, 0.0, 0.1, 0.0],
              "gripper": {"width": 0.07, "grasped": True, "moving": False, "cmd": 3}}
_near_values = json_values | st.lists(st.floats(), min_size=6, max_size=7) | st.lists(
    st.integers(-2**63, 2**64 - 1) | st.floats(-1.0, 1.0), min_size=1, max_size=8)
_grippers = st.fixed_dictionaries({}, optional={
    "width": json_values | st.floats(-0.1, 0.6), "grasped": json_values, "moving": json_values,
    "cmd": json_values})


@given(st.dictionaries(st.sampled_from([*GOOD_STATE, "fault"]), _near_values | _grippers, max_size=4),
       st.sets(st.sampled_from(["q", "dq", "wrench", "gripper"])))
@settings(max_examples=500, deadline=None)
def test_a_state_decodes_as_judging_each_field_would_decode_it(replaced, dropped):
    """The tick's quick path for a well-formed state gives what judging each field gives,
    a state or the same reason to refuse it, whatever is replaced or left out."""
    obj = {k: v for k, v in {**GOOD_STATE, **replaced}.items() if k not in dropped}
    want = _state_or_reason(codec._checked_state, obj)
    assert _state_or_reason(lambda o: codec.decode_state(msgpack.packb(o, use_bin_type=True)), obj) == want
    quick = codec._plain_state(obj)
    assert quick is None or quick == want


@pytest.mark.parametrize("fields, reason", [
    ({"q": [0.0] * 7, "dq": [0.0] * 6}, "bad_dq"),
    ({"q": [0.0] * 65}, "bad_q"),
    ({"q": []}, "bad_q"),
    ({"q": [float("nan")] * 7}, "nonfinite_q"),
    ({"dq": ["x"] * 7}, "bad_dq"),
])
def test_joint_lists_are_checked(fields, reason):
    with pytest.raises(codec.DecodeError) as e:
        codec.decode_state(packed(pose=POSE, **fields))
    assert e.value.reason == reason


@pytest.mark.parametrize("decode, limit", [
    (codec.decode_input, codec.MAX_INPUT_BYTES), (codec.decode_state, codec.MAX_STATE_BYTES),
    (codec.decode_object, codec.MAX_OBJECT_BYTES)])
def test_payloads_over_the_size_limit_are_refused_before_decoding(decode, limit):
    with pytest.raises(codec.DecodeError) as e:
        decode(b"\xc1" * (limit + 1))  # not even msgpack: the size is checked first
    assert e.value.reason == "too_large"


def _demo_rows(n=12):
    return [[0.01 * k, 0.3 - 0.001 * k, 0.0, 0.03, 0.0, 0.0, 0.0, 1.0] for k in range(n)]


def test_demo_round_trips():
    msg = codec.decode_demo(codec.encode_demo("pour", "demo_003", "mug", _demo_rows()))
    assert (msg.task, msg.name, msg.object) == ("pour", "demo_003", "mug")
    assert msg.rows == _demo_rows()


@pytest.mark.parametrize(("mutate", "reason", "detail"), [
    (lambda d: d.update(task="a/b"), "bad_task", "not in names"),
    (lambda d: d.update(name=""), "bad_name", "non-empty name"),
    (lambda d: d.update(columns=["t", "x"]), "bad_columns", "expected"),
    (lambda d: d.update(rows=_demo_rows(9)), "bad_rows", "at least 10"),
    (lambda d: d["rows"][4].pop(), "bad_rows", "row 4: expected 8 numbers"),
    (lambda d: d["rows"][5].__setitem__(2, math.nan), "bad_rows", "row 5: not all finite"),
    (lambda d: d["rows"][6].__setitem__(0, 0.0), "bad_rows", "row 6: t 0.0 not after"),
    (lambda d: d["rows"][7].__setitem__(7, 0.9), "bad_rows", "row 7: quaternion norm 0.900000"),
    (lambda d: d["rows"][8].__setitem__(1, 1e6), "bad_rows", "row 8: position beyond"),
    (lambda d: d["rows"][3].__setitem__(3, "x"), "bad_rows", "row 3: not all finite numbers"),
])
def test_a_malformed_demo_is_refused_naming_its_row(mutate, reason, detail):
    doc = msgpack.unpackb(codec.encode_demo("pour", "d", "mug", _demo_rows()), raw=False)
    mutate(doc)
    with pytest.raises(codec.DecodeError) as e:
        codec.decode_demo(msgpack.packb(doc, use_bin_type=True))
    assert e.value.reason == reason and detail in str(e.value), str(e.value)


@given(st.binary(max_size=300))
@settings(max_examples=300)
def test_any_bytes_decode_as_a_demo_or_raise_decode_error(data):
    try:
        codec.decode_demo(data)
    except codec.DecodeError:
        pass


# --- the gripper --------------------------------------------------------------------------

gripper_cmds = st.builds(
    codec.GripperCmd, seq=st.integers(0, 2**31), stamp=st.floats(0, 2e9), cmd=st.integers(0, 2**31),
    action=st.just("close"), width=st.none() | st.floats(0, codec.MAX_GRIPPER_WIDTH),
    force=st.floats(0.1, codec.MAX_GRIPPER_FORCE),
    speed=st.none() | st.floats(0.001, codec.MAX_GRIPPER_SPEED),
    skill=st.text("abc-@0", max_size=20), in_seq=st.integers(-1, 2**31), in_device=st.text("xyz", max_size=8))


@given(gripper_cmds, st.sampled_from(codec.GRIPPER_ACTIONS))
def test_a_gripper_command_round_trips(c, action):
    c = c._replace(action=action, width=c.width if action != "width" or c.width is not None else 0.04)
    assert codec.decode_gripper(codec.encode_gripper(c)) == c


@pytest.mark.parametrize("fields, reason", [
    ({"action": "squeeze", "force": 10.0}, "bad_action"),
    ({"action": "close"}, "bad_force"),  # a grasp has a force bound, always
    ({"action": "close", "force": 0.0}, "bad_force"),
    ({"action": "close", "force": float("nan")}, "bad_force"),
    ({"action": "close", "force": 5000.0}, "bad_force"),
    ({"action": "width"}, "bad_width"),
    ({"action": "width", "width": -0.01}, "bad_width"),
    ({"action": "open", "width": 2.0}, "bad_width"),
    ({"action": "open", "speed": True}, "bad_speed"),
    ({"action": "open", "cmd": "1"}, "bad_cmd"),
    ({"action": "open", "in_seq": 1.5}, "bad_in_seq"),
    ({"action": "open", "skill": 3}, "bad_source"),
])
def test_a_bad_gripper_command_is_refused_naming_the_field(fields, reason):
    msg = {"seq": 1, "stamp": 1.0, "cmd": 1, **fields}
    with pytest.raises(codec.DecodeError) as e:
        codec.decode_gripper(msgpack.packb(msg, use_bin_type=True))
    assert e.value.reason == reason


def test_a_states_gripper_reading_round_trips_and_a_bad_one_costs_only_itself():
    r = codec.GripperReading(0.021, True, False, 7)
    s = codec.decode_state(codec.encode_state(3, 1.0, POSE, gripper=r))
    assert s.gripper == r and not s.gripper_invalid
    assert codec.decode_state(codec.encode_state(3, 1.0, POSE)).gripper is None
    for bad in ({"width": -1.0}, {"grasped": True}, {"width": 0.02, "grasped": 1}, [0.02],
                {"width": 0.02, "cmd": 1.0}):
        s = codec.decode_state(packed(pose=POSE, gripper=bad))
        assert s.gripper is None and s.gripper_invalid and s.pose == POSE


@given(st.dictionaries(st.sampled_from(["v", "seq", "stamp", "cmd", "action", "width", "force", "speed",
                                        "skill", "in_seq", "in_device"]), json_values))
@settings(max_examples=300, deadline=None)
def test_any_map_is_a_valid_gripper_command_or_a_decode_error(fields):
    try:
        c = codec.decode_gripper(msgpack.packb(fields, use_bin_type=True))
    except codec.DecodeError:
        return
    assert c.action in codec.GRIPPER_ACTIONS and math.isfinite(c.stamp)
    for value, top in ((c.width, codec.MAX_GRIPPER_WIDTH), (c.force, codec.MAX_GRIPPER_FORCE),
                       (c.speed, codec.MAX_GRIPPER_SPEED)):
        assert value is None or 0.0 <= value <= top
    assert c.action != "close" or c.force is not None
