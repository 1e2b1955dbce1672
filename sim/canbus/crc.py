"""CRC-8 SAE J1850 over a frame's id and payload, as in AUTOSAR E2E profile 1.

Every joint-bus frame carries ``CRC`` in data byte 0, computed over the 11-bit frame id
(two bytes, little-endian: the "data id", so a frame cannot pass for another id)
followed by data bytes 1..7. Polynomial 0x1D, initial value 0xFF, final xor 0xFF.
CRC-8 detects every error burst of up to 8 bits, so any single corrupted byte.

The CRC is affine in its input, which gives a cheap per-frame form: a constant per
frame id xor one table lookup per data byte position (:class:`FrameCrc`), or, with
tables over 16-bit words, four lookups per frame (:func:`word_tables`).
"""

from __future__ import annotations

from functools import cache

POLY = 0x1D
INIT = 0xFF
XOR_OUT = 0xFF


def _table() -> list[int]:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return table


_TABLE = _table()


def crc8(data: bytes | bytearray, init: int = INIT, xor_out: int = XOR_OUT) -> int:
    """CRC-8 SAE J1850 of ``data`` (reference implementation, byte-wise table)."""
    crc = init
    for b in data:
        crc = _TABLE[crc ^ b]
    return crc ^ xor_out


def frame_crc(frame_id: int, data: bytes | bytearray) -> int:
    """CRC of a joint-bus frame: over ``frame_id`` (2 bytes LE) and ``data[1:8]``."""
    return crc8(frame_id.to_bytes(2, "little") + bytes(data[1:8]))


@cache
def _linear_tables() -> list[list[int]]:
    """Per data byte position 1..7, the CRC's linear part of that byte alone (shared)."""
    tables = []
    for pos in range(7):
        row = []
        for b in range(256):
            payload = bytearray(7)
            payload[pos] = b
            # the linear part: CRC with zero init/xor of the payload placed after two
            # zero id bytes
            row.append(crc8(bytes(2) + bytes(payload), init=0, xor_out=0))
        tables.append(row)
    return tables


@cache
def word_tables() -> tuple[bytes, bytes, bytes, bytes]:
    """Tables of the CRC's linear part over data byte 1 and the 16-bit little-endian
    words of bytes 2-3, 4-5 and 6-7.

    With ``b1 = data[1]`` and ``w23, w45, w67`` those words (``struct`` format
    ``"<BBHHH"`` after the CRC byte), ``FrameCrc(id)(data) == FrameCrc(id).const ^
    t1[b1] ^ t23[w23] ^ t45[w45] ^ t67[w67]``: four lookups instead of seven, shared by
    every frame id. Built once; ``bytes`` (64 KiB per word table, where a list would
    take 512 KiB) so that they stay in the CPU's cache next to everything else a
    cycle touches.

    Returns
    -------
    t1, t23, t45, t67 : bytes
        Indexed by the byte or word, giving the CRC contribution (0..255).
    """
    t = _linear_tables()
    # entry x = lo | hi << 8 is lo's table xor hi's table: hi varies slowest
    return (bytes(t[0]),
            bytes([lo ^ hi for hi in t[2] for lo in t[1]]),
            bytes([lo ^ hi for hi in t[4] for lo in t[3]]),
            bytes([lo ^ hi for hi in t[6] for lo in t[5]]))


class FrameCrc:
    """Precomputed :func:`frame_crc` for one frame id.

    ``crc(m) = crc(id, 0...0) ^ L(m)`` with ``L`` linear, so the CRC of a frame is a
    constant xor seven lookups in per-position tables. Equal to :func:`frame_crc`
    (tested for every frame id and random payloads).

    Parameters
    ----------
    frame_id : int
        11-bit CAN identifier of the frame.
    """

    __slots__ = ("const", "t1", "t2", "t3", "t4", "t5", "t6", "t7")

    def __init__(self, frame_id: int) -> None:
        head = frame_id.to_bytes(2, "little")
        self.const = crc8(head + bytes(7))
        self.t1, self.t2, self.t3, self.t4, self.t5, self.t6, self.t7 = _linear_tables()

    def __call__(self, data: bytes | bytearray) -> int:
        """CRC over this id and ``data[1:8]`` (``data[0]``, the CRC byte, is ignored)."""
        return (
            self.const
            ^ self.t1[data[1]]
            ^ self.t2[data[2]]
            ^ self.t3[data[3]]
            ^ self.t4[data[4]]
            ^ self.t5[data[5]]
            ^ self.t6[data[6]]
            ^ self.t7[data[7]]
        )
