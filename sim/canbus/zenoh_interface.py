"""python-can interface ``sctd``: a CAN bus carried over Zenoh, one sample per batch.

Registered as the ``can.interface`` entry point ``sctd``, so python-can's own tools
reach the simulator's joint bus from another process::

    python -m can.logger -i sctd -c edan --bus-kwargs connect=tcp/127.0.0.1:7447
    python -m can.viewer -i sctd -c edan

Key and payload
    Every participant publishes and subscribes on ``sctd/<channel>/can`` (the channel
    is the robot name, default ``edan``). A sample holds one batch of frames, in bus
    order, as a msgpack map ``{v: 1, frames: [...]}`` (like every sctd payload, a
    versioned map; docs/wire-contract.md), each frame ``[timestamp, arbitration_id,
    is_extended_id, dlc, data]`` (float Unix time s, int, bool, int, bin of ``dlc``
    bytes, at most 8). ``sctd sim`` publishes one sample per bus cycle (the SYNC, the
    seven commands and the seven joint states: 15 frames) only while someone listens,
    so watching costs little; :meth:`ZenohBus.send` publishes one frame per sample
    (:meth:`ZenohBus.send_batch` several). The simulator delivers frames received on
    the key to its bus, at the start of its next cycle, so external tools can drive
    the drives or inject faults (the drives' counter and CRC checks see them).
    A participant does not receive its own samples (Zenoh ``Locality.REMOTE``).
    Samples that do not decode are dropped and counted (:attr:`ZenohBus.dropped`).

Sessions follow sctd's defaults (TCP on loopback, no multicast scouting, see
:mod:`sctd.wire.session`); ``connect``, ``listen`` (an endpoint, a list, or a
comma-separated string) and ``zenoh_config`` (a json5 file) change them.
"""

from __future__ import annotations

import contextlib
import queue
import time
from collections.abc import Iterable, Sequence
from typing import Any

import can
import msgpack
import zenoh

from .frames import new_message

CAN_KEY_SUFFIX = "can"


def can_key(channel: str) -> str:
    """Key expression of the bus ``channel``: ``sctd/<channel>/can``."""
    channel = str(channel)
    if not channel or any(c in channel for c in "/*$?#"):
        raise ValueError(f"channel {channel!r} must be a single key chunk (the robot name)")
    return f"sctd/{channel}/{CAN_KEY_SUFFIX}"


def encode_frames(msgs: Iterable[can.Message]) -> bytes:
    """One sample's payload: ``{v: 1, frames: [[ts, id, ext, dlc, data], ...]}``."""
    frames = [[m.timestamp, m.arbitration_id, m.is_extended_id, m.dlc, bytes(m.data)] for m in msgs]
    return msgpack.packb({"v": 1, "frames": frames}, use_bin_type=True)


class FrameDecodeError(ValueError):
    """A sample that is not a list of well-formed frames."""


def decode_frames(payload: bytes, channel: Any = None) -> list[can.Message]:
    """Inverse of :func:`encode_frames`; validates every field.

    Raises
    ------
    FrameDecodeError
        Not msgpack, not a list of 5-element frames, or a field out of range.
    """
    try:
        obj = msgpack.unpackb(payload, raw=False)
    except Exception:  # msgpack raises several unrelated types on bad bytes
        raise FrameDecodeError("not msgpack") from None
    if not isinstance(obj, dict) or not isinstance(obj.get("frames"), list):
        raise FrameDecodeError("not a map with a list of frames")
    out = []
    for f in obj["frames"]:
        if not isinstance(f, list | tuple) or len(f) != 5:
            raise FrameDecodeError("frame is not [timestamp, id, is_extended, dlc, data]")
        ts, fid, ext, dlc, data = f
        if isinstance(ts, bool) or not isinstance(ts, int | float):
            raise FrameDecodeError("bad timestamp")
        if not isinstance(ext, bool):
            raise FrameDecodeError("bad is_extended")
        if isinstance(fid, bool) or not isinstance(fid, int) or not 0 <= fid < (
                1 << (29 if ext else 11)):
            raise FrameDecodeError("bad arbitration id")
        if not isinstance(data, bytes) or len(data) > 8:
            raise FrameDecodeError("bad data")
        if isinstance(dlc, bool) or not isinstance(dlc, int) or dlc != len(data):
            raise FrameDecodeError("dlc does not match the data")
        out.append(new_message(float(ts), fid, ext, dlc, bytearray(data), channel, is_rx=True))
    return out


