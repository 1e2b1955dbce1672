"""Joint-bus frame layouts from the DBC, with a precomputed fast encode/decode.

The DBC (``sim/edan_joints.dbc``) is the single source of truth for ids, bit positions
and scalings; cantools loads it. Per frame, :class:`FrameCodec` turns the cantools
signal definitions into shifts, masks and scales once, so the 1 kHz path packs a
frame with a handful of integer operations instead of cantools' generic machinery
(about 25 us per encode on a slow core). ``FrameCodec.encode_cantools`` /
``decode_cantools`` go through cantools itself; tests assert both paths agree
bit for bit over the whole signal ranges.

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
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from struct import Struct
from struct import error as StructError
from typing import Any, cast

import can
import cantools

from .crc import FrameCrc, word_tables
from .frames import CLASSIC_FRAME_SLOTS

# (crc ok, rolling counter, payload values in signal order)
DecodedFrame = tuple[bool, int, tuple[float, ...]]

DBC_PATH = Path(__file__).resolve().parent.parent / "edan_joints.dbc"
"""Path of the shipped joint-bus DBC."""

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

_HEADER = ("CRC", "Counter")

_STRUCT = Struct("<BBHHH")
"""A frame's data as the CRC byte, byte 1 and three little-endian 16-bit words."""
_WORDS = {"b1": (8, 8), "w23": (16, 16), "w45": (32, 16), "w67": (48, 16)}
"""The words of :data:`_STRUCT` after the CRC byte: name -> (first bit, bit count)."""


@dataclass(frozen=True)
class _Field:
    name: str
    start: int
    mask: int
    length: int
    sign_bit: int  # 0 for unsigned
    scale: float
    offset: float
    raw_min: int
    raw_max: int


