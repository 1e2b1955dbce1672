"""Joint-bus frame codecs: the generated fast encode/decode, and cantools' reference.

The DBC (``sim/edan_joints.dbc``) is the single source of truth for ids, bit positions
and scalings; cantools loads it (:mod:`.layout`). Per payload layout, the fast code is
generated from it into a checked-in module (:mod:`._codec_generated`, written by
:mod:`.codegen`), so the 1 kHz path packs a frame with a handful of integer operations
instead of cantools' generic machinery (about 25 us per encode on a slow core).
:class:`FrameCodec` binds one frame's id and CRC constant into its layout's functions;
``FrameCodec.encode_cantools`` / ``decode_cantools`` go through cantools itself; tests
assert both paths agree bit for bit over the whole signal ranges.

A :class:`FrameGroup` does the same for the frames that travel together each cycle
(the seven commands, the seven states) in one generated call: it builds the group's
messages, and decodes a group that arrived exactly as sent (in order, intact, of the
expected cycle), which is what the bus endpoints see nearly every cycle; anything
else they check frame by frame.

Frame protocol (every frame, see :mod:`.crc`): byte 0 ``CRC``, bits 8-11 ``Counter``
(low 4 bits of the SYNC cycle number), the rest payload signals in DBC order.
Values outside a signal's range saturate to the range.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import cast

import can
import cantools

from . import _codec_generated as generated
from .crc import FrameCrc
from .layout import DBC_PATH, Field, fields_from_message, layout_key, load_dbc

# (crc ok, rolling counter, payload values in signal order)
DecodedFrame = tuple[bool, int, tuple[float, ...]]

SYNC_ID = 0x080
"""Frame id of the SYNC frame."""
CMD_BASE_ID = 0x200
"""Frame id of joint ``j``'s command frame is ``CMD_BASE_ID + j`` (``j`` from 1)."""
STATE_BASE_ID = 0x180
"""Frame id of joint ``j``'s state frame is ``STATE_BASE_ID + j`` (``j`` from 1)."""

MODE_ENABLE = 0x1
"""Command ``Mode`` bit: apply the torque (0: the drive brakes)."""
STATUS_ENABLED = 0x1
"""State ``Status`` bit: torque applied."""
STATUS_BRAKED = 0x2
"""State ``Status`` bit: brake engaged, joint held."""
STATUS_TIMEOUT = 0x4
"""State ``Status`` bit: commands missing longer than the drive timeout."""
STATUS_SATURATED = 0x8
"""State ``Status`` bit: torque or position limit reached."""

_REGENERATE = "regenerate the codec: python -m sctd_sim.canbus.codegen"


