"""How well fields explain directions, against chance (Ch. 4.2's model selection by
likelihood, ``docs/learning.md``): a mixture of each field's direction density (a normal
spread of the deviation angle about its direction, or about its plane for a sphere,
normalised on the unit sphere) and uniformly random directions, fitted by EM.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

# Free parameters of each kind's direction model (BIC), besides its spread and share:
# a direction; an axis and a point on it (in the plane normal to it); a centre; a goal.
PARAMETERS = {"translation": 2, "cylinder": 4, "sphere": 3, "point": 3}
PLANE_KINDS = ("sphere",)  # kinds that predict a plane of directions, not one direction
LOG_4PI = math.log(4.0 * math.pi)  # -log density of a uniformly random direction


def _log_normaliser(sigma: float, plane: bool) -> float:
    """log Z of a direction density ``exp(-a^2 / (2 sigma^2)) / Z`` on the unit sphere,
    ``a`` the angle to one direction (``plane`` False: a in [0, pi], area 2 pi sin a da)
    or to a plane (True: a in [0, pi/2] either side, area 2 (2 pi cos a) da)."""
    if plane:
        a = np.linspace(0.0, math.pi / 2, 721)
        z = 4.0 * math.pi * np.trapezoid(np.exp(-0.5 * (a / sigma) ** 2) * np.cos(a), a)
    else:
        a = np.linspace(0.0, math.pi, 1441)
        z = 2.0 * math.pi * np.trapezoid(np.exp(-0.5 * (a / sigma) ** 2) * np.sin(a), a)
    return math.log(float(z))


def mixture_fit(angles: ArrayLike, planes: Sequence[bool], iterations: int = 10
                ) -> tuple[float, Array, Array, Array]:
    """How well fields' deviation ``angles`` (n, K) explain the data, against chance.

    The directions are a mixture: a share ``eps_k`` follows field k (a normal spread
    ``sigma_k`` of the angle about its direction, or about its plane when
    ``planes[k]``), the rest is uniform on the sphere; shares and spreads are fitted by
    EM. A plane takes in a band of directions, a direction only a cone: the density of
    a field that predicts less is lower, so it gains less for each direction it
    explains, whatever its inlier count.

    Returns
    -------
    log_lr : float
        Log-likelihood over the uniform-only model (nats; 0 when nothing is explained).
    eps, sigma : ndarray, shape (K,)
    responsibility : ndarray, shape (n, K)
        Each direction's probability of following each field.
    """
    a = np.asarray(angles, dtype=float)
    a = a.reshape(len(a), -1)
    n, K = a.shape
    if n == 0 or K == 0:
        return 0.0, np.zeros(K), np.zeros(K), np.zeros((n, K))
    lo, hi = math.radians(0.5), math.radians(60.0)
    close = a < math.radians(20.0)
    eps = np.clip(close.mean(axis=0) / max(1.0, float(close.mean(axis=0).sum()) / 0.95), 1e-3, 0.95)
    sigma = np.array([min(hi, max(lo, math.sqrt(float(np.mean(a[close[:, k], k] ** 2)))))
                      if close[:, k].any() else 0.3 for k in range(K)])
    dof = np.array([1.0 if pl else 2.0 for pl in planes])  # an angle to a plane has 1 dimension
    log_lr, r = 0.0, np.zeros((n, K))
    for _ in range(iterations):
        logz = np.array([_log_normaliser(float(sg), bool(pl)) for sg, pl in zip(sigma, planes, strict=True)])
        log_in = np.log(eps) - 0.5 * (a / sigma) ** 2 - logz
        log_out = math.log(max(1e-6, 1.0 - float(eps.sum()))) - LOG_4PI
        m = np.maximum(log_in.max(axis=1), log_out)
        log_mix = m + np.log(np.exp(log_in - m[:, None]).sum(axis=1) + np.exp(log_out - m))
        log_lr = float(np.sum(log_mix) + n * LOG_4PI)
        r = np.exp(log_in - log_mix[:, None])
        w = r.sum(axis=0)
        eps = np.maximum(1e-3, w / n)
        if eps.sum() > 0.999:
            eps *= 0.999 / eps.sum()
        sigma = np.clip(np.sqrt((r * a**2).sum(axis=0) / np.maximum(dof * w, 1e-12)), lo, hi)
    return log_lr, eps, sigma, r


def point_log_ratios(angles: ArrayLike, plane: bool, eps: float, sigma: float) -> Array:
    """Each direction's log-likelihood ratio (n,) under one field's mixture (share
    ``eps``, spread ``sigma``) over uniform directions."""
    a = np.asarray(angles, dtype=float)
    log_in = math.log(eps) - 0.5 * (a / sigma) ** 2 - _log_normaliser(sigma, plane)
    log_out = math.log(max(1e-6, 1.0 - eps)) - LOG_4PI
    return np.logaddexp(log_in, log_out) + LOG_4PI


def mixture_log_likelihood(angles: ArrayLike, plane: bool) -> tuple[float, float, float, Array]:
    """:func:`mixture_fit` of one field: ``(log_lr, eps, sigma, responsibility (n,))``."""
    log_lr, eps, sigma, r = mixture_fit(np.asarray(angles, dtype=float)[:, None], [plane])
    return log_lr, float(eps[0]), float(sigma[0]), r[:, 0]
