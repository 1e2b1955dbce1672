"""Payload layouts of the joint-bus frames, read from the DBC.

The DBC (``sim/edan_joints.dbc``) is the single source of truth for ids, bit positions
and scalings; cantools loads it. A frame's payload layout is the tuple of its
:class:`Field` s (every signal after ``CRC`` and ``Counter``): what both the generated
fast codec (:mod:`.codegen`) and the cantools reference path (:mod:`.codec`) work from.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import cast

import cantools

DBC_PATH = Path(__file__).resolve().parent.parent / "edan_joints.dbc"
"""Path of the shipped joint-bus DBC."""

HEADER = ("CRC", "Counter")
"""The signals every frame starts with: CRC (bits 0-7) and rolling counter (bits 8-11)."""

LayoutKey = tuple[tuple[str, int, int, bool, float, float], ...]
"""A payload layout as plain data: per signal ``(name, start, length, signed, scale,
offset)``, the key of the generated codec's tables."""


@dataclass(frozen=True)
class Field:
    """One payload signal: little-endian, ``length`` bits from bit ``start``.

    Attributes
    ----------
    name : str
    start, length : int
        First bit and bit count.
    signed : bool
    scale, offset : float
        Physical value ``raw * scale + offset``.
    """

    name: str
    start: int
    length: int
    signed: bool
    scale: float
    offset: float

    @property
    def mask(self) -> int:
        """All ``length`` bits set."""
        return (1 << self.length) - 1

    @property
    def sign_bit(self) -> int:
        """The raw value's sign bit; 0 for an unsigned signal."""
        return (1 << (self.length - 1)) if self.signed else 0

    @property
    def raw_min(self) -> int:
        """Smallest raw value."""
        return -(1 << (self.length - 1)) if self.signed else 0

    @property
    def raw_max(self) -> int:
        """Largest raw value."""
        return (1 << (self.length - 1)) - 1 if self.signed else (1 << self.length) - 1


def fields_from_message(message: cantools.database.can.Message) -> tuple[Field, ...]:
    """The payload layout of a DBC frame, validated.

    Parameters
    ----------
    message : cantools.database.can.Message
        It must be 8 bytes, start with ``CRC`` (bits 0-7) and ``Counter`` (bits 8-11),
        and have only little-endian signals.

    Returns
    -------
    tuple of Field
        The signals after ``CRC`` and ``Counter``, in DBC order.

    Raises
    ------
    ValueError
        The frame does not fit, naming it and what is wrong.
    """
    sigs = list(message.signals)
    if message.length != 8 or [s.name for s in sigs[:2]] != list(HEADER):
        raise ValueError(f"{message.name}: need 8 bytes starting with CRC, Counter")
    if sigs[0].start != 0 or sigs[0].length != 8 or sigs[1].start != 8 or sigs[1].length != 4:
        raise ValueError(f"{message.name}: CRC must be bits 0-7 and Counter bits 8-11")
    fields = []
    for s in sigs[2:]:
        if s.byte_order != "little_endian":
            raise ValueError(f"{message.name}.{s.name}: only little-endian signals")
        fields.append(Field(name=s.name, start=s.start, length=s.length, signed=bool(s.is_signed),
                            scale=float(s.scale), offset=float(s.offset)))
    return tuple(fields)


def layout_key(fields: tuple[Field, ...]) -> LayoutKey:
    """``fields`` as plain data (see :data:`LayoutKey`)."""
    return tuple((f.name, f.start, f.length, f.signed, f.scale, f.offset) for f in fields)


def group_name(message_name: str) -> tuple[str, int] | None:
    """``("JointCmd", 3)`` for ``"JointCmd_3"``: the group a frame travels in and its
    place there; None for a frame of its own (``"SYNC"``)."""
    m = re.fullmatch(r"(.+)_(\d+)", message_name)
    return None if m is None else (m.group(1), int(m.group(2)))


@cache
def load_dbc(path: str | Path = DBC_PATH) -> cantools.database.can.Database:
    """Load (once per path) the joint-bus DBC."""
    return cast(cantools.database.can.Database, cantools.database.load_file(str(path)))


@dataclass(frozen=True)
class JointBusRanges:
    """What the joint bus carries for each joint, from the DBC's signal ranges.

    Attributes
    ----------
    n_joints : int
        Joints with both a ``JointCmd_j`` and a ``JointState_j`` frame.
    position : tuple of float
        ``(min, max)`` of a measured position (``JointState_j.Position``), rad.
    velocity : tuple of float
        ``(min, max)`` of a measured velocity (``JointState_j.Velocity``), rad/s.
    torque : tuple of float
        ``(min, max)`` of a torque both commanded and reported (the narrower of
        ``JointCmd_j.Torque`` and ``JointState_j.Torque``), N m.
    """

    n_joints: int
    position: tuple[float, float]
    velocity: tuple[float, float]
    torque: tuple[float, float]


def joint_bus_ranges(path: str | Path = DBC_PATH) -> JointBusRanges:
    """The joint count and the per-joint ranges the bus of DBC ``path`` carries (the
    intersection over its joints; a value outside is saturated when encoded)."""
    db = load_dbc(path)
    by_group: dict[str, list[cantools.database.can.Message]] = {}
    for message in db.messages:
        group = group_name(message.name)
        if group is not None:
            by_group.setdefault(group[0], []).append(message)
    cmd, state = by_group.get("JointCmd", []), by_group.get("JointState", [])

    def span(messages: list[cantools.database.can.Message], signal: str) -> tuple[float, float]:
        sigs = [m.get_signal_by_name(signal) for m in messages]
        if any(s.minimum is None or s.maximum is None for s in sigs):
            raise ValueError(f"{path}: {signal}: every joint's signal needs a [min|max] range")
        return (max(float(cast(float, s.minimum)) for s in sigs),
                min(float(cast(float, s.maximum)) for s in sigs))

    torque_cmd, torque_state = span(cmd, "Torque"), span(state, "Torque")
    return JointBusRanges(
        n_joints=min(len(cmd), len(state)),
        position=span(state, "Position"),
        velocity=span(state, "Velocity"),
        torque=(max(torque_cmd[0], torque_state[0]), min(torque_cmd[1], torque_state[1])),
    )
