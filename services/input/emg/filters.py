"""The chain's filter parameters: one definition for the calibration file, the
``--calibrate`` flags and the chain (no scipy here, so loading the backend stays cheap)."""

from __future__ import annotations

from dataclasses import dataclass, field

BAND_TOP_HZ = 450.0  # surface EMG carries little above this
NYQUIST_MARGIN = 0.45  # the band-pass top stays below 0.45 fs


@dataclass(frozen=True)
class Filters:
    """The chain's filters; what the calibration file stores under ``filters``.

    Attributes
    ----------
    band_low_hz : float
        Band-pass low edge (motion artefacts and drift sit below ~20 Hz).
    band_high_hz : float
        Band-pass high edge; 0 picks ``min(450 Hz, 0.45 fs)``.
    band_order : int
        Butterworth order of the band-pass (per edge).
    notch_hz : float
        Mains notch (50 or 60), 0 for none.
    envelope_hz : float
        Cut-off of the envelope's Butterworth low-pass.
    envelope_order : int
        Its order.
    """

    band_low_hz: float = field(default=20.0, metadata={"metavar": "HZ", "help": "band-pass low edge, Hz"})
    band_high_hz: float = field(default=0.0, metadata={"metavar": "HZ",
        "help": "band-pass high edge, Hz (0: min(450, 0.45 x the board's rate))"})
    band_order: int = field(default=4, metadata={"metavar": "N",
                                                 "help": "band-pass Butterworth order"})
    notch_hz: float = field(default=0.0, metadata={"metavar": "HZ",
                                                   "help": "mains notch, Hz: 50 or 60 (0: none)"})
    envelope_hz: float = field(default=4.0, metadata={"metavar": "HZ",
                                                      "help": "envelope low-pass cut-off, Hz"})
    envelope_order: int = field(default=2, metadata={"metavar": "N",
                                                     "help": "envelope low-pass Butterworth order"})

    def band_hz(self, rate_hz: float) -> tuple[float, float]:
        """The band-pass edges at sampling rate ``rate_hz``; ValueError when they do not
        fit below the Nyquist limit."""
        top = NYQUIST_MARGIN * rate_hz
        high = self.band_high_hz or min(BAND_TOP_HZ, top)
        if high > top:
            raise ValueError(f"band-pass top {high:g} Hz is above 0.45 x {rate_hz:g} Hz "
                             f"(the board's Nyquist limit with a margin)")
        if not 0.0 < self.band_low_hz < high:
            raise ValueError(f"band-pass low edge {self.band_low_hz:g} Hz must be in (0, {high:g}) Hz")
        return self.band_low_hz, high
