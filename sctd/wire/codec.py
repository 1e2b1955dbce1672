"""Wire contract v1: the msgpack payloads (docs/wire-contract.md; the keys are in
:mod:`sctd.wire.keys`).

Decoders validate everything and raise :class:`DecodeError` with a short reason that
the runtime counts per reason; they never raise anything else on bad bytes.
Encoders add ``v: 1`` (the wire version) to every map they write; decoders accept maps
without it (v1 senders that predate the field) and ignore fields they do not know, so
the contract can be extended without breaking readers.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import msgpack

WIRE_VERSION = 1

# Largest payloads the runtime decodes (bytes), checked before anything is copied or
# decoded; larger ones are dropped and counted as ``<kind>_too_large``. A v1 input is
# about 60 bytes, a state with q, dq and wrench about 300.
MAX_INPUT_BYTES = 4096
MAX_STATE_BYTES = 65536
MAX_FAULT_CHARS = 500  # a state's fault text is cut to this
MAX_OBJECT_BYTES = 4096
MAX_JOINTS = 64  # longest q / dq a state may carry
MAX_POSITION = 1000.0  # m: a pose further from the world origin is not a pose of this robot
MAX_BUTTONS = 32
# Button positions in an input message's ``buttons`` (wire contract v1): 4 is grasp,
# the gripper's (the runtime turns its presses into gripper commands).
BUTTON_MODE, BUTTON_ENABLE, BUTTON_ESCAPE, BUTTON_CHOOSE, BUTTON_GRASP = 0, 1, 2, 3, 4


class DecodeError(ValueError):
    """A malformed message; ``reason`` is a short tag for the drop counters."""

    def __init__(self, reason: str, detail: str = ""):
        self.reason = reason
        super().__init__(f"{reason}: {detail}" if detail else reason)


def pack(msg: dict[str, Any]) -> bytes:
    """msgpack-encode a message map, adding the wire version."""
    msg.setdefault("v", WIRE_VERSION)
    return msgpack.packb(msg, use_bin_type=True)


def unpack_map(data: bytes, max_array_len: int = -1) -> dict[str, Any]:
    """Decode bytes to a msgpack map or raise DecodeError('not_msgpack' / 'not_map');
    ``max_array_len`` bounds every array while it is unpacked (memory): a longer one is
    DecodeError('too_long')."""
    try:
        obj = msgpack.unpackb(data, raw=False, strict_map_key=False, max_array_len=max_array_len)
    except ValueError as e:
        if "exceeds max_array_len" in str(e):
            raise DecodeError("too_long", str(e)) from None
        raise DecodeError("not_msgpack") from None
    except Exception:  # msgpack raises ExtraData, FormatError, ValueError, ...
        raise DecodeError("not_msgpack") from None
    if not isinstance(obj, dict):
        raise DecodeError("not_map")
    v = obj.get("v", WIRE_VERSION)
    if not isinstance(v, int) or v < 1:
        raise DecodeError("bad_version", repr(v))
    return obj


def _int(obj: dict, key: str) -> int:
    x = obj.get(key)
    if isinstance(x, bool) or not isinstance(x, int):
        raise DecodeError(f"bad_{key}", repr(x)[:40])
    return x


def _stamp(obj: dict) -> float:
    x = obj.get("stamp")
    if isinstance(x, bool) or not isinstance(x, int | float) or not math.isfinite(x):
        raise DecodeError("bad_stamp", repr(x)[:40])
    return float(x)


_NUMBERS = frozenset((int, float))  # not bool: type(True) is bool


def _floats(obj: dict, key: str, sizes: tuple[int, ...]) -> list[float]:
    x = obj.get(key)
    if not isinstance(x, list | tuple) or len(x) not in sizes:
        raise DecodeError(f"bad_{key}", f"expected {' or '.join(map(str, sizes))} numbers")
    if not _NUMBERS.issuperset(map(type, x)):
        raise DecodeError(f"bad_{key}", "non-numeric element")
    return list(map(float, x))


def _finite(values: list[float]) -> bool:
    """All finite: NaN and inf propagate through the sum (inf - inf is NaN)."""
    return math.isfinite(sum(values))


def _pose(obj: dict, key: str = "pose") -> list[float]:
    p = _floats(obj, key, (7,))
    if not _finite(p):
        raise DecodeError(f"nonfinite_{key}")
    # x * x, not x ** 2: a huge finite element gives inf, where ** raises OverflowError
    n = math.sqrt(p[3] * p[3] + p[4] * p[4] + p[5] * p[5] + p[6] * p[6])
    if abs(n - 1.0) > 1e-2:
        raise DecodeError(f"bad_{key}", f"quaternion norm {n:.4f}")
    if max(abs(p[0]), abs(p[1]), abs(p[2])) > MAX_POSITION:
        raise DecodeError(f"bad_{key}", f"position beyond {MAX_POSITION:g} m")
    return p


# Named tuples, not frozen dataclasses: the tick decodes about one state per period,
# and a frozen dataclass costs ~2 us to build against ~0.3 us for a named tuple.
class InputMsg(NamedTuple):
    seq: int
    stamp: float
    u: tuple[float, ...]  # may hold non-finite values: the runtime treats those as zero
    buttons: tuple[int, ...] = ()  # 0/1 by position; () when the message has none
    stop: bool = False  # the sender asks every device's motion to halt (wire contract: stop)


class StateMsg(NamedTuple):
    seq: int
    stamp: float
    pose: list[float]
    wrench: list[float] | None
    q: list[float] | None = None
    dq: list[float] | None = None
    wrench_nonfinite: bool = False  # a wrench was sent but not finite: dropped, the pose kept
    fault: str | None = None  # the arm is faulted (it follows no target): what happened
    gripper: GripperReading | None = None  # the hand's fingers, where the robot has a gripper
    gripper_invalid: bool = False  # a gripper reading was sent but malformed: dropped, the pose kept


class ObjectMsg(NamedTuple):
    seq: int
    stamp: float
    pose: list[float]


def _size(data: bytes, limit: int) -> None:
    if len(data) > limit:
        raise DecodeError("too_large", f"{len(data)} bytes > {limit}")


def _joints(obj: dict, key: str) -> list[float] | None:
    x = obj.get(key)
    if x is None:
        return None
    if not isinstance(x, list | tuple) or not 1 <= len(x) <= MAX_JOINTS:
        raise DecodeError(f"bad_{key}", f"expected 1 to {MAX_JOINTS} numbers")
    if not _NUMBERS.issuperset(map(type, x)):
        raise DecodeError(f"bad_{key}", "non-numeric element")
    if not math.isfinite(sum(x)):  # ints and floats alike
        raise DecodeError(f"nonfinite_{key}")
    return x if type(x) is list else list(x)


def decode_input(data: bytes) -> InputMsg:
    """``sctd/<robot>/input/<device>``: seq, stamp, u (3 or 6 numbers), optional buttons
    (at most MAX_BUTTONS values 0 or 1 by position: 0 mode switch, 1 enable, 2 escape,
    3 choose: a skill set's next member, 4 grasp: the gripper)
    and optional ``stop`` (0/1 or a bool; absent: 0)."""
    _size(data, MAX_INPUT_BYTES)
    obj = unpack_map(data)
    u = _floats(obj, "u", (3, 6))
    b = obj.get("buttons")
    buttons: tuple[int, ...] = ()
    if b is not None:
        if not isinstance(b, list | tuple) or len(b) > MAX_BUTTONS or not all(
                x is True or x is False or (type(x) is int and x in (0, 1)) for x in b):
            raise DecodeError("bad_buttons", f"expected at most {MAX_BUTTONS} values 0 or 1")
        buttons = tuple(int(x) for x in b)
    stop = obj.get("stop", 0)
    if not (stop is True or stop is False or (type(stop) is int and stop in (0, 1))):
        raise DecodeError("bad_stop", "expected 0 or 1")
    return InputMsg(_int(obj, "seq"), _stamp(obj), tuple(u), buttons, bool(stop))


def decode_state(data: bytes) -> StateMsg:
    """``sctd/<robot>/state``: seq, stamp, pose [7], optional q, dq (equal lengths, at
    most MAX_JOINTS, finite), wrench [6] and ``fault`` (a non-empty string while the arm
    is faulted and follows no target: what happened, at most MAX_FAULT_CHARS). A
    non-finite wrench is dropped and flagged (``wrench_nonfinite``) without costing the
    pose: force guards then see none."""
    _size(data, MAX_STATE_BYTES)
    obj = unpack_map(data)
    m = _plain_state(obj)
    return m if m is not None else _checked_state(obj)


def _plain_state(obj: dict) -> StateMsg | None:
    """The state ``obj`` (an unpacked map) when it is well-formed as every sender's is
    (an integer ``seq``, a float ``stamp``, a pose, optional ``wrench``, ``q`` and ``dq``
    lists and ``gripper`` map, all finite, no fault), else None, and
    :func:`_checked_state` then judges it field by field, so that a malformed state is
    refused for the same reason either way. The tick decodes a state each millisecond:
    these few checks cost half as much as judging each field."""
    seq, stamp, pose = obj.get("seq"), obj.get("stamp"), obj.get("pose")
    if type(seq) is not int or type(stamp) is not float or type(pose) is not list or len(pose) != 7 \
            or obj.get("fault") not in (None, ""):
        return None
    values = pose
    wrench, q, dq = obj.get("wrench"), obj.get("q"), obj.get("dq")
    if wrench is not None:
        if type(wrench) is not list or len(wrench) != 6:
            return None
        values = values + wrench
    for joints in (q, dq):
        if joints is not None:
            if type(joints) is not list or not 1 <= len(joints) <= MAX_JOINTS:
                return None
            values = values + joints
    if q is not None and dq is not None and len(q) != len(dq):
        return None
    if not _NUMBERS.issuperset(map(type, values)) or not math.isfinite(sum(values) + stamp):
        return None
    x, y, z, qx, qy, qz, qw = pose
    if abs(math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw) - 1.0) > 1e-2 \
            or max(abs(x), abs(y), abs(z)) > MAX_POSITION:
        return None
    g = obj.get("gripper")
    gripper = None
    if g is not None:
        if type(g) is not dict:
            return None
        width, cmd = g.get("width"), g.get("cmd", -1)
        grasped, moving = g.get("grasped", False), g.get("moving", False)
        if type(width) is not float or not 0.0 <= width <= MAX_GRIPPER_WIDTH or type(cmd) is not int \
                or type(grasped) is not bool or type(moving) is not bool:
            return None
        gripper = GripperReading(width, grasped, moving, cmd)
    return StateMsg(seq, stamp, list(map(float, pose)), None if wrench is None else list(map(float, wrench)),
                    q, dq, False, None, gripper, False)


def _checked_state(obj: dict) -> StateMsg:
    """:func:`decode_state` of an unpacked map, every field judged on its own."""
    wrench = None
    nonfinite = False
    if obj.get("wrench") is not None:
        wrench = _floats(obj, "wrench", (6,))
        if not _finite(wrench):
            wrench, nonfinite = None, True
    q, dq = _joints(obj, "q"), _joints(obj, "dq")
    if q is not None and dq is not None and len(q) != len(dq):
        raise DecodeError("bad_dq", f"{len(dq)} velocities for {len(q)} joints")
    try:
        gripper, gripper_invalid = _gripper_reading(obj), False
    except DecodeError:
        gripper, gripper_invalid = None, True
    return StateMsg(_int(obj, "seq"), _stamp(obj), _pose(obj), wrench, q, dq, nonfinite, _fault(obj),
                    gripper, gripper_invalid)


def _fault(obj: dict) -> str | None:
    x = obj.get("fault")
    if x is None or x == "":
        return None
    if not isinstance(x, str):
        raise DecodeError("bad_fault", f"expected a string, got {type(x).__name__}")
    return x[:MAX_FAULT_CHARS]


def decode_object(data: bytes) -> ObjectMsg:
    """``sctd/<robot>/objects/<name>``: seq, stamp, pose [7]."""
    _size(data, MAX_OBJECT_BYTES)
    obj = unpack_map(data)
    return ObjectMsg(_int(obj, "seq"), _stamp(obj), _pose(obj))


def encode_input(seq: int, stamp: float, u: list[float] | tuple[float, ...],
                 buttons: list[int] | tuple[int, ...] | None = None, stop: bool = False) -> bytes:
    """An input message; ``stop`` is written only when set (readers default it to 0)."""
    msg: dict[str, Any] = {"seq": seq, "stamp": stamp, "u": [float(x) for x in u]}
    if buttons is not None:
        msg["buttons"] = [int(bool(x)) for x in buttons]
    if stop:
        msg["stop"] = 1
    return pack(msg)


def encode_state(seq: int, stamp: float, pose: list[float], *, q: list[float] | None = None,
                 dq: list[float] | None = None, wrench: list[float] | None = None,
                 fault: str | None = None, gripper: GripperReading | None = None) -> bytes:
    """A state; ``fault`` is written only while the arm is faulted, ``gripper`` where
    the robot has one."""
    msg: dict[str, Any] = {"seq": seq, "stamp": stamp, "pose": [float(x) for x in pose]}
    if gripper is not None:
        msg["gripper"] = gripper_field(gripper)
    if fault:
        msg["fault"] = fault[:MAX_FAULT_CHARS]
    if q is not None:
        msg["q"] = [float(x) for x in q]
    if dq is not None:
        msg["dq"] = [float(x) for x in dq]
    if wrench is not None:
        msg["wrench"] = [float(x) for x in wrench]
    return pack(msg)


def encode_object(seq: int, stamp: float, pose: list[float]) -> bytes:
    return pack({"seq": seq, "stamp": stamp, "pose": [float(x) for x in pose]})


def encode_target(seq: int, stamp: float, pose: list[float], state: str, skill: str,
                  in_seq: int, in_device: str = "", seed: bool = False) -> bytes:
    """A target: ``in_seq`` and ``in_device`` name the input message the tick followed
    (the owning device's newest, else the newest of any device; -1 and "" for none);
    ``seed`` (written only when set) marks a target that is the measured pose (the first
    after the state came back or a fault cleared), not a step of the previous one."""
    msg = {"seq": seq, "stamp": stamp, "pose": pose, "state": state, "skill": skill,
           "in_seq": in_seq, "in_device": in_device}
    if seed:
        msg["seed"] = True
    return pack(msg)


def decode_target(data: bytes) -> dict[str, Any]:
    obj = unpack_map(data)
    _int(obj, "seq")
    _stamp(obj)
    _pose(obj)
    return obj


# --- the gripper (sctd/<robot>/gripper, and the state's ``gripper``) ---------------------

GRIPPER_ACTIONS = ("open", "close", "width")
MAX_GRIPPER_BYTES = 1024
MAX_GRIPPER_WIDTH = 0.5  # m: wider than any hand an assistive arm carries opens
MAX_GRIPPER_FORCE = 1000.0  # N
MAX_GRIPPER_SPEED = 1.0  # m/s


class GripperCmd(NamedTuple):
    """``sctd/<robot>/gripper``: what the gripper is to do.

    ``cmd`` numbers the commands: a robot carries each number out once, and a message
    that repeats it (the sender repeats its newest command, so that a lost message
    costs nothing) changes nothing. ``action``: ``open`` (to ``width``, else all the
    way), ``close`` (until the fingers meet something, squeezing at most ``force`` N,
    or down to ``width``), ``width`` (to ``width``, not a grasp). ``in_seq`` and
    ``in_device`` name the input message that asked for it (-1 and "" for none: a
    skill's own, at a state's entry)."""

    seq: int
    stamp: float
    cmd: int
    action: str
    width: float | None = None
    force: float | None = None
    speed: float | None = None
    skill: str = ""
    in_seq: int = -1
    in_device: str = ""


class GripperReading(NamedTuple):
    """The state's optional ``gripper``: the fingers' ``width`` (m), whether they hold
    something (``grasped``), whether they move, and ``cmd``, the newest command number
    carried out or under way (-1 for none)."""

    width: float
    grasped: bool
    moving: bool = False
    cmd: int = -1


def encode_gripper(c: GripperCmd) -> bytes:
    msg: dict[str, Any] = {"seq": c.seq, "stamp": c.stamp, "cmd": c.cmd, "action": c.action,
                           "skill": c.skill, "in_seq": c.in_seq, "in_device": c.in_device}
    for key in ("width", "force", "speed"):
        value = getattr(c, key)
        if value is not None:
            msg[key] = float(value)
    return pack(msg)


def _bounded(obj: dict, key: str, top: float, *, positive: bool = False) -> float | None:
    """An optional number in [0, top] (or (0, top] with ``positive``), else DecodeError."""
    x = obj.get(key)
    if x is None:
        return None
    if type(x) not in _NUMBERS or not math.isfinite(x) or not (0.0 < x if positive else 0.0 <= x) \
            or x > top:
        raise DecodeError(f"bad_{key}", f"expected a number in {'(0' if positive else '[0'}, {top:g}], "
                                        f"got {repr(x)[:40]}")
    return float(x)


def decode_gripper(data: bytes) -> GripperCmd:
    """``sctd/<robot>/gripper`` (:class:`GripperCmd`): every field checked, nothing
    guessed: an unknown action, a width, force or speed out of its range or a
    ``close`` without a force bound is refused."""
    _size(data, MAX_GRIPPER_BYTES)
    obj = unpack_map(data)
    action = obj.get("action")
    if action not in GRIPPER_ACTIONS:
        raise DecodeError("bad_action",
                          f"expected one of {', '.join(GRIPPER_ACTIONS)}, got {repr(action)[:40]}")
    width = _bounded(obj, "width", MAX_GRIPPER_WIDTH)
    force = _bounded(obj, "force", MAX_GRIPPER_FORCE, positive=True)
    speed = _bounded(obj, "speed", MAX_GRIPPER_SPEED, positive=True)
    if action == "width" and width is None:
        raise DecodeError("bad_width", "action width needs a width")
    if action == "close" and force is None:
        raise DecodeError("bad_force", "action close needs a force bound (N)")
    skill, device = obj.get("skill", ""), obj.get("in_device", "")
    if not isinstance(skill, str) or not isinstance(device, str):
        raise DecodeError("bad_source", "skill and in_device must be strings")
    in_seq = obj.get("in_seq", -1)
    if isinstance(in_seq, bool) or not isinstance(in_seq, int):
        raise DecodeError("bad_in_seq", repr(in_seq)[:40])
    return GripperCmd(_int(obj, "seq"), _stamp(obj), _int(obj, "cmd"), action, width, force, speed,
                      skill[:MAX_NAME], in_seq, device[:MAX_NAME])


def gripper_field(r: GripperReading) -> dict[str, Any]:
    """The state's ``gripper`` map for ``r`` (:func:`encode_state`'s ``gripper``)."""
    return {"width": float(r.width), "grasped": bool(r.grasped), "moving": bool(r.moving), "cmd": int(r.cmd)}


def _gripper_reading(obj: dict) -> GripperReading | None:
    """The state's ``gripper`` map, or None (absent); DecodeError when malformed."""
    g = obj.get("gripper")
    if g is None:
        return None
    if not isinstance(g, dict):
        raise DecodeError("bad_gripper", f"expected a map, got {type(g).__name__}")
    width = _bounded(g, "width", MAX_GRIPPER_WIDTH)
    if width is None:
        raise DecodeError("bad_gripper", "no width")
    flags = [g.get(k, False) for k in ("grasped", "moving")]
    if not all(isinstance(f, bool) for f in flags):
        raise DecodeError("bad_gripper", "grasped and moving must be true or false")
    cmd = g.get("cmd", -1)
    if isinstance(cmd, bool) or not isinstance(cmd, int):
        raise DecodeError("bad_gripper", f"cmd: expected an integer, got {repr(cmd)[:40]}")
    return GripperReading(width, flags[0], flags[1], cmd)


# --- demonstrations (sctd/<robot>/demos/<task>/<name>) ----------------------------------

DEMO_COLUMNS = ("t", "x", "y", "z", "qx", "qy", "qz", "qw")
# Optional, after the pose, both or neither: the fingers' width (m, the state's
# ``gripper.width``) and whether they hold something (0/1, its ``grasped``).
DEMO_GRIPPER_COLUMNS = ("gripper", "grasped")
MAX_DEMO_BYTES = 16 * 1024 * 1024  # a message's bytes
MAX_DEMO_ROWS = 100_000  # rows of one demonstration: over 16 minutes at 100 Hz
MIN_DEMO_ROWS = 10  # what the learner needs (sctd.learn.demos.MIN_SAMPLES)
DEMO_QUAT_TOLERANCE = 1e-3  # as the learner's CSV reader


# Optional, last, any number of bodies: each body's pose in the task object's frame
# (T_obj_body), seven columns ``<body>.x, <body>.y, ..., <body>.qw`` per body: the other
# bodies of the scene, whose frames a skill's states may be in (docs/learning.md).
DEMO_BODY_FIELDS = ("x", "y", "z", "qx", "qy", "qz", "qw")
MAX_DEMO_BODIES = 16  # bodies one demonstration may carry


class DemoMsg(NamedTuple):
    task: str
    name: str
    object: str
    rows: list[list[float]]  # t, x, y, z, qx, qy, qz, qw: the ee in the object's frame
    columns: tuple[str, ...] = DEMO_COLUMNS  # and the gripper's, and the bodies' (demo_bodies)


def demo_body_columns(body: str) -> tuple[str, ...]:
    """The seven columns of ``body``'s pose in the task object's frame."""
    return tuple(f"{body}.{c}" for c in DEMO_BODY_FIELDS)


def demo_bodies(columns: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """The bodies whose poses demonstration ``columns`` carry, in their order (each
    seven :func:`demo_body_columns` after the pose's and the gripper's)."""
    start = len(DEMO_COLUMNS)
    if tuple(columns[start:start + len(DEMO_GRIPPER_COLUMNS)]) == DEMO_GRIPPER_COLUMNS:
        start += len(DEMO_GRIPPER_COLUMNS)
    return tuple(c.rsplit(".", 1)[0] for c in columns[start::len(DEMO_BODY_FIELDS)])


def demo_columns(rows: list[list[float]], bodies: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The columns of demonstration rows: the pose's, the gripper's when the rows carry
    them (10 numbers each, before the bodies'), and seven for each of ``bodies``."""
    extra = len(DEMO_BODY_FIELDS) * len(bodies)
    with_gripper = bool(rows) and len(rows[0]) - extra == len(DEMO_COLUMNS) + len(DEMO_GRIPPER_COLUMNS)
    base = DEMO_COLUMNS + DEMO_GRIPPER_COLUMNS if with_gripper else DEMO_COLUMNS
    return base + tuple(c for b in bodies for c in demo_body_columns(b))


def format_demo_row(row: list[float], columns: tuple[str, ...] | list[str]) -> str:
    """One demonstration row as a CSV line without its newline, as the recorder writes
    it: time to the microsecond, poses (the hand's and the bodies') to 1e-9, the
    fingers' width to the micrometre and grasped 0 or 1."""
    out = [f"{row[0]:.6f}"]
    for c, x in zip(columns[1:], row[1:], strict=True):
        out.append(f"{x:.6f}" if c == "gripper" else str(int(x)) if c == "grasped" else f"{x:.9f}")
    return ",".join(out)


MAX_NAME = 64  # characters of a task, demonstration, object or skill name
_NOT_IN_NAMES = frozenset("/\\*$?#@ ")


def name_problem(x: object) -> str:
    """What is wrong with ``x`` as a name that becomes a key chunk and a file name (a
    task, a demonstration, an object, a skill): "" when nothing is. A name is 1 to
    :data:`MAX_NAME` printable characters, none of ``/ \\ * $ ? # @`` or spaces, and
    does not start with a dot (``.``, ``..`` and hidden files are not names)."""
    if not isinstance(x, str) or not x:
        return f"expected a non-empty name, got {repr(x)[:40]}"
    if len(x) > MAX_NAME:
        return f"a name of {len(x)} characters, at most {MAX_NAME}"
    if x.startswith("."):
        return f"{x[:40]!r} starts with a dot"
    bad = next((c for c in x if c in _NOT_IN_NAMES or not c.isprintable()), None)
    if bad is not None:
        return f"{x[:40]!r} has {bad!r} (not in names: / \\ * $ ? # @, spaces, control characters)"
    return ""


def _chunk(obj: dict, key: str) -> str:
    x = obj.get(key)
    problem = name_problem(x)
    if problem:
        raise DecodeError(f"bad_{key}", problem)
    assert isinstance(x, str)
    return x


def encode_demo(task: str, name: str, object_name: str, rows: list[list[float]],
                bodies: tuple[str, ...] = ()) -> bytes:
    """A finished demonstration: rows ``t, x, y, z, qx, qy, qz, qw`` (the end-effector in
    the task object's frame, ``t`` from 0, strictly increasing), each followed by
    ``gripper, grasped`` where the rows carry the fingers and by the pose of each of
    ``bodies`` in the object's frame (:func:`demo_columns`)."""
    return pack({"task": task, "name": name, "object": object_name,
                 "columns": list(demo_columns(rows, bodies)),
                 "rows": [[float(x) for x in r] for r in rows]})


def decode_demo(data: bytes) -> DemoMsg:
    """``sctd/<robot>/demos/<task>/<name>``: task, name, object, columns (exactly
    :data:`DEMO_COLUMNS`, or those and :data:`DEMO_GRIPPER_COLUMNS`) and
    :data:`MIN_DEMO_ROWS` to :data:`MAX_DEMO_ROWS` rows (bounded while unpacking) of 8
    (or 10) finite numbers,
    ``t`` strictly increasing, quaternions unit, ``gripper`` in [0, MAX_GRIPPER_WIDTH] m
    and ``grasped`` 0 or 1. A bad row is named by its index and a bad value by its column
    (``bad_rows: row 12: column grasped: ...``)."""
    _size(data, MAX_DEMO_BYTES)
    try:
        obj = unpack_map(data, max_array_len=MAX_DEMO_ROWS)
    except DecodeError as e:
        if e.reason == "too_long":
            raise DecodeError("bad_rows", f"more than {MAX_DEMO_ROWS} rows ({e})") from None
        raise
    task, name, object_name = _chunk(obj, "task"), _chunk(obj, "name"), _chunk(obj, "object")
    columns = obj.get("columns")
    problem = demo_columns_problem(columns, object_name)
    if problem:
        raise DecodeError("bad_columns", problem)
    assert isinstance(columns, list)
    rows = obj.get("rows")
    if not isinstance(rows, list) or len(rows) < MIN_DEMO_ROWS:
        raise DecodeError("bad_rows", f"expected a list of at least {MIN_DEMO_ROWS} rows")
    out = []
    last_t = -math.inf
    for k, row in enumerate(rows):
        problem = _demo_row_problem(row, last_t, columns)
        if problem:
            raise DecodeError("bad_rows", f"row {k}: {problem}")
        out.append(list(map(float, row)))
        last_t = row[0]
    return DemoMsg(task, name, object_name, out, tuple(columns))


def demo_columns_problem(columns: Any, object_name: str) -> str:
    """What is wrong with a demonstration's ``columns`` ("" when nothing is):
    :data:`DEMO_COLUMNS`, optionally :data:`DEMO_GRIPPER_COLUMNS`, then the seven
    :func:`demo_body_columns` of each of at most :data:`MAX_DEMO_BODIES` bodies (names
    as :func:`name_problem` takes them, each once, none the task object)."""
    expected = (f"expected {list(DEMO_COLUMNS)}, optionally followed by {list(DEMO_GRIPPER_COLUMNS)}, "
                f"then <body>.{', <body>.'.join(DEMO_BODY_FIELDS)} per body")
    if not isinstance(columns, list) or not all(isinstance(c, str) for c in columns) \
            or columns[:len(DEMO_COLUMNS)] != list(DEMO_COLUMNS):
        return expected
    rest = columns[len(DEMO_COLUMNS):]
    if rest[:1] == ["gripper"] or rest[:1] == ["grasped"]:
        if rest[:2] != list(DEMO_GRIPPER_COLUMNS):
            return expected
        rest = rest[2:]
    n = len(DEMO_BODY_FIELDS)
    if len(rest) % n or len(rest) > n * MAX_DEMO_BODIES:
        return f"{expected} (at most {MAX_DEMO_BODIES} bodies)"
    bodies: list[str] = []
    for i in range(0, len(rest), n):
        body = rest[i].rsplit(".", 1)[0]
        problem = name_problem(body)
        if problem or rest[i:i + n] != list(demo_body_columns(body)):
            return f"column {rest[i]!r}: {problem or expected}"
        if body == object_name:
            return f"column {rest[i]!r}: body {body!r} is the task object (its frame is the hand's)"
        if body in bodies:
            return f"column {rest[i]!r}: body {body!r} twice"
        bodies.append(body)
    return ""


def _demo_row_problem(row: Any, last_t: float, columns: list[str]) -> str:
    """What is wrong with one demonstration row of ``len(columns)`` numbers ("" when
    nothing is)."""
    width = len(columns)
    if not isinstance(row, list | tuple) or len(row) != width:
        return f"expected {width} numbers"
    if not _NUMBERS.issuperset(map(type, row)) or not _finite(list(row)):
        return "not all finite numbers"
    if row[0] <= last_t:
        return f"t {row[0]!r} not after the previous row's {last_t!r}"
    start = len(DEMO_COLUMNS)
    if width > start and columns[start] == "gripper":
        problem = demo_gripper_problem(row[8], row[9])
        if problem:
            return problem
        start += len(DEMO_GRIPPER_COLUMNS)
    for i in (1, *range(start, width, len(DEMO_BODY_FIELDS))):
        problem = _demo_pose_problem(row[i:i + 7], "" if i == 1 else columns[i].rsplit(".", 1)[0])
        if problem:
            return problem
    return ""


def _demo_pose_problem(pose: Any, body: str) -> str:
    """What is wrong with a demonstration row's pose (the hand's, ``body`` "", or a
    body's): a unit quaternion, a position within :data:`MAX_POSITION`."""
    where = f"columns {body}.qx..{body}.qw: " if body else ""
    qn = math.sqrt(sum(q * q for q in pose[3:7]))
    if abs(qn - 1.0) > DEMO_QUAT_TOLERANCE:
        return f"{where}quaternion norm {qn:.6f} is not unit (tolerance {DEMO_QUAT_TOLERANCE})"
    if max(abs(pose[0]), abs(pose[1]), abs(pose[2])) > MAX_POSITION:
        where = f"columns {body}.x..{body}.z: " if body else ""
        return f"{where}position beyond {MAX_POSITION:g} m"
    return ""


def demo_gripper_problem(width: float, grasped: float) -> str:
    """What is wrong with a demonstration row's ``gripper`` and ``grasped`` ("" when
    nothing is): the width in [0, :data:`MAX_GRIPPER_WIDTH`] m, grasped 0 or 1."""
    if not 0.0 <= width <= MAX_GRIPPER_WIDTH:
        return f"column gripper: width {width!r} m not in [0, {MAX_GRIPPER_WIDTH:g}]"
    if grasped not in (0, 1):
        return f"column grasped: {grasped!r} is not 0 or 1"
    return ""
