"""The open EMG device: board samples -> chain -> calibrated axes, one
:class:`~sctd_services.input.device.Reading` per bridge tick."""

from __future__ import annotations

import time

import numpy as np

from ..device import InputDevice, InputError, Reading
from .board import BoardSource
from .calibration import Calibration
from .processing import N_AXES, Chain

STALE_S = 0.5  # no sample for this long: the board is gone (read returns None)


class Processor:
    """The calibrated chain without the board: raw chunk (n, channels) -> axes (3,).

    Parameters
    ----------
    cal : Calibration
    """

    def __init__(self, cal: Calibration):
        self.cal = cal
        self.chain = Chain(cal.filters, cal.rate_hz, len(cal.channels))
        self.u = np.zeros(N_AXES)
        self.hold_n = round(cal.mapping.hold_s * cal.rate_hz)
        self.seen = 0  # samples processed
        self.zero_until = -1  # the last sample the co-contraction hold covers

    def __call__(self, raw: np.ndarray) -> np.ndarray:
        """The axes after the newest sample of ``raw`` (n >= 1, channels)."""
        a = self.cal.normalisation(self.chain.envelope(raw))
        co = np.flatnonzero(self.cal.mapping.cocontracted(a))
        if len(co):
            self.zero_until = self.seen + int(co[-1]) + self.hold_n
        self.seen += len(a)
        self.u = np.zeros(N_AXES) if self.seen - 1 <= self.zero_until else self.cal.mapping(a[-1])
        return self.u


class EmgDevice(InputDevice):
    """A calibrated EMG board as a 3-axis device without buttons.

    Parameters
    ----------
    source : BoardSource
        The streaming board (closed with the device).
    cal : Calibration
        Checked against the board: same sampling rate, channels among its rows.
    """

    buttons = 0

    def __init__(self, source: BoardSource, cal: Calibration):
        if abs(source.rate_hz - cal.rate_hz) > 1e-6:
            source.close()
            raise InputError(f"emg: the calibration is for {cal.rate_hz:g} Hz, board {source.name} "
                             f"samples at {source.rate_hz:g} Hz: calibrate on this board")
        bad = [c for c in cal.channels if not 0 <= c < source.rows]
        if bad:
            source.close()
            raise InputError(f"emg: calibration channels {bad} are not rows of board {source.name} "
                             f"(0..{source.rows - 1})")
        self.source = source
        self.name = f"emg {source.name} channels {','.join(map(str, cal.channels))}"
        self.axes = N_AXES
        self.process = Processor(cal)
        self.last_data = time.monotonic()
        self._closed = False

    def read(self) -> Reading | None:
        raw = self.source.poll(self.process.cal.channels)
        now = time.monotonic()
        if raw.shape[0]:
            self.last_data = now
            self.process(raw)
        elif now - self.last_data > STALE_S:
            return None
        return Reading(axes=tuple(float(x) for x in self.process.u), stamp=time.time())

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.source.close()