class FrameCodec:
    """Fast encoder/decoder of one DBC frame with CRC and counter.

    Parameters
    ----------
    message : cantools.database.can.Message
        The frame's definition. It must be 8 bytes, little-endian, and start with
        ``CRC`` (bits 0-7) and ``Counter`` (bits 8-11) (see
        :func:`~.layout.fields_from_message`), and its payload layout must be one the
        generated codec has.

    Attributes
    ----------
    frame_id : int
    name : str
    signal_names : tuple of str
        Payload signals (everything after ``CRC`` and ``Counter``) in the order
        :meth:`encode` takes and :meth:`decode` returns them.
    pack : callable
        ``pack(counter, *values) -> bytearray``: :meth:`encode` without the argument
        unpacking, for the 1 kHz path.
    frame : callable
        ``frame(stamp, counter, *values) -> can.Message``: :attr:`pack` into a new
        classic data frame with this id and timestamp ``stamp`` (as
        :func:`~.frames.new_message` builds it).
    unpack : callable
        ``unpack(data) -> (crc_ok, counter, values)``: :meth:`decode` for data known
        to be 8 bytes long.
    """

    def __init__(self, message: cantools.database.can.Message) -> None:
        self.message = message
        self.frame_id = int(message.frame_id)
        self.name = str(message.name)
        self.crc = FrameCrc(self.frame_id)
        self._fields = fields_from_message(message)
        self.signal_names = tuple(f.name for f in self._fields)
        make = generated.LAYOUTS.get(layout_key(self._fields))
        if make is None:
            raise ValueError(f"{self.name}: payload layout not in the generated codec ({_REGENERATE})")
        encode, frame, decode = make(self.crc.const, self.frame_id)
        self.pack: Callable[..., bytearray] = encode
        self.frame: Callable[..., can.Message] = frame
        self.unpack: Callable[[bytes | bytearray], DecodedFrame] = decode

    def encode(self, counter: int, values: Sequence[float]) -> bytearray:
        """Pack one frame.

        Parameters
        ----------
        counter : int
            Rolling counter; only its low 4 bits are sent.
        values : sequence of float
            Physical values of :attr:`signal_names`, in that order. Saturated to the
            signal range, rounded to the nearest raw step.

        Returns
        -------
        bytearray, length 8
            The frame's data with ``CRC`` filled in.
        """
        return self.pack(counter, *values)

    def decode(self, data: bytes | bytearray) -> DecodedFrame:
        """Unpack one frame.

        Parameters
        ----------
        data : bytes, length 8

        Returns
        -------
        crc_ok : bool
            Whether the CRC matches (and the length is 8); if not, the other outputs
            are meaningless.
        counter : int
        values : tuple of float
            Physical values of :attr:`signal_names`.
        """
        if len(data) != 8:
            return False, 0, ()
        return self.unpack(data)

    def encode_cantools(self, counter: int, values: Sequence[float]) -> bytes:
        """:meth:`encode` through cantools (slow reference path)."""
        sig = dict(zip(self.signal_names, values, strict=True))
        for f in self._fields:
            # Hand cantools raw integers: scaling a rounded raw value back to physical
            # units and letting cantools re-scale it can land one step low
            # (127669.999... truncated).
            x = round((sig[f.name] - f.offset) / f.scale)
            sig[f.name] = min(max(x, f.raw_min), f.raw_max)
        sig["Counter"] = counter & 0xF
        sig["CRC"] = 0
        data = bytearray(self.message.encode(sig, scaling=False, strict=False))
        data[0] = self.crc(data)
        return bytes(data)

    def decode_cantools(self, data: bytes | bytearray) -> DecodedFrame:
        """:meth:`decode` through cantools (slow reference path)."""
        d = cast(Mapping[str, float], self.message.decode(bytes(data), decode_choices=False,
                                                          scaling=True))
        vals = tuple(float(d[n]) for n in self.signal_names)
        return self.crc(data) == data[0], int(d["Counter"]), vals

    def resolution(self, name: str) -> float:
        """Scale (one raw step) of payload signal ``name``."""
        return self.field(name).scale

    def field(self, name: str) -> Field:
        """Payload signal ``name``'s layout (bits, sign, scale, offset).

        Raises
        ------
        ValueError
            The frame has no such payload signal.
        """
        for f in self._fields:
            if f.name == name:
                return f
        raise ValueError(f"{self.name}: no payload signal {name!r} (it has {', '.join(self.signal_names)})")

    def limits(self, name: str) -> tuple[float, float]:
        """Physical range of payload signal ``name``."""
        f = next(f for f in self._fields if f.name == name)
        return f.raw_min * f.scale + f.offset, f.raw_max * f.scale + f.offset


