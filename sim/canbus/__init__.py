"""The CAN joint bus: DBC codecs, in-process bus, drives, controller endpoint, faults.

Frames (``sim/edan_joints.dbc``): ``SYNC`` (0x080) opens every cycle; ``JointCmd_j``
(0x200 + j) carries joint j's torque command; ``JointState_j`` (0x180 + j) its
position, velocity, torque and status. Each has a CRC-8 and a 4-bit rolling counter
(:mod:`.crc`, :mod:`.link`).
"""

from .codec import (
    CMD_BASE_ID,
    MODE_ENABLE,
    STATE_BASE_ID,
    STATUS_BRAKED,
    STATUS_ENABLED,
    STATUS_SATURATED,
    STATUS_TIMEOUT,
    SYNC_ID,
    FrameCodec,
    FrameGroup,
    JointBusCodecs,
)
from .crc import FrameCrc, crc8, frame_crc
from .drives import JointDrives
from .endpoint import BusEndpoint
from .faults import FaultConfig, FaultCounts, FaultInjectingBus
from .layout import DBC_PATH, JointBusRanges, joint_bus_ranges, load_dbc
from .link import LinkStats, classify
from .master import BusMaster
from .values import BusValues, signal_rounding
from .virtual import FastVirtualBus, drain, send_batch

__all__ = [
    "CMD_BASE_ID",
    "DBC_PATH",
    "MODE_ENABLE",
    "STATE_BASE_ID",
    "STATUS_BRAKED",
    "STATUS_ENABLED",
    "STATUS_SATURATED",
    "STATUS_TIMEOUT",
    "SYNC_ID",
    "BusEndpoint",
    "BusMaster",
    "BusValues",
    "FastVirtualBus",
    "FaultConfig",
    "FaultCounts",
    "FaultInjectingBus",
    "FrameCodec",
    "FrameCrc",
    "FrameGroup",
    "JointBusCodecs",
    "JointBusRanges",
    "JointDrives",
    "LinkStats",
    "classify",
    "crc8",
    "drain",
    "frame_crc",
    "joint_bus_ranges",
    "load_dbc",
    "send_batch",
    "signal_rounding",
]
