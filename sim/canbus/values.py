"""The joint bus's values without its frames: what a clean cycle's frames make of a command
and a state, worked out arithmetically.

A clean cycle (every frame sent, intact, in order: what the simulated bus without faults
carries every cycle) changes the values it carries in one way only, by its fixed-point
signals: each value rounds to its signal's step and saturates to its range,

    x -> min(max(round((x - offset) / scale), raw_min), raw_max) * scale + offset

with the DBC's scale, offset and bits (:class:`~.layout.Field`): the same Python float
operations the generated codec's encoder and decoder do (``round`` of the quotient,
the clamp, the integer times the scale), so the result is bit for bit the decoded
frame's (tested over the signals' whole ranges, their halves and beyond), and a value
that cannot be encoded (NaN, infinite) raises as it does there.

:class:`~sctd_sim.arm.SimArm` with ``joint_bus=False`` hands these values to the same
:class:`~.master.BusMaster` and :class:`~.drives.JointDrives` logic (counters, timeouts,
brakes, saturation) that the frames would reach, and so comes to the same numbers as
the bus path, without packing, CRCs, frames and the virtual bus: the lockstep trials'
path.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from .codec import MODE_ENABLE, FrameCodec, JointBusCodecs
from .layout import Field

Rounding = Callable[[Sequence[float]], list[float]]


def signal_rounding(field: Field) -> Rounding:
    """``values -> values`` as the signal ``field`` carries them (module doc): a list of
    floats for a sequence of floats.

    Raises (when called)
    --------------------
    ValueError, OverflowError
        A value is NaN or infinite (as the encoder does).
    """
    s, lo, hi, off = field.scale, field.raw_min, field.raw_max, field.offset
    if off:
        return lambda xs: [(lo if (r := round((x - off) / s)) < lo else (hi if r > hi else r)) * s + off
                           for x in xs]
    return lambda xs: [(lo if (r := round(x / s)) < lo else (hi if r > hi else r)) * s for x in xs]


class BusValues:
    """The joint bus of :class:`JointBusCodecs` as values: a command's modes and torques
    as the drives decode them, a state's positions, velocities and torques as the
    controller decodes them (module doc).

    Parameters
    ----------
    codecs : JointBusCodecs
    """

    def __init__(self, codecs: JointBusCodecs) -> None:
        n = codecs.n_joints
        cmd, state = codecs.cmd[0], codecs.state[0]  # (every frame of a group has one layout)
        self._torque = _rounding(cmd, "Torque")
        self._q, self._dq, self._tau = (_rounding(state, name) for name in ("Position", "Velocity", "Torque"))
        self._modes = {True: (MODE_ENABLE,) * n, False: (0,) * n}

    def command(self, tau: np.ndarray, enable: bool) -> tuple[tuple[int, ...], list[float]]:
        """The drives' ``Mode`` and ``Torque`` of a command of torques ``tau`` (N m, shape
        (n,)) with the enable bit ``enable``."""
        return self._modes[bool(enable)], self._torque(tau.tolist())

    def state(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray
              ) -> tuple[list[float], list[float], list[float]]:
        """The controller's positions (rad), velocities (rad/s) and torques (N m) of a
        state, each shape (n,)."""
        return self._q(q.tolist()), self._dq(dq.tolist()), self._tau(tau.tolist())


def _rounding(codec: FrameCodec, name: str) -> Rounding:
    return signal_rounding(codec.field(name))
