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

The hand answers the stick a moment late (the daemon's tick, the arm's tracking: 10-20
ms for a translation and 20-30 ms for a turn on the simulated arm). A model that pairs
each motion with the stick held over the same moments (:class:`DeviceModel` alone)
credits part of each push to the axis pushed just before: trying the axes of a rotate
mode one after the other, it learns that each turns about the others' axes as well,
and pushing them together the turns never separate. People adapt to a delay between
their action and what they see of it (Foulkes & Miall 2000, "Adaptation to visual
feedback delays in a human manual tracking task", Exp. Brain Res. 131; Cunningham,
Billock & Tsou 2001, "Sensorimotor adaptation to violations of temporal contiguity",
Psychol. Sci. 12): :class:`DelayedDeviceModel` learns the delay with the device, one
model per candidate delay, and uses the one whose predictions came closest to what the
hand then did.
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


# A twist's error as the person judges a prediction: 0.1 m/s counts as much as 0.5 rad/s
# (the speeds a teleoperated arm's modes give).
ERROR_SCALE = np.array([10.0, 10.0, 10.0, 2.0, 2.0, 2.0])


class DelayedDeviceModel:
    """The device and its input-to-motion delay: a :class:`DeviceModel` per candidate
    delay in ``lags`` (s), each fitted to the hand's motion paired with the stick held
    that long before; the one whose predictions (made before each pair teaches it) erred
    least, exponentially weighted by ``memory`` per pair, is the person's model.

    It answers what :class:`DeviceModel` answers (``B``, ``known``, :meth:`command`...)
    with its best model; :meth:`update` takes one input per candidate delay.
    """

    def __init__(self, n_axes: int, lags: tuple[float, ...], memory: float = 0.95):
        if not lags:
            raise ValueError("lags: at least one candidate delay")
        self.n = n_axes
        self.lags = tuple(lags)
        self.models = [DeviceModel(n_axes) for _ in self.lags]
        self.errors = np.zeros(len(self.lags))  # weighted squared prediction error per candidate
        self.memory = memory
        self.best = 0

    def update(self, inputs: list[Array], twist: Array, min_input: float = 0.1) -> None:
        """Learn from the motion ``twist`` (6,) and ``inputs[k]``, the stick held
        ``lags[k]`` earlier: first score each candidate's prediction of it, then teach
        every candidate its pair."""
        if len(inputs) != len(self.models):
            raise ValueError(f"inputs: {len(inputs)} for {len(self.models)} candidate delays")
        for k, (m, u) in enumerate(zip(self.models, inputs, strict=True)):
            if m.updates and float(np.max(np.abs(u))) >= min_input:
                e = (twist - m.predict(u)) * ERROR_SCALE
                self.errors[k] = self.memory * self.errors[k] + float(e @ e)
            m.update(u, twist, min_input)
        self.best = int(np.argmin(self.errors))

    @property
    def lag(self) -> float:
        """The delay the person now expects, s."""
        return self.lags[self.best]

    @property
    def model(self) -> DeviceModel:
        return self.models[self.best]

    @property
    def B(self) -> Array:
        return self.model.B

    @property
    def updates(self) -> int:
        return self.model.updates

    @property
    def known(self) -> bool:
        return self.model.known

    def predict(self, u: Array) -> Array:
        return self.model.predict(u)

    def relearn(self, prior: float = 10.0) -> None:
        """Doubt every candidate (:meth:`DeviceModel.relearn`); the delay is kept."""
        for m in self.models:
            m.relearn(prior)

    def command(self, twist: Array, W: Array, effort: float = 1e-3) -> tuple[Array, float]:
        return self.model.command(twist, W, effort)
