"""Synthetic contractions with a known answer: rest noise on every channel and, per
phase, band-limited bursts on the channels that phase drives (``docs/input-emg.md``).

BrainFlow's own synthetic board cannot be driven per channel, so the tests and the
benchmark write these samples as a playback file and run them through BrainFlow's
playback board.
"""

from __future__ import annotations

import numpy as np
from scipy import signal as sps

# which channel each single-axis phase drives; co-contraction drives them all
PHASE_CHANNELS = {"+x": [0], "-x": [1], "+y": [2], "-y": [3], "+z": [4], "-z": [5]}
REST_UV, CONTRACTION_UV, CROSSTALK = 5.0, 120.0, 0.08


def contractions(timeline: list[tuple[str, float]], rate_hz: float, n_channels: int,
                 random_state: int | np.random.Generator = 0) -> np.ndarray:
    """Samples (n, n_channels) in uV following ``timeline`` [(phase, seconds), ...].

    A phase is ``rest``, ``co-contract`` or a key of :data:`PHASE_CHANNELS`; a driven
    channel carries 30 Hz-to-0.4 fs noise of RMS ``CONTRACTION_UV`` (``CROSSTALK`` of it
    on its neighbours), every channel ``REST_UV`` of white noise.
    """
    rng = np.random.default_rng(random_state)
    sos = sps.butter(4, [30.0, 0.4 * rate_hz], btype="bandpass", fs=rate_hz, output="sos")
    parts = []
    for phase, seconds in timeline:
        n = round(seconds * rate_hz)
        gain = np.zeros(n_channels)
        driven = range(min(6, n_channels)) if phase == "co-contract" else PHASE_CHANNELS.get(phase, [])
        if phase not in PHASE_CHANNELS and phase not in ("rest", "co-contract"):
            raise ValueError(f"synthetic phase {phase!r}: rest, co-contract or one of {list(PHASE_CHANNELS)}")
        for c in driven:
            gain[c] = 1.0
            for k in (c - 1, c + 1):
                if 0 <= k < n_channels:
                    gain[k] = max(gain[k], CROSSTALK)
        burst = sps.sosfilt(sos, rng.standard_normal((n, n_channels)), axis=0)
        burst *= CONTRACTION_UV / max(float(np.std(burst)), 1e-12)
        parts.append(REST_UV * rng.standard_normal((n, n_channels)) + burst * gain)
    return np.vstack(parts)
