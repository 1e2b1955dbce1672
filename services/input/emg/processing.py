"""The EMG chain on plain arrays, free of BrainFlow: band-pass, full-wave rectification,
envelope, normalisation by the calibrated rest and maximum contraction, and the linear
map from channel envelopes to 3 signed axes (``docs/input-emg.md``).

Everything is causal and runs chunk by chunk: each filter carries its state from one
chunk to the next, so feeding a signal in chunks of any size gives the same output as
feeding it whole.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal as sps

from .filters import Filters

N_AXES = 3

def bandpass_sos(filters: Filters, rate_hz: float) -> np.ndarray:
    """Second-order sections (n, 6) of the band-pass (and the notch when set)."""
    low, high = filters.band_hz(rate_hz)
    sos = sps.butter(filters.band_order, [low, high], btype="bandpass", fs=rate_hz, output="sos")
    if filters.notch_hz:
        if not 0.0 < filters.notch_hz < rate_hz / 2:
            raise ValueError(f"notch {filters.notch_hz:g} Hz is not below the Nyquist limit "
                             f"{rate_hz / 2:g} Hz")
        b, a = sps.iirnotch(filters.notch_hz, 30.0, fs=rate_hz)
        sos = np.vstack([sos, sps.tf2sos(b, a)])
    return np.asarray(sos)


def envelope_sos(filters: Filters, rate_hz: float) -> np.ndarray:
    """Second-order sections of the envelope's low-pass."""
    if not 0.0 < filters.envelope_hz < rate_hz / 2:
        raise ValueError(f"envelope cut-off {filters.envelope_hz:g} Hz must be in (0, {rate_hz / 2:g}) Hz")
    return np.asarray(sps.butter(filters.envelope_order, filters.envelope_hz, fs=rate_hz, output="sos"))


def group_delay_s(sos: np.ndarray, rate_hz: float, f_hz: float = 0.5) -> float:
    """Group delay (s) of the filter ``sos`` at ``f_hz`` (the envelope's: near DC, where
    the envelope of a held contraction lives). For a 2nd-order Butterworth low-pass of
    cut-off ``fc`` it is ``sqrt(2) / (2 pi fc)`` at DC."""
    b, a = sps.sos2tf(sos)
    _, gd = sps.group_delay((b, a), w=[f_hz], fs=rate_hz)
    return float(gd[0]) / rate_hz


@dataclass(frozen=True)
class Normalisation:
    """Per channel: the envelope at rest and at maximum voluntary contraction (MVC), in
    the board's units (uV for BrainFlow's EMG channels)."""

    rest: np.ndarray  # (n_channels,)
    mvc: np.ndarray  # (n_channels,)

    def __call__(self, envelope: np.ndarray) -> np.ndarray:
        """Activations (..., n_channels) in [0, 1.5]: ``(e - rest) / (mvc - rest)``."""
        return np.clip((envelope - self.rest) / (self.mvc - self.rest), 0.0, 1.5)


@dataclass(frozen=True)
class AxisMap:
    """Activations -> 3 signed axes: ``u = dz(a @ matrix + bias)``, clipped to [-1, 1].

    Attributes
    ----------
    matrix : ndarray (n_channels, 3)
    bias : ndarray (3,)
    deadzone : float
        Outputs with ``|u| <= deadzone`` are 0; above, rescaled to start from 0 at its
        edge (as the mapping file's dead band).
    cocontraction : float or None
        When every channel the matrix uses (a non-zero row) is active at least this
        much, all axes are 0 (None: no rule; the fitted matrix alone then maps
        co-contraction near zero).
    hold_s : float
        How long the co-contraction rule keeps the axes at 0 after it last held (one
        channel's envelope dipping for a moment, or the muscles relaxing at different
        speeds, must not move the arm); applied by the caller that knows the time
        (:class:`~sctd_services.input.emg.device.Processor`).
    """

    matrix: np.ndarray
    bias: np.ndarray
    deadzone: float = 0.1
    cocontraction: float | None = None
    hold_s: float = 0.3
    used: np.ndarray = field(init=False, repr=False)  # the channels with a non-zero row

    def __post_init__(self) -> None:
        object.__setattr__(self, "used", np.flatnonzero(np.any(self.matrix != 0.0, axis=1)))

    def cocontracted(self, activation: np.ndarray) -> np.ndarray:
        """Whether the co-contraction rule holds, per sample (...,) of (..., n_channels)."""
        if self.cocontraction is None:
            return np.zeros(activation.shape[:-1], dtype=bool)
        return np.asarray(np.min(activation[..., self.used], axis=-1) >= self.cocontraction)

    def __call__(self, activation: np.ndarray) -> np.ndarray:
        """Axes (..., 3) of activations (..., n_channels), the co-contraction rule applied
        sample by sample (without its hold)."""
        u = activation @ self.matrix + self.bias
        mag = np.abs(u)
        u = np.where(mag > self.deadzone, np.sign(u) * (mag - self.deadzone) / (1.0 - self.deadzone), 0.0)
        u = np.where(self.cocontracted(activation)[..., None], 0.0, u)
        return np.clip(u, -1.0, 1.0)


