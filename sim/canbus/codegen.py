"""Generator of the fast frame codec, :mod:`._codec_generated`, from the DBC.

Run ``python -m sctd_sim.canbus.codegen`` after changing ``sim/edan_joints.dbc``: it
rewrites ``sim/canbus/_codec_generated.py`` (``--check`` only compares); a test fails
while the checked-in module differs from what the DBC gives.

What it writes, per payload layout (the SYNC frame's, the command frames', the state
frames'): ``<layout>_make(K, FID) -> (encode, frame, decode)``, closures over one
frame's CRC constant ``K`` and id ``FID`` (the seven frames of a layout share the
code, which keeps the 1 kHz cycle's working set small); and per group of frames that
travel together (``JointCmd_1..7``, ``JointState_1..7``, in bus order)
``<group>_frames`` and ``<group>_unpack`` (plus the partial unpackers of
:data:`UNPACK_SUBSETS`), with every id and CRC constant a literal.

How the code packs: the 8 data bytes are handled as ``struct`` ``"<BBHHH"``: the CRC
byte, byte 1 (counter and the low payload bits) and three 16-bit words, so every value
stays a small int; a signal is cut into its parts in these words, with the masks and
shifts as literals. The CRC is four lookups over the same words
(:func:`~.crc.word_tables`). Unrolled code with literal constants runs several times
as fast as a loop over signal descriptors; the per-frame cost matters at 15 frames per
millisecond. Values outside a signal's range saturate to the range.
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence
from pathlib import Path

from .crc import FrameCrc
from .frames import CLASSIC_FRAME_SLOTS
from .layout import DBC_PATH, Field, fields_from_message, group_name, layout_key, load_dbc

GENERATED_PATH = Path(__file__).resolve().parent / "_codec_generated.py"
"""Where the generated module is checked in."""

UNPACK_SUBSETS: dict[str, tuple[tuple[str, ...], ...]] = {"joint_cmd": (("Mode", "Torque"),)}
"""Per group (``JointCmd_j`` frames: ``joint_cmd``), the signal subsets it also gets an
unpacker for (the drives read only ``Mode`` and ``Torque`` of the commands, see
:class:`~.drives.JointDrives`)."""

_WORDS = {"b1": (8, 8), "w23": (16, 16), "w45": (32, 16), "w67": (48, 16)}
"""The words after the CRC byte: name -> (first bit, bit count)."""

_LINE = 108  # ruff's line length, 110, with room to spare


class _Layout:
    """Source snippets packing and unpacking one payload layout (see the module doc)."""

    def __init__(self, fields: tuple[Field, ...]) -> None:
        self.fields = fields
        self._words: dict[str, list[str]] = {w: [] for w in _WORDS}  # encode: parts per word
        self._signals: list[list[str]] = []  # decode: parts of each signal's raw value
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
            self._signals.append(parts)

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
            lines += _assign(pad, w, parts or ["0"], " | ")
        lines.append(f"{pad}data = bytearray(_pack({self.crc(crc_const)}, b1, w23, w45, w67))")
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
            raw = " | ".join(self._signals[i])
            if f.sign_bit:
                lines += _assign(pad, f"r{i}", self._signals[i], " | ")
                raw = f"((r{i} ^ {f.sign_bit}) - {f.sign_bit})"
            value = raw if f.scale == 1.0 else f"{raw} * {f.scale!r}"
            lines.append(f"{pad}{out} = {value if not f.offset else f'{value} + {f.offset!r}'}")
        return lines

    @staticmethod
    def crc(crc_const: str) -> str:
        """Expression: the CRC of the words."""
        return f"{crc_const} ^ T1[b1] ^ T23[w23] ^ T45[w45] ^ T67[w67]"

    @staticmethod
    def message(pad: str, name: str, frame_id: str) -> list[str]:
        """Lines setting ``name`` to a new frame with ``frame_id``, ``stamp`` and
        ``data`` (every slot, as :func:`~.frames.new_message`)."""
        return [f"{pad}{name} = _new(_Message)", f"{pad}{name}.arbitration_id = {frame_id}",
                *(f"{pad}{name}.{k} = {v!r}" for k, v in CLASSIC_FRAME_SLOTS.items()),
                f"{pad}{name}.timestamp = stamp", f"{pad}{name}.data = data"]


def _raw_expr(f: Field, x: str) -> str:
    """Source of ``round((x - offset) / scale)``, without the no-op parts (``x - 0.0``
    and ``x / 1.0`` are ``x`` exactly, so the result is the same)."""
    y = f"({x} - {f.offset!r})" if f.offset else x
    return f"round({y})" if f.scale == 1.0 else f"round({y} / {f.scale!r})"


def _shift(x: str, n: int, op: str) -> str:
    return x if n == 0 else f"({x} {op} {n})"


def _assign(pad: str, name: str, parts: Sequence[str], op: str) -> list[str]:
    """``name = part op part ...``, wrapped in parentheses over lines when too long."""
    line = f"{pad}{name} = {op.join(parts)}"
    if len(line) <= _LINE:
        return [line]
    cont = pad + " " * (len(name) + 4)
    return [f"{pad}{name} = ({parts[0]}", *(f"{cont}{op.lstrip()}{p}" for p in parts[1:-1]),
            f"{cont}{op.lstrip()}{parts[-1]})"]


def _snake(name: str) -> str:
    """``JointCmd`` -> ``joint_cmd``, ``SYNC`` -> ``sync``."""
    return re.sub(r"(?<=[a-z0-9])(?=[A-Z])", "_", name).lower()


def _signature(names: Sequence[str], annotation: str) -> str:
    return ", ".join(f"{n}: {annotation}" for n in names)


def _def(name: str, params: Sequence[str], returns: str, pad: str = "") -> list[str]:
    """``def name(params) -> returns:``, its parameters wrapped over lines when too long."""
    line = f"{pad}def {name}({', '.join(params)}) -> {returns}:"
    if len(line) <= _LINE:
        return [line]
    lines, cur = [f"{pad}def {name}("], f"{pad}        "
    for p in params:
        if len(cur) + len(p) + 2 > _LINE:
            lines.append(cur.rstrip())
            cur = f"{pad}        "
        cur += f"{p}, "
    return [*lines, cur.rstrip(), f"{pad}) -> {returns}:"]


def _layout_source(name: str, fields: tuple[Field, ...]) -> list[str]:
    """``<name>_make(K, FID)``: one frame's encode, frame and decode."""
    lay = _Layout(fields)
    args = [f"x{i}" for i in range(len(fields))]
    outs = [f"v{i}" for i in range(len(fields))]
    pad = " " * 8
    return [
        f"def {name}_make(K: int, FID: int) -> tuple[Encode, MakeFrame, Decode]:",
        f'    """Encode, frame and decode of one frame of the ``{name}`` layout: CRC constant',
        '    ``K``, id ``FID`` (see :class:`~.codec.FrameCodec`)."""',
        "",
        f"    def encode(counter: int, {_signature(args, 'float')}) -> bytearray:",
        *lay.pack(args, "counter", "K", pad),
        "        return data",
        "",
        f"    def frame(stamp: float, counter: int, {_signature(args, 'float')}) -> can.Message:",
        *lay.pack(args, "counter", "K", pad),
        *lay.message(pad, "m", "FID"),
        "        return m",
        "",
        "    def decode(data: bytes | bytearray) -> tuple[bool, int, tuple[float, ...]]:",
        lay.words("data", pad),
        *lay.values(outs, pad),
        f"        return ({lay.crc('K')}) == c, b1 & 15, ({', '.join(outs)},)",
        "",
        "    return encode, frame, decode",
    ]


