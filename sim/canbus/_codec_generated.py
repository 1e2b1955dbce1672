"""The joint bus's fast frame codec, generated from ``edan_joints.dbc``: do not edit.

Regenerate with ``python -m sctd_sim.canbus.codegen`` (see :mod:`.codegen`, which also
explains the code); :mod:`.codec` looks the functions up in :data:`LAYOUTS` and
:data:`GROUPS`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from struct import Struct
from struct import error as _StructError
from typing import Any, cast

import can

from .crc import word_tables
from .layout import LayoutKey

Encode = Callable[..., bytearray]
MakeFrame = Callable[..., can.Message]
Decode = Callable[[bytes | bytearray], tuple[bool, int, tuple[float, ...]]]
Unpacked = tuple[tuple[Any, ...], ...] | None  # per signal: float, or int for bit fields
Frames = Callable[..., list[can.Message]]
Unpack = Callable[[Sequence[can.Message], int], Unpacked]
GroupCode = tuple[Frames, dict[tuple[str, ...], Unpack]]

T1, T23, T45, T67 = word_tables()
_STRUCT = Struct("<BBHHH")
_pack = _STRUCT.pack
_unpack = _STRUCT.unpack
_new = cast(Callable[[type[can.Message]], can.Message], object.__new__)
_Message = can.Message

SYNC_LAYOUT: LayoutKey = (
    ('Flags', 12, 4, False, 1.0, 0.0),
    ('Cycle', 16, 32, False, 1.0, 0.0),
    ('Period', 48, 16, False, 1e-06, 0.0),
)

JOINT_CMD_LAYOUT: LayoutKey = (
    ('Mode', 12, 4, False, 1.0, 0.0),
    ('Torque', 16, 16, True, 0.01, 0.0),
    ('Position', 32, 16, True, 0.0001, 0.0),
    ('Velocity', 48, 16, True, 0.0002, 0.0),
)

JOINT_STATE_LAYOUT: LayoutKey = (
    ('Status', 12, 4, False, 1.0, 0.0),
    ('Position', 16, 20, True, 1e-05, 0.0),
    ('Velocity', 36, 16, True, 0.0002, 0.0),
    ('Torque', 52, 12, True, 0.1, 0.0),
)


def sync_make(K: int, FID: int) -> tuple[Encode, MakeFrame, Decode]:
    """Encode, frame and decode of one frame of the ``sync`` layout: CRC constant
    ``K``, id ``FID`` (see :class:`~.codec.FrameCodec`)."""

    def encode(counter: int, x0: float, x1: float, x2: float) -> bytearray:
        r0 = round(x0)
        r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
        r1 = round(x1)
        r1 = 0 if r1 < 0 else (4294967295 if r1 > 4294967295 else r1)
        r2 = round(x2 / 1e-06)
        r2 = 0 if r2 < 0 else (65535 if r2 > 65535 else r2)
        b1 = (counter & 15) | (r0 << 4)
        w23 = (r1 & 65535)
        w45 = (r1 >> 16)
        w67 = r2
        data = bytearray(_pack(K ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
        return data

    def frame(stamp: float, counter: int, x0: float, x1: float, x2: float) -> can.Message:
        r0 = round(x0)
        r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
        r1 = round(x1)
        r1 = 0 if r1 < 0 else (4294967295 if r1 > 4294967295 else r1)
        r2 = round(x2 / 1e-06)
        r2 = 0 if r2 < 0 else (65535 if r2 > 65535 else r2)
        b1 = (counter & 15) | (r0 << 4)
        w23 = (r1 & 65535)
        w45 = (r1 >> 16)
        w67 = r2
        data = bytearray(_pack(K ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
        m = _new(_Message)
        m.arbitration_id = FID
        m.is_extended_id = False
        m.is_remote_frame = False
        m.is_error_frame = False
        m.channel = None
        m.dlc = 8
        m.is_fd = False
        m.is_rx = False
        m.bitrate_switch = False
        m.error_state_indicator = False
        m.timestamp = stamp
        m.data = data
        return m

    def decode(data: bytes | bytearray) -> tuple[bool, int, tuple[float, ...]]:
        c, b1, w23, w45, w67 = _unpack(data)
        v0 = (b1 >> 4)
        v1 = w23 | (w45 << 16)
        v2 = w67 * 1e-06
        return (K ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) == c, b1 & 15, (v0, v1, v2,)

    return encode, frame, decode


def joint_cmd_make(K: int, FID: int) -> tuple[Encode, MakeFrame, Decode]:
    """Encode, frame and decode of one frame of the ``joint_cmd`` layout: CRC constant
    ``K``, id ``FID`` (see :class:`~.codec.FrameCodec`)."""

    def encode(counter: int, x0: float, x1: float, x2: float, x3: float) -> bytearray:
        r0 = round(x0)
        r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
        r1 = round(x1 / 0.01)
        r1 = -32768 if r1 < -32768 else (32767 if r1 > 32767 else r1)
        r2 = round(x2 / 0.0001)
        r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
        r3 = round(x3 / 0.0002)
        r3 = -32768 if r3 < -32768 else (32767 if r3 > 32767 else r3)
        b1 = (counter & 15) | (r0 << 4)
        w23 = (r1 & 65535)
        w45 = (r2 & 65535)
        w67 = (r3 & 65535)
        data = bytearray(_pack(K ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
        return data

    def frame(stamp: float, counter: int, x0: float, x1: float, x2: float, x3: float) -> can.Message:
        r0 = round(x0)
        r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
        r1 = round(x1 / 0.01)
        r1 = -32768 if r1 < -32768 else (32767 if r1 > 32767 else r1)
        r2 = round(x2 / 0.0001)
        r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
        r3 = round(x3 / 0.0002)
        r3 = -32768 if r3 < -32768 else (32767 if r3 > 32767 else r3)
        b1 = (counter & 15) | (r0 << 4)
        w23 = (r1 & 65535)
        w45 = (r2 & 65535)
        w67 = (r3 & 65535)
        data = bytearray(_pack(K ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
        m = _new(_Message)
        m.arbitration_id = FID
        m.is_extended_id = False
        m.is_remote_frame = False
        m.is_error_frame = False
        m.channel = None
        m.dlc = 8
        m.is_fd = False
        m.is_rx = False
        m.bitrate_switch = False
        m.error_state_indicator = False
        m.timestamp = stamp
        m.data = data
        return m

    def decode(data: bytes | bytearray) -> tuple[bool, int, tuple[float, ...]]:
        c, b1, w23, w45, w67 = _unpack(data)
        v0 = (b1 >> 4)
        r1 = w23
        v1 = ((r1 ^ 32768) - 32768) * 0.01
        r2 = w45
        v2 = ((r2 ^ 32768) - 32768) * 0.0001
        r3 = w67
        v3 = ((r3 ^ 32768) - 32768) * 0.0002
        return (K ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) == c, b1 & 15, (v0, v1, v2, v3,)

    return encode, frame, decode


def joint_state_make(K: int, FID: int) -> tuple[Encode, MakeFrame, Decode]:
    """Encode, frame and decode of one frame of the ``joint_state`` layout: CRC constant
    ``K``, id ``FID`` (see :class:`~.codec.FrameCodec`)."""

    def encode(counter: int, x0: float, x1: float, x2: float, x3: float) -> bytearray:
        r0 = round(x0)
        r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
        r1 = round(x1 / 1e-05)
        r1 = -524288 if r1 < -524288 else (524287 if r1 > 524287 else r1)
        r2 = round(x2 / 0.0002)
        r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
        r3 = round(x3 / 0.1)
        r3 = -2048 if r3 < -2048 else (2047 if r3 > 2047 else r3)
        b1 = (counter & 15) | (r0 << 4)
        w23 = (r1 & 65535)
        w45 = ((r1 >> 16) & 15) | ((r2 & 4095) << 4)
        w67 = ((r2 >> 12) & 15) | ((r3 & 4095) << 4)
        data = bytearray(_pack(K ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
        return data

    def frame(stamp: float, counter: int, x0: float, x1: float, x2: float, x3: float) -> can.Message:
        r0 = round(x0)
        r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
        r1 = round(x1 / 1e-05)
        r1 = -524288 if r1 < -524288 else (524287 if r1 > 524287 else r1)
        r2 = round(x2 / 0.0002)
        r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
        r3 = round(x3 / 0.1)
        r3 = -2048 if r3 < -2048 else (2047 if r3 > 2047 else r3)
        b1 = (counter & 15) | (r0 << 4)
        w23 = (r1 & 65535)
        w45 = ((r1 >> 16) & 15) | ((r2 & 4095) << 4)
        w67 = ((r2 >> 12) & 15) | ((r3 & 4095) << 4)
        data = bytearray(_pack(K ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
        m = _new(_Message)
        m.arbitration_id = FID
        m.is_extended_id = False
        m.is_remote_frame = False
        m.is_error_frame = False
        m.channel = None
        m.dlc = 8
        m.is_fd = False
        m.is_rx = False
        m.bitrate_switch = False
        m.error_state_indicator = False
        m.timestamp = stamp
        m.data = data
        return m

    def decode(data: bytes | bytearray) -> tuple[bool, int, tuple[float, ...]]:
        c, b1, w23, w45, w67 = _unpack(data)
        v0 = (b1 >> 4)
        r1 = w23 | ((w45 & 15) << 16)
        v1 = ((r1 ^ 524288) - 524288) * 1e-05
        r2 = (w45 >> 4) | ((w67 & 15) << 12)
        v2 = ((r2 ^ 32768) - 32768) * 0.0002
        r3 = (w67 >> 4)
        v3 = ((r3 ^ 2048) - 2048) * 0.1
        return (K ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) == c, b1 & 15, (v0, v1, v2, v3,)

    return encode, frame, decode

def joint_cmd_frames(
        stamp: float, counter: int, X0: Sequence[float], X1: Sequence[float], X2: Sequence[float],
        X3: Sequence[float],
) -> list[can.Message]:
    """The ``joint_cmd`` frames in bus order, signal ``i`` of frame ``j`` from ``X<i>[j]``
    (ids 513, 514, 515, 516, 517, 518, 519; see :attr:`~.codec.FrameGroup.frames`)."""
    x0_0, x0_1, x0_2, x0_3, x0_4, x0_5, x0_6, = X0
    x1_0, x1_1, x1_2, x1_3, x1_4, x1_5, x1_6, = X1
    x2_0, x2_1, x2_2, x2_3, x2_4, x2_5, x2_6, = X2
    x3_0, x3_1, x3_2, x3_3, x3_4, x3_5, x3_6, = X3
    r0 = round(x0_0)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_0 / 0.01)
    r1 = -32768 if r1 < -32768 else (32767 if r1 > 32767 else r1)
    r2 = round(x2_0 / 0.0001)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_0 / 0.0002)
    r3 = -32768 if r3 < -32768 else (32767 if r3 > 32767 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = (r2 & 65535)
    w67 = (r3 & 65535)
    data = bytearray(_pack(167 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m0 = _new(_Message)
    m0.arbitration_id = 513
    m0.is_extended_id = False
    m0.is_remote_frame = False
    m0.is_error_frame = False
    m0.channel = None
    m0.dlc = 8
    m0.is_fd = False
    m0.is_rx = False
    m0.bitrate_switch = False
    m0.error_state_indicator = False
    m0.timestamp = stamp
    m0.data = data
    r0 = round(x0_1)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_1 / 0.01)
    r1 = -32768 if r1 < -32768 else (32767 if r1 > 32767 else r1)
    r2 = round(x2_1 / 0.0001)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_1 / 0.0002)
    r3 = -32768 if r3 < -32768 else (32767 if r3 > 32767 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = (r2 & 65535)
    w67 = (r3 & 65535)
    data = bytearray(_pack(8 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m1 = _new(_Message)
    m1.arbitration_id = 514
    m1.is_extended_id = False
    m1.is_remote_frame = False
    m1.is_error_frame = False
    m1.channel = None
    m1.dlc = 8
    m1.is_fd = False
    m1.is_rx = False
    m1.bitrate_switch = False
    m1.error_state_indicator = False
    m1.timestamp = stamp
    m1.data = data
    r0 = round(x0_2)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_2 / 0.01)
    r1 = -32768 if r1 < -32768 else (32767 if r1 > 32767 else r1)
    r2 = round(x2_2 / 0.0001)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_2 / 0.0002)
    r3 = -32768 if r3 < -32768 else (32767 if r3 > 32767 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = (r2 & 65535)
    w67 = (r3 & 65535)
    data = bytearray(_pack(109 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m2 = _new(_Message)
    m2.arbitration_id = 515
    m2.is_extended_id = False
    m2.is_remote_frame = False
    m2.is_error_frame = False
    m2.channel = None
    m2.dlc = 8
    m2.is_fd = False
    m2.is_rx = False
    m2.bitrate_switch = False
    m2.error_state_indicator = False
    m2.timestamp = stamp
    m2.data = data
    r0 = round(x0_3)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_3 / 0.01)
    r1 = -32768 if r1 < -32768 else (32767 if r1 > 32767 else r1)
    r2 = round(x2_3 / 0.0001)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_3 / 0.0002)
    r3 = -32768 if r3 < -32768 else (32767 if r3 > 32767 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = (r2 & 65535)
    w67 = (r3 & 65535)
    data = bytearray(_pack(75 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m3 = _new(_Message)
    m3.arbitration_id = 516
    m3.is_extended_id = False
    m3.is_remote_frame = False
    m3.is_error_frame = False
    m3.channel = None
    m3.dlc = 8
    m3.is_fd = False
    m3.is_rx = False
    m3.bitrate_switch = False
    m3.error_state_indicator = False
    m3.timestamp = stamp
    m3.data = data
    r0 = round(x0_4)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_4 / 0.01)
    r1 = -32768 if r1 < -32768 else (32767 if r1 > 32767 else r1)
    r2 = round(x2_4 / 0.0001)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_4 / 0.0002)
    r3 = -32768 if r3 < -32768 else (32767 if r3 > 32767 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = (r2 & 65535)
    w67 = (r3 & 65535)
    data = bytearray(_pack(46 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m4 = _new(_Message)
    m4.arbitration_id = 517
    m4.is_extended_id = False
    m4.is_remote_frame = False
    m4.is_error_frame = False
    m4.channel = None
    m4.dlc = 8
    m4.is_fd = False
    m4.is_rx = False
    m4.bitrate_switch = False
    m4.error_state_indicator = False
    m4.timestamp = stamp
    m4.data = data
    r0 = round(x0_5)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_5 / 0.01)
    r1 = -32768 if r1 < -32768 else (32767 if r1 > 32767 else r1)
    r2 = round(x2_5 / 0.0001)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_5 / 0.0002)
    r3 = -32768 if r3 < -32768 else (32767 if r3 > 32767 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = (r2 & 65535)
    w67 = (r3 & 65535)
    data = bytearray(_pack(129 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m5 = _new(_Message)
    m5.arbitration_id = 518
    m5.is_extended_id = False
    m5.is_remote_frame = False
    m5.is_error_frame = False
    m5.channel = None
    m5.dlc = 8
    m5.is_fd = False
    m5.is_rx = False
    m5.bitrate_switch = False
    m5.error_state_indicator = False
    m5.timestamp = stamp
    m5.data = data
    r0 = round(x0_6)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_6 / 0.01)
    r1 = -32768 if r1 < -32768 else (32767 if r1 > 32767 else r1)
    r2 = round(x2_6 / 0.0001)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_6 / 0.0002)
    r3 = -32768 if r3 < -32768 else (32767 if r3 > 32767 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = (r2 & 65535)
    w67 = (r3 & 65535)
    data = bytearray(_pack(228 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m6 = _new(_Message)
    m6.arbitration_id = 519
    m6.is_extended_id = False
    m6.is_remote_frame = False
    m6.is_error_frame = False
    m6.channel = None
    m6.dlc = 8
    m6.is_fd = False
    m6.is_rx = False
    m6.bitrate_switch = False
    m6.error_state_indicator = False
    m6.timestamp = stamp
    m6.data = data
    return [m0, m1, m2, m3, m4, m5, m6]


def joint_cmd_unpack(messages: Sequence[can.Message], counter: int) -> Unpacked:
    """``Mode, Torque, Position, Velocity`` of the frames 513, 514, 515, 516, 517, 518, 519
    if they are exactly those, in order, intact, of cycle ``counter``; else None (see
    :attr:`~.codec.FrameGroup.unpack_exact`)."""
    try:
        m0, m1, m2, m3, m4, m5, m6, = messages
        if m0.arbitration_id != 513:
            return None
        c, b1, w23, w45, w67 = _unpack(m0.data)
        if (167 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_0 = (b1 >> 4)
        r1 = w23
        v1_0 = ((r1 ^ 32768) - 32768) * 0.01
        r2 = w45
        v2_0 = ((r2 ^ 32768) - 32768) * 0.0001
        r3 = w67
        v3_0 = ((r3 ^ 32768) - 32768) * 0.0002
        if m1.arbitration_id != 514:
            return None
        c, b1, w23, w45, w67 = _unpack(m1.data)
        if (8 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_1 = (b1 >> 4)
        r1 = w23
        v1_1 = ((r1 ^ 32768) - 32768) * 0.01
        r2 = w45
        v2_1 = ((r2 ^ 32768) - 32768) * 0.0001
        r3 = w67
        v3_1 = ((r3 ^ 32768) - 32768) * 0.0002
        if m2.arbitration_id != 515:
            return None
        c, b1, w23, w45, w67 = _unpack(m2.data)
        if (109 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_2 = (b1 >> 4)
        r1 = w23
        v1_2 = ((r1 ^ 32768) - 32768) * 0.01
        r2 = w45
        v2_2 = ((r2 ^ 32768) - 32768) * 0.0001
        r3 = w67
        v3_2 = ((r3 ^ 32768) - 32768) * 0.0002
        if m3.arbitration_id != 516:
            return None
        c, b1, w23, w45, w67 = _unpack(m3.data)
        if (75 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_3 = (b1 >> 4)
        r1 = w23
        v1_3 = ((r1 ^ 32768) - 32768) * 0.01
        r2 = w45
        v2_3 = ((r2 ^ 32768) - 32768) * 0.0001
        r3 = w67
        v3_3 = ((r3 ^ 32768) - 32768) * 0.0002
        if m4.arbitration_id != 517:
            return None
        c, b1, w23, w45, w67 = _unpack(m4.data)
        if (46 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_4 = (b1 >> 4)
        r1 = w23
        v1_4 = ((r1 ^ 32768) - 32768) * 0.01
        r2 = w45
        v2_4 = ((r2 ^ 32768) - 32768) * 0.0001
        r3 = w67
        v3_4 = ((r3 ^ 32768) - 32768) * 0.0002
        if m5.arbitration_id != 518:
            return None
        c, b1, w23, w45, w67 = _unpack(m5.data)
        if (129 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_5 = (b1 >> 4)
        r1 = w23
        v1_5 = ((r1 ^ 32768) - 32768) * 0.01
        r2 = w45
        v2_5 = ((r2 ^ 32768) - 32768) * 0.0001
        r3 = w67
        v3_5 = ((r3 ^ 32768) - 32768) * 0.0002
        if m6.arbitration_id != 519:
            return None
        c, b1, w23, w45, w67 = _unpack(m6.data)
        if (228 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_6 = (b1 >> 4)
        r1 = w23
        v1_6 = ((r1 ^ 32768) - 32768) * 0.01
        r2 = w45
        v2_6 = ((r2 ^ 32768) - 32768) * 0.0001
        r3 = w67
        v3_6 = ((r3 ^ 32768) - 32768) * 0.0002
    except (ValueError, _StructError):  # not n messages, not 8 bytes
        return None
    return (
        (v0_0, v0_1, v0_2, v0_3, v0_4, v0_5, v0_6),
        (v1_0, v1_1, v1_2, v1_3, v1_4, v1_5, v1_6),
        (v2_0, v2_1, v2_2, v2_3, v2_4, v2_5, v2_6),
        (v3_0, v3_1, v3_2, v3_3, v3_4, v3_5, v3_6),
    )


def joint_cmd_unpack_mode_torque(messages: Sequence[can.Message], counter: int) -> Unpacked:
    """``Mode, Torque`` of the frames 513, 514, 515, 516, 517, 518, 519
    if they are exactly those, in order, intact, of cycle ``counter``; else None (see
    :attr:`~.codec.FrameGroup.unpack_exact`)."""
    try:
        m0, m1, m2, m3, m4, m5, m6, = messages
        if m0.arbitration_id != 513:
            return None
        c, b1, w23, w45, w67 = _unpack(m0.data)
        if (167 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_0 = (b1 >> 4)
        r1 = w23
        v1_0 = ((r1 ^ 32768) - 32768) * 0.01
        if m1.arbitration_id != 514:
            return None
        c, b1, w23, w45, w67 = _unpack(m1.data)
        if (8 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_1 = (b1 >> 4)
        r1 = w23
        v1_1 = ((r1 ^ 32768) - 32768) * 0.01
        if m2.arbitration_id != 515:
            return None
        c, b1, w23, w45, w67 = _unpack(m2.data)
        if (109 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_2 = (b1 >> 4)
        r1 = w23
        v1_2 = ((r1 ^ 32768) - 32768) * 0.01
        if m3.arbitration_id != 516:
            return None
        c, b1, w23, w45, w67 = _unpack(m3.data)
        if (75 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_3 = (b1 >> 4)
        r1 = w23
        v1_3 = ((r1 ^ 32768) - 32768) * 0.01
        if m4.arbitration_id != 517:
            return None
        c, b1, w23, w45, w67 = _unpack(m4.data)
        if (46 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_4 = (b1 >> 4)
        r1 = w23
        v1_4 = ((r1 ^ 32768) - 32768) * 0.01
        if m5.arbitration_id != 518:
            return None
        c, b1, w23, w45, w67 = _unpack(m5.data)
        if (129 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_5 = (b1 >> 4)
        r1 = w23
        v1_5 = ((r1 ^ 32768) - 32768) * 0.01
        if m6.arbitration_id != 519:
            return None
        c, b1, w23, w45, w67 = _unpack(m6.data)
        if (228 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_6 = (b1 >> 4)
        r1 = w23
        v1_6 = ((r1 ^ 32768) - 32768) * 0.01
    except (ValueError, _StructError):  # not n messages, not 8 bytes
        return None
    return (
        (v0_0, v0_1, v0_2, v0_3, v0_4, v0_5, v0_6),
        (v1_0, v1_1, v1_2, v1_3, v1_4, v1_5, v1_6),
    )


def joint_state_frames(
        stamp: float, counter: int, X0: Sequence[float], X1: Sequence[float], X2: Sequence[float],
        X3: Sequence[float],
) -> list[can.Message]:
    """The ``joint_state`` frames in bus order, signal ``i`` of frame ``j`` from ``X<i>[j]``
    (ids 385, 386, 387, 388, 389, 390, 391; see :attr:`~.codec.FrameGroup.frames`)."""
    x0_0, x0_1, x0_2, x0_3, x0_4, x0_5, x0_6, = X0
    x1_0, x1_1, x1_2, x1_3, x1_4, x1_5, x1_6, = X1
    x2_0, x2_1, x2_2, x2_3, x2_4, x2_5, x2_6, = X2
    x3_0, x3_1, x3_2, x3_3, x3_4, x3_5, x3_6, = X3
    r0 = round(x0_0)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_0 / 1e-05)
    r1 = -524288 if r1 < -524288 else (524287 if r1 > 524287 else r1)
    r2 = round(x2_0 / 0.0002)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_0 / 0.1)
    r3 = -2048 if r3 < -2048 else (2047 if r3 > 2047 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = ((r1 >> 16) & 15) | ((r2 & 4095) << 4)
    w67 = ((r2 >> 12) & 15) | ((r3 & 4095) << 4)
    data = bytearray(_pack(182 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m0 = _new(_Message)
    m0.arbitration_id = 385
    m0.is_extended_id = False
    m0.is_remote_frame = False
    m0.is_error_frame = False
    m0.channel = None
    m0.dlc = 8
    m0.is_fd = False
    m0.is_rx = False
    m0.bitrate_switch = False
    m0.error_state_indicator = False
    m0.timestamp = stamp
    m0.data = data
    r0 = round(x0_1)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_1 / 1e-05)
    r1 = -524288 if r1 < -524288 else (524287 if r1 > 524287 else r1)
    r2 = round(x2_1 / 0.0002)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_1 / 0.1)
    r3 = -2048 if r3 < -2048 else (2047 if r3 > 2047 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = ((r1 >> 16) & 15) | ((r2 & 4095) << 4)
    w67 = ((r2 >> 12) & 15) | ((r3 & 4095) << 4)
    data = bytearray(_pack(25 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m1 = _new(_Message)
    m1.arbitration_id = 386
    m1.is_extended_id = False
    m1.is_remote_frame = False
    m1.is_error_frame = False
    m1.channel = None
    m1.dlc = 8
    m1.is_fd = False
    m1.is_rx = False
    m1.bitrate_switch = False
    m1.error_state_indicator = False
    m1.timestamp = stamp
    m1.data = data
    r0 = round(x0_2)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_2 / 1e-05)
    r1 = -524288 if r1 < -524288 else (524287 if r1 > 524287 else r1)
    r2 = round(x2_2 / 0.0002)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_2 / 0.1)
    r3 = -2048 if r3 < -2048 else (2047 if r3 > 2047 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = ((r1 >> 16) & 15) | ((r2 & 4095) << 4)
    w67 = ((r2 >> 12) & 15) | ((r3 & 4095) << 4)
    data = bytearray(_pack(124 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m2 = _new(_Message)
    m2.arbitration_id = 387
    m2.is_extended_id = False
    m2.is_remote_frame = False
    m2.is_error_frame = False
    m2.channel = None
    m2.dlc = 8
    m2.is_fd = False
    m2.is_rx = False
    m2.bitrate_switch = False
    m2.error_state_indicator = False
    m2.timestamp = stamp
    m2.data = data
    r0 = round(x0_3)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_3 / 1e-05)
    r1 = -524288 if r1 < -524288 else (524287 if r1 > 524287 else r1)
    r2 = round(x2_3 / 0.0002)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_3 / 0.1)
    r3 = -2048 if r3 < -2048 else (2047 if r3 > 2047 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = ((r1 >> 16) & 15) | ((r2 & 4095) << 4)
    w67 = ((r2 >> 12) & 15) | ((r3 & 4095) << 4)
    data = bytearray(_pack(90 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m3 = _new(_Message)
    m3.arbitration_id = 388
    m3.is_extended_id = False
    m3.is_remote_frame = False
    m3.is_error_frame = False
    m3.channel = None
    m3.dlc = 8
    m3.is_fd = False
    m3.is_rx = False
    m3.bitrate_switch = False
    m3.error_state_indicator = False
    m3.timestamp = stamp
    m3.data = data
    r0 = round(x0_4)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_4 / 1e-05)
    r1 = -524288 if r1 < -524288 else (524287 if r1 > 524287 else r1)
    r2 = round(x2_4 / 0.0002)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_4 / 0.1)
    r3 = -2048 if r3 < -2048 else (2047 if r3 > 2047 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = ((r1 >> 16) & 15) | ((r2 & 4095) << 4)
    w67 = ((r2 >> 12) & 15) | ((r3 & 4095) << 4)
    data = bytearray(_pack(63 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m4 = _new(_Message)
    m4.arbitration_id = 389
    m4.is_extended_id = False
    m4.is_remote_frame = False
    m4.is_error_frame = False
    m4.channel = None
    m4.dlc = 8
    m4.is_fd = False
    m4.is_rx = False
    m4.bitrate_switch = False
    m4.error_state_indicator = False
    m4.timestamp = stamp
    m4.data = data
    r0 = round(x0_5)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_5 / 1e-05)
    r1 = -524288 if r1 < -524288 else (524287 if r1 > 524287 else r1)
    r2 = round(x2_5 / 0.0002)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_5 / 0.1)
    r3 = -2048 if r3 < -2048 else (2047 if r3 > 2047 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = ((r1 >> 16) & 15) | ((r2 & 4095) << 4)
    w67 = ((r2 >> 12) & 15) | ((r3 & 4095) << 4)
    data = bytearray(_pack(144 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m5 = _new(_Message)
    m5.arbitration_id = 390
    m5.is_extended_id = False
    m5.is_remote_frame = False
    m5.is_error_frame = False
    m5.channel = None
    m5.dlc = 8
    m5.is_fd = False
    m5.is_rx = False
    m5.bitrate_switch = False
    m5.error_state_indicator = False
    m5.timestamp = stamp
    m5.data = data
    r0 = round(x0_6)
    r0 = 0 if r0 < 0 else (15 if r0 > 15 else r0)
    r1 = round(x1_6 / 1e-05)
    r1 = -524288 if r1 < -524288 else (524287 if r1 > 524287 else r1)
    r2 = round(x2_6 / 0.0002)
    r2 = -32768 if r2 < -32768 else (32767 if r2 > 32767 else r2)
    r3 = round(x3_6 / 0.1)
    r3 = -2048 if r3 < -2048 else (2047 if r3 > 2047 else r3)
    b1 = (counter & 15) | (r0 << 4)
    w23 = (r1 & 65535)
    w45 = ((r1 >> 16) & 15) | ((r2 & 4095) << 4)
    w67 = ((r2 >> 12) & 15) | ((r3 & 4095) << 4)
    data = bytearray(_pack(245 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67], b1, w23, w45, w67))
    m6 = _new(_Message)
    m6.arbitration_id = 391
    m6.is_extended_id = False
    m6.is_remote_frame = False
    m6.is_error_frame = False
    m6.channel = None
    m6.dlc = 8
    m6.is_fd = False
    m6.is_rx = False
    m6.bitrate_switch = False
    m6.error_state_indicator = False
    m6.timestamp = stamp
    m6.data = data
    return [m0, m1, m2, m3, m4, m5, m6]


def joint_state_unpack(messages: Sequence[can.Message], counter: int) -> Unpacked:
    """``Status, Position, Velocity, Torque`` of the frames 385, 386, 387, 388, 389, 390, 391
    if they are exactly those, in order, intact, of cycle ``counter``; else None (see
    :attr:`~.codec.FrameGroup.unpack_exact`)."""
    try:
        m0, m1, m2, m3, m4, m5, m6, = messages
        if m0.arbitration_id != 385:
            return None
        c, b1, w23, w45, w67 = _unpack(m0.data)
        if (182 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_0 = (b1 >> 4)
        r1 = w23 | ((w45 & 15) << 16)
        v1_0 = ((r1 ^ 524288) - 524288) * 1e-05
        r2 = (w45 >> 4) | ((w67 & 15) << 12)
        v2_0 = ((r2 ^ 32768) - 32768) * 0.0002
        r3 = (w67 >> 4)
        v3_0 = ((r3 ^ 2048) - 2048) * 0.1
        if m1.arbitration_id != 386:
            return None
        c, b1, w23, w45, w67 = _unpack(m1.data)
        if (25 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_1 = (b1 >> 4)
        r1 = w23 | ((w45 & 15) << 16)
        v1_1 = ((r1 ^ 524288) - 524288) * 1e-05
        r2 = (w45 >> 4) | ((w67 & 15) << 12)
        v2_1 = ((r2 ^ 32768) - 32768) * 0.0002
        r3 = (w67 >> 4)
        v3_1 = ((r3 ^ 2048) - 2048) * 0.1
        if m2.arbitration_id != 387:
            return None
        c, b1, w23, w45, w67 = _unpack(m2.data)
        if (124 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_2 = (b1 >> 4)
        r1 = w23 | ((w45 & 15) << 16)
        v1_2 = ((r1 ^ 524288) - 524288) * 1e-05
        r2 = (w45 >> 4) | ((w67 & 15) << 12)
        v2_2 = ((r2 ^ 32768) - 32768) * 0.0002
        r3 = (w67 >> 4)
        v3_2 = ((r3 ^ 2048) - 2048) * 0.1
        if m3.arbitration_id != 388:
            return None
        c, b1, w23, w45, w67 = _unpack(m3.data)
        if (90 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_3 = (b1 >> 4)
        r1 = w23 | ((w45 & 15) << 16)
        v1_3 = ((r1 ^ 524288) - 524288) * 1e-05
        r2 = (w45 >> 4) | ((w67 & 15) << 12)
        v2_3 = ((r2 ^ 32768) - 32768) * 0.0002
        r3 = (w67 >> 4)
        v3_3 = ((r3 ^ 2048) - 2048) * 0.1
        if m4.arbitration_id != 389:
            return None
        c, b1, w23, w45, w67 = _unpack(m4.data)
        if (63 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_4 = (b1 >> 4)
        r1 = w23 | ((w45 & 15) << 16)
        v1_4 = ((r1 ^ 524288) - 524288) * 1e-05
        r2 = (w45 >> 4) | ((w67 & 15) << 12)
        v2_4 = ((r2 ^ 32768) - 32768) * 0.0002
        r3 = (w67 >> 4)
        v3_4 = ((r3 ^ 2048) - 2048) * 0.1
        if m5.arbitration_id != 390:
            return None
        c, b1, w23, w45, w67 = _unpack(m5.data)
        if (144 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_5 = (b1 >> 4)
        r1 = w23 | ((w45 & 15) << 16)
        v1_5 = ((r1 ^ 524288) - 524288) * 1e-05
        r2 = (w45 >> 4) | ((w67 & 15) << 12)
        v2_5 = ((r2 ^ 32768) - 32768) * 0.0002
        r3 = (w67 >> 4)
        v3_5 = ((r3 ^ 2048) - 2048) * 0.1
        if m6.arbitration_id != 391:
            return None
        c, b1, w23, w45, w67 = _unpack(m6.data)
        if (245 ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) != c or b1 & 15 != counter:
            return None
        v0_6 = (b1 >> 4)
        r1 = w23 | ((w45 & 15) << 16)
        v1_6 = ((r1 ^ 524288) - 524288) * 1e-05
        r2 = (w45 >> 4) | ((w67 & 15) << 12)
        v2_6 = ((r2 ^ 32768) - 32768) * 0.0002
        r3 = (w67 >> 4)
        v3_6 = ((r3 ^ 2048) - 2048) * 0.1
    except (ValueError, _StructError):  # not n messages, not 8 bytes
        return None
    return (
        (v0_0, v0_1, v0_2, v0_3, v0_4, v0_5, v0_6),
        (v1_0, v1_1, v1_2, v1_3, v1_4, v1_5, v1_6),
        (v2_0, v2_1, v2_2, v2_3, v2_4, v2_5, v2_6),
        (v3_0, v3_1, v3_2, v3_3, v3_4, v3_5, v3_6),
    )


LAYOUTS: dict[LayoutKey, Callable[[int, int], tuple[Encode, MakeFrame, Decode]]] = {
    SYNC_LAYOUT: sync_make,
    JOINT_CMD_LAYOUT: joint_cmd_make,
    JOINT_STATE_LAYOUT: joint_state_make,
}
"""Payload layout -> its ``make(K, FID)``."""

GROUPS: dict[tuple[LayoutKey, tuple[int, ...]], GroupCode] = {
    (JOINT_CMD_LAYOUT, (513, 514, 515, 516, 517, 518, 519)): (joint_cmd_frames, {
        ('Mode', 'Torque', 'Position', 'Velocity'): joint_cmd_unpack,
        ('Mode', 'Torque'): joint_cmd_unpack_mode_torque,
    }),
    (JOINT_STATE_LAYOUT, (385, 386, 387, 388, 389, 390, 391)): (joint_state_frames, {
        ('Status', 'Position', 'Velocity', 'Torque'): joint_state_unpack,
    }),
}
"""(layout, frame ids in bus order) -> (frames, {signal names: unpacker})."""