def _endpoints(value: str | Sequence[str] | None) -> list[str] | None:
    if value is None or value == "":
        return None
    if isinstance(value, str):
        return [e.strip() for e in value.split(",") if e.strip()]
    return [str(e) for e in value]


class ZenohBus(can.BusABC):
    """A python-can bus whose frames travel over Zenoh (see the module doc).

    Parameters
    ----------
    channel : str, optional
        Robot name; the key is ``sctd/<channel>/can``.
    connect, listen : str or list of str, optional
        Zenoh endpoints (loopback TCP without ``zenoh_config``).
    zenoh_config : str, optional
        Zenoh json5 config file replacing the loopback defaults.
    receive_own_messages : bool, optional
        Also receive the frames this bus sends.
    session : zenoh.Session, optional
        Use an open session (not closed on shutdown) instead of opening one.
    **kwargs
        Passed to :class:`can.BusABC` (e.g. ``can_filters``).

    Attributes
    ----------
    dropped : int
        Received samples that did not decode.
    """

    def __init__(self, channel: Any = "edan", connect: str | Sequence[str] | None = None,
                 listen: str | Sequence[str] | None = None, zenoh_config: str | None = None,
                 receive_own_messages: bool = False, session: zenoh.Session | None = None,
                 **kwargs: Any) -> None:
        from sctd.wire.session import MSGPACK, close_session, open_session

        self.channel = channel = str(channel if channel is not None else "edan")
        self.channel_info = f"Zenoh {can_key(channel)}"
        self.key = can_key(channel)
        self.receive_own_messages = receive_own_messages
        self.dropped = 0
        self._rx: queue.SimpleQueue[can.Message] = queue.SimpleQueue()
        # a failure midway closes what was opened; shutdown() closes the rest
        with contextlib.ExitStack() as stack:
            if session is None:
                session = open_session(_endpoints(listen), _endpoints(connect), zenoh_config)
                stack.callback(close_session, session)  # bounded: see sctd.wire.session
            self._session = session
            self._pub = session.declare_publisher(self.key, encoding=MSGPACK,
                                                  congestion_control=zenoh.CongestionControl.BLOCK)
            stack.callback(_undeclare_quietly, self._pub)
            self._sub = session.declare_subscriber(self.key, self._on_sample,
                                                   allowed_origin=zenoh.Locality.REMOTE)
            stack.callback(_undeclare_quietly, self._sub)
            super().__init__(channel=channel, **kwargs)
            self._resources = stack.pop_all()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            msgs = decode_frames(sample.payload.to_bytes(), self.channel)
        except FrameDecodeError:
            self.dropped += 1
            return
        put = self._rx.put
        for m in msgs:
            put(m)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            if timeout is None:
                return self._rx.get(), False
            if timeout <= 0:
                return self._rx.get_nowait(), False
            return self._rx.get(timeout=timeout), False
        except queue.Empty:
            return None, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Publish one frame (one sample)."""
        self.send_batch([msg])

    def send_batch(self, msgs: Sequence[can.Message]) -> None:
        """Publish several frames in one sample, in order."""
        if not self._is_shutdown:
            for m in msgs:
                if m.is_fd or m.is_remote_frame or m.is_error_frame or len(m.data) > 8:
                    raise can.CanOperationError("sctd bus carries classic data frames only")
        else:
            raise can.CanOperationError("bus is shut down")
        stamp = time.time()
        out = [new_message(m.timestamp or stamp, m.arbitration_id, m.is_extended_id, len(m.data),
                           bytearray(m.data), self.channel) for m in msgs]
        self._pub.put(encode_frames(out))
        if self.receive_own_messages:
            for m in out:
                self._rx.put(m)

    def shutdown(self) -> None:
        """Undeclare the publisher and subscriber; close the session if it is ours."""
        if self._is_shutdown:
            return
        super().shutdown()
        self._resources.close()


def _undeclare_quietly(declaration: zenoh.Publisher | zenoh.Subscriber) -> None:
    try:
        declaration.undeclare()
    except Exception:  # a session the caller gave may already be closed
        pass
