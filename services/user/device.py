"""What the simulated user learns of the input device: how the hand moves when the
stick moves, in each mode the display shows.

A person does not know a skill's mappings, fields or constraints; they learn the
device from the robot's response to their own inputs. Here that is a linear model per
displayed mode, ``twist ~= B u`` (the hand's world-frame twist for input ``u``),
fitted by recursive least squares over the user's own input/motion pairs, forgetting
only along the direction the stick is pushed now (directional forgetting, Kulhavý 1987),
so it follows a mapping that changes with the hand's position (a vector field, a
constraint) or over time in the directions the person uses, and keeps what it saw of the
other axes. Plain exponential forgetting would let the covariance of the axes not pushed
for a while grow without bound (wind-up), and then the hand's small transient turns when
it starts or stops a translation are read as what those axes do: the model would
promise that a translation mode turns the hand, and the user would never look for the
mode that does.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


class DeviceModel:
    """``twist ~= B u`` for one displayed mode, by recursive least squares.

    Parameters
    ----------
    n_axes : int
        Input axes.
    forgetting : float
        Weight of the past per informative update along the pushed direction (0.9 at ~7
        updates/s: a memory of a couple of seconds).
    prior : float
        Initial covariance: how little the user knows before trying.
    """

    def __init__(self, n_axes: int, forgetting: float = 0.9, prior: float = 1e3):
        self.n = n_axes
        self.forgetting = forgetting
        self.B = np.zeros((6, n_axes))
        self.R = np.eye(n_axes) / prior  # information: the inverse of the covariance
        self.updates = 0
        self.tried = np.zeros(n_axes, dtype=bool)  # axes pushed clearly at least once

    def update(self, u: Array, twist: Array, min_input: float = 0.1) -> None:
        """Learn from one pair: input ``u`` (k,) held while the hand moved at ``twist``
        (6,). Pairs with (almost) no input teach nothing and are skipped, so that the
        model does not forget while the user rests."""
        if float(np.max(np.abs(u))) < min_input:
            return
        Ru = self.R @ u
        uRu = float(u @ Ru)
        if uRu > 1e-12:  # forget the old information along u only
            self.R = self.R - (1.0 - self.forgetting) * np.outer(Ru, Ru) / uRu
        self.R = self.R + np.outer(u, u)
        self.R = 0.5 * (self.R + self.R.T)
        g = np.linalg.solve(self.R, u)
        self.B += np.outer(twist - self.B @ u, g)
        self.updates += 1
        self.tried |= np.abs(u) >= 0.3

    def predict(self, u: Array) -> Array:
        """The twist the model expects for deflection ``u``."""
        return self.B @ u

    def relearn(self, prior: float = 10.0) -> None:
        """Doubt what was learned (it no longer predicts the hand): keep the estimate as
        a starting point but let new pairs overwrite it quickly, and try every axis
        again."""
        self.R = np.eye(self.n) / prior
        self.tried[:] = False

    @property
    def known(self) -> bool:
        """Every axis has been tried."""
        return bool(self.tried.all())

    def command(self, twist: Array, W: Array, effort: float = 1e-3) -> tuple[Array, float]:
        """The input (each axis in [-1, 1]) whose predicted motion comes closest to
        ``twist`` in the ``W``-weighted norm, and the fraction of the weighted error it
        leaves (1: this mode cannot help, 0: exactly what is wanted)."""
        A = W @ self.B
        b = W @ twist
        A_reg = np.vstack([A, np.sqrt(effort) * np.eye(self.n)])
        b_reg = np.concatenate([b, np.zeros(self.n)])
        u = np.linalg.lstsq(A_reg, b_reg, rcond=None)[0]
        # Where the device cannot go as fast as wanted, a person pushes the stick the
        # same way as far as it goes, rather than into a corner that also does things
        # they did not ask for.
        peak = float(np.max(np.abs(u)))
        if peak > 1.0:
            u = u / peak
        want = float(np.linalg.norm(b))
        residual = float(np.linalg.norm(A @ u - b)) / want if want > 1e-9 else 0.0
        return u, residual