def _frames_source(name: str, fields: tuple[Field, ...], ids: Sequence[int]) -> list[str]:
    """``<name>_frames(stamp, counter, *signals)``: the group's frames in bus order."""
    lay = _Layout(fields)
    n_sig = len(fields)
    sigs = [f"X{i}" for i in range(n_sig)]
    lines = [
        *_def(f"{name}_frames", ["stamp: float", "counter: int", *(f"{x}: Sequence[float]" for x in sigs)],
              "list[can.Message]"),
        f'    """The ``{name}`` frames in bus order, signal ``i`` of frame ``j`` from ``X<i>[j]``',
        f'    (ids {", ".join(map(str, ids))}; see :attr:`~.codec.FrameGroup.frames`)."""',
    ]
    lines += [f"    {', '.join(f'x{i}_{j}' for j in range(len(ids)))}, = X{i}" for i in range(n_sig)]
    for j, fid in enumerate(ids):
        lines += lay.pack([f"x{i}_{j}" for i in range(n_sig)], "counter", str(FrameCrc(fid).const),
                          "    ")
        lines += lay.message("    ", f"m{j}", str(fid))
    lines.append(f"    return [{', '.join(f'm{j}' for j in range(len(ids)))}]")
    return lines


def _unpack_source(func: str, fields: tuple[Field, ...], ids: Sequence[int],
                   picked: Sequence[str]) -> list[str]:
    """``func(messages, counter)``: the signals ``picked`` of an exact, clean group."""
    lay = _Layout(fields)
    names = [f.name for f in fields]
    outs = [f"v{i}" if name in picked else "" for i, name in enumerate(names)]
    lines = [
        f"def {func}(messages: Sequence[can.Message], counter: int) -> Unpacked:",
        f'    """``{", ".join(picked)}`` of the frames {", ".join(map(str, ids))}',
        '    if they are exactly those, in order, intact, of cycle ``counter``; else None (see',
        '    :attr:`~.codec.FrameGroup.unpack_exact`)."""',
        "    try:",
        f"        {', '.join(f'm{j}' for j in range(len(ids)))}, = messages",
    ]
    for j, fid in enumerate(ids):
        lines += [f"        if m{j}.arbitration_id != {fid}:", "            return None",
                  lay.words(f"m{j}.data", " " * 8),
                  f"        if ({lay.crc(str(FrameCrc(fid).const))}) != c or b1 & 15 != counter:",
                  "            return None",
                  *lay.values([f"{v}_{j}" if v else "" for v in outs], " " * 8)]
    lines += ["    except (ValueError, _StructError):  # not n messages, not 8 bytes",
              "        return None", "    return ("]
    for name in picked:
        lines.append(f"        ({', '.join(f'v{names.index(name)}_{j}' for j in range(len(ids)))}),")
    lines.append("    )")
    return lines