class FrameGroup:
    """Frames of one layout that travel together (the joints' commands, or their
    states), with generated code for the whole group in bus order.

    Parameters
    ----------
    codecs : sequence of FrameCodec
        The group's frames, in the order they are sent; all of one payload layout, and
        a group the generated codec has (``JointCmd_1..n``, ``JointState_1..n``).

    Attributes
    ----------
    codecs : tuple of FrameCodec
    frame_ids : tuple of int
    signal_names : tuple of str
        The payload signals (as :attr:`FrameCodec.signal_names`).
    subsets : tuple of tuple of str
        The signal selections :meth:`unpacker` has code for (all signals first).
    frames : callable
        ``frames(stamp, counter, *signals) -> list[can.Message]``: one frame per codec,
        each signal a sequence with one value per frame (as
        ``[c.frame(stamp, counter, *vals) for c, vals in zip(codecs, zip(*signals))]``).
    unpack_exact : callable
        ``unpack_exact(messages, counter) -> tuple or None``: if ``messages`` are
        exactly the group's frames in order, each 8 bytes with a good CRC and counter
        ``counter``, the decoded values as one tuple per signal (one value per frame);
        else None (and nothing else: the caller then looks at the frames one by one).
        :meth:`unpacker` gives one for some of the signals.
    """

    def __init__(self, codecs: Sequence[FrameCodec]) -> None:
        self.codecs = tuple(codecs)
        if not self.codecs or any(c._fields != self.codecs[0]._fields for c in self.codecs):
            raise ValueError("FrameGroup: needs frames of one payload layout")
        self.frame_ids = tuple(c.frame_id for c in self.codecs)
        self.signal_names = self.codecs[0].signal_names
        code = generated.GROUPS.get((layout_key(self.codecs[0]._fields), self.frame_ids))
        if code is None:
            raise ValueError(f"FrameGroup: frames {self.frame_ids} are not a group of the "
                             f"generated codec ({_REGENERATE})")
        self.frames, self._unpackers = code
        self.subsets = tuple(self._unpackers)
        self.unpack_exact = self._unpackers[self.signal_names]

    def unpacker(self, names: Sequence[str]) -> generated.Unpack:
        """:attr:`unpack_exact` returning only the signals ``names``, in that order (one
        of :attr:`subsets`). Every frame's CRC still covers all its bytes.

        Raises
        ------
        ValueError
            A name is not a signal of the group, or the selection has no generated code.
        """
        unknown = set(names) - set(self.signal_names)
        if unknown:
            raise ValueError(f"FrameGroup.unpacker: no signals {sorted(unknown)}")
        unpack = self._unpackers.get(tuple(names))
        if unpack is None:
            raise ValueError(f"FrameGroup.unpacker: no generated code for {tuple(names)} (add it to "
                             f"codegen.UNPACK_SUBSETS and {_REGENERATE})")
        return unpack


class JointBusCodecs:
    """The codecs of one joint bus: SYNC, and per joint a command and a state frame.

    Parameters
    ----------
    n_joints : int, optional
        Number of joints (frames ``JointCmd_1..n``, ``JointState_1..n`` must exist).
    dbc_path : str or Path, optional

    Attributes
    ----------
    sync : FrameCodec
    cmd, state : list of FrameCodec
        Index ``i`` is joint ``i + 1``.
    by_id : dict of int to FrameCodec
    cmd_group, state_group : FrameGroup
        The command and the state frames as groups, joint 1 first.
    """

    def __init__(self, n_joints: int = 7, dbc_path: str | Path = DBC_PATH) -> None:
        db = load_dbc(dbc_path)
        self.n_joints = n_joints
        self.sync = FrameCodec(db.get_message_by_frame_id(SYNC_ID))
        self.cmd = [FrameCodec(db.get_message_by_frame_id(CMD_BASE_ID + j)) for j in
                    range(1, n_joints + 1)]
        self.state = [FrameCodec(db.get_message_by_frame_id(STATE_BASE_ID + j)) for j in
                      range(1, n_joints + 1)]
        self.by_id = {c.frame_id: c for c in [self.sync, *self.cmd, *self.state]}
        self.cmd_group = FrameGroup(self.cmd)
        self.state_group = FrameGroup(self.state)

    @property
    def all(self) -> list[FrameCodec]:
        """Every frame codec, SYNC first."""
        return [self.sync, *self.cmd, *self.state]