class Chain:
    """The causal chain ``raw (n, channels) -> envelope (n, channels)``; its state is the
    filters' (the model/data split: the designed sections are fixed, ``zi`` changes).

    Parameters
    ----------
    filters : Filters
    rate_hz : float
        The board's sampling rate.
    n_channels : int
    """

    def __init__(self, filters: Filters, rate_hz: float, n_channels: int):
        self.filters = filters
        self.rate_hz = rate_hz
        self.n_channels = n_channels
        self.band_sos = bandpass_sos(filters, rate_hz)
        self.env_sos = envelope_sos(filters, rate_hz)
        self.reset()

    def reset(self) -> None:
        """Forget the past (filters at rest)."""
        self.band_zi = np.zeros((self.band_sos.shape[0], 2, self.n_channels))
        self.env_zi = np.zeros((self.env_sos.shape[0], 2, self.n_channels))

    @property
    def envelope_delay_s(self) -> float:
        """The envelope low-pass's group delay near DC (s)."""
        return group_delay_s(self.env_sos, self.rate_hz)

    def bandpass(self, raw: np.ndarray) -> np.ndarray:
        """Band-passed ``raw`` (n, channels), state carried to the next call."""
        if raw.shape[0] == 0:
            return np.zeros((0, self.n_channels))
        y, self.band_zi = sps.sosfilt(self.band_sos, raw, axis=0, zi=self.band_zi)
        return np.asarray(y)

    def envelope(self, raw: np.ndarray) -> np.ndarray:
        """Envelope (n, channels) of ``raw`` (n, channels): band-pass, rectify, low-pass."""
        if raw.shape[0] == 0:
            return np.zeros((0, self.n_channels))
        rect = np.abs(self.bandpass(raw))
        env, self.env_zi = sps.sosfilt(self.env_sos, rect, axis=0, zi=self.env_zi)
        return np.asarray(env)


def fit_axis_map(activation: np.ndarray, target: np.ndarray, *, ridge: float = 1e-2,
                 deadzone: float = 0.1, use: np.ndarray | None = None) -> AxisMap:
    """Ridge regression of ``target`` (n, 3) on ``activation`` (n, channels) with a bias:
    ``min |A W + 1 b - Y|^2 + ridge n |W|^2`` (the bias unpenalised); channels outside
    ``use`` (a boolean mask, default all) get zero rows.

    Rest and co-contraction samples carry target 0, so the fit itself maps them near
    zero; the dead zone swallows what is left.
    """
    n, m = activation.shape
    use = np.ones(m, dtype=bool) if use is None else np.asarray(use, dtype=bool)
    a_mean, y_mean = activation[:, use].mean(axis=0), target.mean(axis=0)
    A, Y = activation[:, use] - a_mean, target - y_mean
    W = np.zeros((m, target.shape[1]))
    W[use] = np.linalg.solve(A.T @ A + ridge * n * np.eye(A.shape[1]), A.T @ Y)
    return AxisMap(matrix=W, bias=y_mean - a_mean @ W[use], deadzone=deadzone)