class FrameCodec:
    """Fast encoder/decoder of one DBC frame with CRC and counter.

    Parameters
    ----------
    message : cantools.database.can.Message
        The frame's definition. It must be 8 bytes, little-endian, and start with
        ``CRC`` (bits 0-7) and ``Counter`` (bits 8-11).

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
        sigs = list(message.signals)
        if message.length != 8 or [s.name for s in sigs[:2]] != list(_HEADER):
            raise ValueError(f"{message.name}: need 8 bytes starting with CRC, Counter")
        if sigs[0].start != 0 or sigs[0].length != 8 or sigs[1].start != 8 or sigs[1].length != 4:
            raise ValueError(f"{message.name}: CRC must be bits 0-7 and Counter bits 8-11")
        self.message = message
        self.frame_id = int(message.frame_id)
        self.name = str(message.name)
        self.crc = FrameCrc(self.frame_id)
        fields = []
        for s in sigs[2:]:
            if s.byte_order != "little_endian":
                raise ValueError(f"{message.name}.{s.name}: only little-endian signals")
            if s.is_signed:
                raw_min, raw_max = -(1 << (s.length - 1)), (1 << (s.length - 1)) - 1
            else:
                raw_min, raw_max = 0, (1 << s.length) - 1
            fields.append(
                _Field(
                    name=s.name,
                    start=s.start,
                    mask=(1 << s.length) - 1,
                    length=s.length,
                    sign_bit=(1 << (s.length - 1)) if s.is_signed else 0,
                    scale=float(s.scale),
                    offset=float(s.offset),
                    raw_min=raw_min,
                    raw_max=raw_max,
                )
            )
        self._fields = tuple(fields)
        self.signal_names = tuple(f.name for f in fields)
        self._compile()

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
        return self._encode(counter, *values)

    def decode(self, data: bytes | bytearray) -> tuple[bool, int, tuple[float, ...]]:
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
        return self._decode(data)

    def _compile(self) -> None:
        """Bind this frame's CRC constant and id into its layout's generated functions
        (see :func:`_layout_factory`)."""
        make = _layout_factory(self._fields)
        encode, frame, decode = make(self.crc.const, self.frame_id)
        self._encode = self.pack = cast(Callable[..., bytearray], encode)
        self.frame = cast(Callable[..., can.Message], frame)
        self._decode = self.unpack = cast(Callable[[bytes | bytearray], DecodedFrame], decode)

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

    def decode_cantools(self, data: bytes | bytearray) -> tuple[bool, int, tuple[float, ...]]:
        """:meth:`decode` through cantools (slow reference path)."""
        d = cast(Mapping[str, float], self.message.decode(bytes(data), decode_choices=False,
                                                          scaling=True))
        vals = tuple(float(d[n]) for n in self.signal_names)
        return self.crc(data) == data[0], int(d["Counter"]), vals

    def resolution(self, name: str) -> float:
        """Scale (one raw step) of payload signal ``name``."""
        return next(f.scale for f in self._fields if f.name == name)

    def limits(self, name: str) -> tuple[float, float]:
        """Physical range of payload signal ``name``."""
        f = next(f for f in self._fields if f.name == name)
        return f.raw_min * f.scale + f.offset, f.raw_max * f.scale + f.offset


class _Layout:
    """Source snippets packing and unpacking one payload layout.

    The 8 data bytes are handled as ``struct`` ``"<BBHHH"``: the CRC byte, byte 1
    (counter and the low payload bits) and three 16-bit words, so every value stays a
    small int; a signal is cut into its parts in these words, with the masks and shifts
    as literals. The CRC is four lookups over the same words
    (:func:`~.crc.word_tables`). Unrolled code with literal constants runs several
    times as fast as a loop over signal descriptors; the per-frame cost matters at 15
    frames per millisecond.
    """

    def __init__(self, fields: tuple[_Field, ...]) -> None:
        self.fields = fields
        self._words: dict[str, list[str]] = {w: [] for w in _WORDS}  # encode: parts per word
        self._signals: list[str] = []  # decode: raw value of each signal from the words
        for i, f in enumerate(fields):
            end = f.start + f.length
            parts = []
            for w, (w_start, w_len) in _WORDS.items():
                lo, hi = max(f.start, w_start), min(end, w_start + w_len)
                if lo >= hi:
                    continue
                mask = (1 << (hi - lo)) - 1
                # encode: bits lo..hi of the signal into the word (>> on a negative raw
                # value is arithmetic, so & mask gives its two's complement bits)
                x = _shift(f"r{i}", lo - f.start, ">>")
                if hi < end or f.sign_bit:
                    x = f"({x} & {mask})"
                self._words[w].append(_shift(x, lo - w_start, "<<"))
                # decode: the same bits out of the word (unsigned: no mask at its top)
                y = _shift(w, lo - w_start, ">>")
                if hi < w_start + w_len:
                    y = f"({y} & {mask})"
                parts.append(_shift(y, lo - f.start, "<<"))
            self._signals.append(" | ".join(parts))

    def pack(self, args: Sequence[str], counter: str, crc_const: str, pad: str) -> list[str]:
        """Lines setting ``data`` (a bytearray) from the physical values ``args``."""
        lines = []
        for i, (f, x) in enumerate(zip(self.fields, args, strict=True)):
            lines.append(f"{pad}r{i} = {_raw_expr(f, x)}")
            lines.append(f"{pad}r{i} = {f.raw_min} if r{i} < {f.raw_min} else "
                         f"({f.raw_max} if r{i} > {f.raw_max} else r{i})")
        for w, parts in self._words.items():
            if w == "b1":
                parts = [f"({counter} & 15)", *parts]
            lines.append(f"{pad}{w} = {' | '.join(parts) or '0'}")
        lines.append(f"{pad}data = bytearray(_pack({crc_const} ^ T1[b1] ^ T23[w23] ^ T45[w45] "
                     "^ T67[w67], b1, w23, w45, w67))")
        return lines

    @staticmethod
    def words(data: str, pad: str) -> str:
        """Line setting ``c, b1, w23, w45, w67`` from the 8 bytes ``data``."""
        return f"{pad}c, b1, w23, w45, w67 = _unpack({data})"

    def values(self, outs: Sequence[str], pad: str) -> list[str]:
        """Lines setting ``outs`` (names; "" skips a signal) to the physical values from
        the words; the caller checks the CRC ``c`` and the counter ``b1 & 15``."""
        lines = []
        for i, (f, out) in enumerate(zip(self.fields, outs, strict=True)):
            if not out:  # not wanted
                continue
            raw = self._signals[i]
            if f.sign_bit:
                lines.append(f"{pad}r{i} = {raw}")
                raw = f"((r{i} ^ {f.sign_bit}) - {f.sign_bit})"
            value = raw if f.scale == 1.0 else f"{raw} * {f.scale!r}"
            lines.append(f"{pad}{out} = {value if not f.offset else f'{value} + {f.offset!r}'}")
        return lines

    @staticmethod
    def crc_ok(crc_const: str) -> str:
        """Expression: the CRC byte ``c`` matches the words."""
        return f"({crc_const} ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]) == c"

    @staticmethod
    def message(pad: str, frame_id: str) -> list[str]:
        """Lines setting ``m`` to a new frame with ``frame_id``, ``stamp`` and ``data``."""
        return [f"{pad}m = _new(_Message)", f"{pad}m.arbitration_id = {frame_id}",
                *(f"{pad}m.{k} = {v!r}" for k, v in CLASSIC_FRAME_SLOTS.items()),
                f"{pad}m.timestamp = stamp", f"{pad}m.data = data"]


def _run(src: str, name: str) -> Any:
    t1, t23, t45, t67 = word_tables()
    ns: dict[str, Any] = {"T1": t1, "T23": t23, "T45": t45, "T67": t67,
                          "_pack": _STRUCT.pack, "_unpack": _STRUCT.unpack,
                          "_StructError": StructError, "_new": object.__new__,
                          "_Message": can.Message}
    exec(src, ns)  # generated from the DBC layout only
    return ns[name]


@cache
def _layout_factory(fields: tuple[_Field, ...]) -> Callable[[int, int], tuple[Callable, ...]]:
    """Generate the encode/decode functions of a payload layout (see :class:`_Layout`).

    Returns ``make(crc_const, frame_id) -> (encode, frame, decode)``, closures over the
    frame's constants: the frames of one layout (the seven command frames, the seven
    state frames) share the code, which keeps the 1 kHz cycle's working set small.
    """
    lay = _Layout(fields)
    args = [f"x{i}" for i in range(len(fields))]
    outs = [f"v{i}" for i in range(len(fields))]
    src = "\n".join([
        "def make(K, FID):",
        f"    def encode(counter, {', '.join(args)}):",
        *lay.pack(args, "counter", "K", "        "),
        "        return data",
        f"    def frame(stamp, counter, {', '.join(args)}):",
        *lay.pack(args, "counter", "K", "        "),
        *lay.message("        ", "FID"),
        "        return m",
        "    def decode(data):",
        lay.words("data", "        "),
        *lay.values(outs, "        "),
        f"        return {lay.crc_ok('K')}, b1 & 15, ({', '.join(outs)},)",
        "    return encode, frame, decode",
    ])
    return cast(Callable[[int, int], tuple[Callable, ...]], _run(src, "make"))


class FrameGroup:
    """Frames of one layout that travel together (the joints' commands, or their
    states), with generated code for the whole group in bus order.

    Parameters
    ----------
    codecs : sequence of FrameCodec
        The group's frames, in the order they are sent; all of one payload layout.

    Attributes
    ----------
    codecs : tuple of FrameCodec
    frame_ids : tuple of int
    signal_names : tuple of str
        The payload signals (as :attr:`FrameCodec.signal_names`).
    frames : callable
        ``frames(stamp, counter, *signals) -> list[can.Message]``: one frame per codec,
        each signal a sequence with one value per frame (as
        ``[c.frame(stamp, counter, *vals) for c, vals in zip(codecs, zip(*signals))]``).
    unpack_exact : callable
        ``unpack_exact(messages, counter) -> tuple or None``: if ``messages`` are
        exactly the group's frames in order, each 8 bytes with a good CRC and counter
        ``counter``, the decoded values as one tuple per signal (one value per frame);
        else None (and nothing else: the caller then looks at the frames one by one).
        :meth:`unpacker` makes one for some of the signals.
    """

    def __init__(self, codecs: Sequence[FrameCodec]) -> None:
        self.codecs = tuple(codecs)
        if not self.codecs or any(c._fields != self.codecs[0]._fields for c in self.codecs):
            raise ValueError("FrameGroup: needs frames of one payload layout")
        self.frame_ids = tuple(c.frame_id for c in self.codecs)
        self.signal_names = self.codecs[0].signal_names
        self._layout = lay = _Layout(self.codecs[0]._fields)
        n, n_sig = len(self.codecs), len(lay.fields)
        enc = [f"def frames(stamp, counter, {', '.join(f'X{i}' for i in range(n_sig))}):"]
        enc += [f"    {', '.join(f'x{i}_{j}' for j in range(n))}, = X{i}" for i in range(n_sig)]
        for j, c in enumerate(self.codecs):
            enc += lay.pack([f"x{i}_{j}" for i in range(n_sig)], "counter", str(c.crc.const), "    ")
            enc += lay.message("    ", str(c.frame_id))
            enc.append(f"    m{j} = m")
        enc.append(f"    return [{', '.join(f'm{j}' for j in range(n))}]")
        self.frames = cast(Callable[..., list[can.Message]], _run("\n".join(enc), "frames"))
        self.unpack_exact = self.unpacker()

    def unpacker(self, names: Sequence[str] | None = None
                 ) -> Callable[[Sequence[can.Message], int], tuple | None]:
        """:attr:`unpack_exact` returning only the signals ``names`` (in that order;
        default all). Every frame's CRC still covers all its bytes."""
        picked = list(self.signal_names if names is None else names)
        unknown = set(picked) - set(self.signal_names)
        if unknown:
            raise ValueError(f"FrameGroup.unpacker: no signals {sorted(unknown)}")
        lay, n = self._layout, len(self.codecs)
        outs = [f"v{i}" if name in picked else "_" for i, name in enumerate(self.signal_names)]
        dec = ["def unpack_exact(messages, counter):", "    try:",
               f"        {', '.join(f'm{j}' for j in range(n))}, = messages"]
        for j, c in enumerate(self.codecs):
            dec.append(f"        if m{j}.arbitration_id != {c.frame_id}:")
            dec.append("            return None")
            dec.append(lay.words(f"m{j}.data", "        "))
            dec.append(f"        if not {lay.crc_ok(str(c.crc.const))} or b1 & 15 != counter:")
            dec.append("            return None")
            dec += lay.values([f"{v}_{j}" if v != "_" else "" for v in outs], "        ")
        dec += ["    except (ValueError, _StructError):  # not n messages, not 8 bytes",
                "        return None",
                "    return (" + " ".join(
                    f"({', '.join(f'v{self.signal_names.index(name)}_{j}' for j in range(n))},),"
                    for name in picked) + ")"]
        return cast(Callable[[Sequence[can.Message], int], tuple | None],
                    _run("\n".join(dec), "unpack_exact"))


def _raw_expr(f: _Field, x: str) -> str:
    """Source of ``round((x - offset) / scale)``, without the no-op parts (``x - 0.0``
    and ``x / 1.0`` are ``x`` exactly, so the result is the same)."""
    y = f"({x} - {f.offset!r})" if f.offset else x
    return f"round({y})" if f.scale == 1.0 else f"round({y} / {f.scale!r})"


def _shift(x: str, n: int, op: str) -> str:
    return x if n == 0 else f"({x} {op} {n})"


@cache
def load_dbc(path: str | Path = DBC_PATH) -> cantools.database.can.Database:
    """Load (once per path) the joint-bus DBC."""
    return cast(cantools.database.can.Database, cantools.database.load_file(str(path)))


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
