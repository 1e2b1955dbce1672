"""Cheap construction of :class:`can.Message` for the 1 kHz path.

``can.Message.__init__`` normalises and checks every argument (about 1.5 us per frame
on a slow core, 15 frames per cycle); the bus code builds frames it knows to be valid
classic data frames, so it fills the slots directly (about 0.5 us). The codecs'
generated ``FrameCodec.frame`` does the same inline (:data:`CLASSIC_FRAME_SLOTS`).
"""

from __future__ import annotations

from typing import Any

import can

_new = object.__new__
_Message = can.Message

CLASSIC_FRAME_SLOTS: dict[str, Any] = {
    "is_extended_id": False, "is_remote_frame": False, "is_error_frame": False,
    "channel": None, "dlc": 8, "is_fd": False, "is_rx": False, "bitrate_switch": False,
    "error_state_indicator": False,
}
"""The slots of an 8-byte classic data frame with an 11-bit id, besides
``arbitration_id``, ``timestamp`` and ``data`` (what :func:`new_message` sets by
default)."""


def new_message(timestamp: float, arbitration_id: int, is_extended_id: bool, dlc: int,
                data: bytearray, channel: Any = None, is_rx: bool = False) -> can.Message:
    """A classic data frame without running :class:`can.Message`'s constructor.

    The caller guarantees validity: ``data`` a ``bytearray`` of ``dlc`` (<= 8) bytes,
    an id in range for ``is_extended_id``. Every slot is set, so the message behaves
    exactly as one built by the constructor (equality, printing, copying).
    """
    m = _new(_Message)
    m.timestamp = timestamp
    m.arbitration_id = arbitration_id
    m.is_extended_id = is_extended_id
    m.is_remote_frame = False
    m.is_error_frame = False
    m.channel = channel
    m.dlc = dlc
    m.data = data
    m.is_fd = False
    m.is_rx = is_rx
    m.bitrate_switch = False
    m.error_state_indicator = False
    return m