_PREAMBLE = '''"""The joint bus's fast frame codec, generated from ``{dbc}``: do not edit.

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
'''


def _layouts(dbc_path: str | Path) -> tuple[dict[str, tuple[Field, ...]],
                                             dict[str, tuple[str, list[int]]]]:
    """The DBC's layouts (name -> fields, named after their first frame or its group)
    and its groups (group name -> (layout name, frame ids in group order))."""
    layouts: dict[str, tuple[Field, ...]] = {}
    members: dict[str, list[tuple[int, str, int]]] = {}
    for msg in load_dbc(dbc_path).messages:
        fields = fields_from_message(msg)
        group = group_name(msg.name)
        name = next((k for k, v in layouts.items() if v == fields), None)
        if name is None:
            name = _snake(group[0] if group else msg.name)
            layouts[name] = fields
        if group is not None:
            members.setdefault(_snake(group[0]), []).append((group[1], name, int(msg.frame_id)))
    groups = {}
    for g, items in members.items():
        if len(items) > 1 and len({lay for _, lay, _ in items}) == 1:
            groups[g] = (items[0][1], [fid for _, _, fid in sorted(items)])
    return layouts, groups


def _group_source(group: str, layout: str, fields: tuple[Field, ...], ids: Sequence[int]
                  ) -> tuple[list[str], list[str]]:
    """A group's functions, and its entry of the ``GROUPS`` table."""
    subsets = {tuple(f.name for f in fields): f"{group}_unpack"}
    for sub in UNPACK_SUBSETS.get(group, ()):
        subsets[sub] = f"{group}_unpack_{'_'.join(_snake(s) for s in sub)}"
    lines = ["", *_frames_source(group, fields, ids), ""]
    for sub, func in subsets.items():
        lines += ["", *_unpack_source(func, fields, ids, sub), ""]
    entry = [f"    ({layout.upper()}_LAYOUT, {tuple(ids)!r}): ({group}_frames, {{",
             *(f"        {sub!r}: {func}," for sub, func in subsets.items()), "    }),"]
    return lines, entry


def module_source(dbc_path: str | Path = DBC_PATH) -> str:
    """The text of :mod:`._codec_generated` for the DBC at ``dbc_path``."""
    layouts, groups = _layouts(dbc_path)
    out = [_PREAMBLE.format(dbc=Path(dbc_path).name).rstrip("\n")]
    for name, fields in layouts.items():
        out += ["", f"{name.upper()}_LAYOUT: LayoutKey = (",
                *(f"    {f!r}," for f in layout_key(fields)), ")"]
    for name, fields in layouts.items():
        out += ["", "", *_layout_source(name, fields)]
    entries = []
    for group, (layout, ids) in groups.items():
        lines, entry = _group_source(group, layout, layouts[layout], ids)
        out += lines
        entries += entry
    out += ["", "LAYOUTS: dict[LayoutKey, Callable[[int, int], tuple[Encode, MakeFrame, Decode]]] = {",
            *(f"    {n.upper()}_LAYOUT: {n}_make," for n in layouts), "}",
            '"""Payload layout -> its ``make(K, FID)``."""', "",
            "GROUPS: dict[tuple[LayoutKey, tuple[int, ...]], GroupCode] = {",
            *entries, "}",
            '"""(layout, frame ids in bus order) -> (frames, {signal names: unpacker})."""']
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    """Write (or with ``--check`` compare) :data:`GENERATED_PATH`; exit 1 if it differed
    under ``--check``."""
    p = argparse.ArgumentParser(prog="python -m sctd_sim.canbus.codegen",
                                description="generate the joint bus's fast frame codec from the DBC")
    p.add_argument("--dbc", default=str(DBC_PATH), help="DBC file (default: the shipped one)")
    p.add_argument("--check", action="store_true",
                   help="only compare with the checked-in module; exit 1 if it differs")
    args = p.parse_args(argv)
    text = module_source(args.dbc)
    current = GENERATED_PATH.read_text() if GENERATED_PATH.exists() else None
    if args.check:
        if current != text:
            print(f"{GENERATED_PATH}: out of date (run python -m sctd_sim.canbus.codegen)",
                  file=sys.stderr)
            return 1
        return 0
    if current != text:
        GENERATED_PATH.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
