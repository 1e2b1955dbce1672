"""Cartesian impedance controller of the simulated arm (the robot's own controller).

Torque law, per cycle, everything in world axes at the ee origin::

    e     = [p_t - p ; log(R_t R^T)]                (pose error, rotation vector)
    F     = K e + D (v_t - J dq)                    (spring, damper, velocity feed-forward)
    tau   = J^T F + N^T (k_n (q_rest - q) - d_n dq) + h(q, dq) + b dq

``h = C(q, dq) dq + g(q)`` (Pinocchio ``nonLinearEffects``) compensates gravity and
Coriolis, ``b dq`` the known viscous friction. ``N^T = I - J^T Jbar^T`` is the
dynamically consistent null-space projector with ``Jbar = M^-1 J^T Lambda`` and the
task-space inertia ``Lambda = (J M^-1 J^T + lambda^2 I)^-1``, where the damping
``lambda`` grows from 0 to ``gains.damping_max`` as the smallest singular value of
``J`` falls below ``gains.sigma_min`` (a damped pseudo-inverse, so nothing blows up
at singularities).

Damping ``D`` makes each of the six task-space modes critically damped (damping ratio
``zeta``) by double diagonalisation (Albu-Schaeffer et al., ICRA 2003): with
``Lambda = L L^T`` and ``L^-1 K L^-T = U S U^T``, ``D = 2 zeta L U S^1/2 U^T L^T``.
It is recomputed every ``gains.damping_every`` cycles (Lambda changes slowly).

Target handling: :meth:`CartesianImpedanceController.set_target` records when a target
arrived (on the controller's clock, the ``t`` of :meth:`update`). A target older than
``gains.target_timeout`` is stale: the controller then holds the pose it measured at
that moment until a new target arrives. The target velocity ``v_t`` is the
finite difference of consecutive targets over their stamps; a jump faster than
``gains.ff_max_speed`` / ``ff_max_rate`` is treated as a step (no feed-forward).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.linalg.lapack import dposv as _dposv

from .robot import ArmModel

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


@dataclass(frozen=True)
class ImpedanceGains:
    """Parameters of :class:`CartesianImpedanceController`.

    Attributes
    ----------
    k_trans : float
        Translational stiffness, N/m.
    k_rot : float
        Rotational stiffness, N m / rad.
    zeta : float
        Damping ratio of every task-space mode.
    k_null, d_null : float
        Null-space stiffness (N m / rad) towards the rest posture ``q_rest``, and damping
        (N m s / rad).
    sigma_min : float
        Smallest singular value of ``J`` below which the pseudo-inverse is damped.
    damping_max : float
        Damping ``lambda`` at a singularity.
    damping_every : int
        Cycles between recomputations of ``D`` and ``lambda``.
    target_timeout : float
        Age, s, after which a target is stale and the measured pose is held.
    feedforward : bool
        Use the target velocity in the damper.
    ff_max_speed, ff_max_rate : float
        Target motions faster than these (m/s, rad/s) are steps, not velocities.
    max_error_trans, max_error_rot : float
        Pose error saturation, m and rad (bounds the spring force).
    friction_compensation : float
        Fraction of the model's viscous friction compensated.
    """

    k_trans: float = 3000.0
    k_rot: float = 150.0
    zeta: float = 1.0
    k_null: float = 8.0
    d_null: float = 1.5
    sigma_min: float = 0.05
    damping_max: float = 0.05
    damping_every: int = 10
    target_timeout: float = 0.1
    feedforward: bool = True
    ff_max_speed: float = 1.5
    ff_max_rate: float = 3.0
    max_error_trans: float = 0.10
    max_error_rot: float = 0.6
    friction_compensation: float = 1.0


class CartesianImpedanceController:
    """Torque-level Cartesian impedance controller tracking an ee target.

    Parameters
    ----------
    arm : ArmModel
        Shared immutable model (this controller owns its ``pinocchio.Data``).
    gains : ImpedanceGains, optional
    q_rest : ndarray, shape (7,), optional
        Posture the null-space spring pulls towards; default ``arm.rest``.

    Attributes
    ----------
    T_world_ee : ndarray, shape (4, 4)
        Measured ee pose at the last :meth:`update`.
    T_world_target : ndarray, shape (4, 4)
        Target in use (the held pose while :attr:`holding`).
    v_target : ndarray, shape (6,)
        Target twist used as feed-forward.
    error : ndarray, shape (6,)
        Last pose error ``[e_p, e_r]`` (m, rad).
    holding : bool
        True while the target is stale (or none was ever given).
    tau : ndarray, shape (7,)
        Last commanded torque, N m.
    """

    def __init__(self, arm: ArmModel, gains: ImpedanceGains | None = None,
                 q_rest: np.ndarray | None = None) -> None:
        self.arm = arm
        self.q_rest = np.array(arm.rest if q_rest is None else q_rest, dtype=float)
        self.gains = gains or ImpedanceGains()
        self.model = arm.model
        self.data = arm.model.createData()
        g = self.gains
        self._k = np.array([g.k_trans] * 3 + [g.k_rot] * 3)
        self.K = np.diag(self._k)
        self.D = np.zeros((6, 6))
        self.T_world_ee = np.eye(4)
        self.T_world_target = np.eye(4)
        self.v_target = np.zeros(6)
        self.error = np.zeros(6)
        self.tau = np.zeros(arm.nq)
        self.holding = True
        self.t = 0.0
        self._rx_t = -np.inf
        self._stamp: float | None = None
        self._ff_until = -np.inf
        self._lambda2 = 0.0
        self._cycles = 0
        self._started = False
        self._eye6 = np.eye(6)
        self._friction = g.friction_compensation * arm.damping

    # -- target ----------------------------------------------------------------------
    def set_target(self, T_world_target: np.ndarray, stamp: float | None = None,
                   twist: np.ndarray | None = None) -> None:
        """Give a new ee target.

        Parameters
        ----------
        T_world_target : ndarray, shape (4, 4)
            Target ee pose in world.
        stamp : float, optional
            Sender's time of the target, s (used only for the velocity estimate;
            default: the controller clock).
        twist : ndarray, shape (6,), optional
            Target twist ``[v, w]`` (world axes); default estimated from consecutive
            targets.
        """
        T_new = np.asarray(T_world_target, dtype=float)
        stamp = self.t if stamp is None else float(stamp)
        g = self.gains
        if twist is not None:
            self.v_target = np.asarray(twist, dtype=float).copy()
            self._ff_until = self.t + g.target_timeout
        elif self._stamp is not None and not self.holding and 0.0 < stamp - self._stamp <= 0.05:
            dt = stamp - self._stamp
            v = (T_new[:3, 3] - self.T_world_target[:3, 3]) / dt
            w = pin.log3(T_new[:3, :3] @ self.T_world_target[:3, :3].T) / dt
            if v @ v <= g.ff_max_speed**2 and w @ w <= g.ff_max_rate**2:
                self.v_target = np.concatenate([v, w])
                self._ff_until = self.t + 3.0 * dt
            else:
                self.v_target = np.zeros(6)
        else:
            self.v_target = np.zeros(6)
        self.T_world_target = T_new.copy()
        self._stamp = stamp
        self._rx_t = self.t
        self.holding = False

    def hold(self) -> None:
        """Hold the last measured pose (as if the target had gone stale)."""
        self.holding = True
        self.T_world_target = self.T_world_ee.copy()
        self.v_target = np.zeros(6)
        self._stamp = None

    # -- control law -----------------------------------------------------------------
    def update(self, q: np.ndarray, dq: np.ndarray, t: float) -> np.ndarray:
        """Compute the joint torque for measured ``q`` (rad), ``dq`` (rad/s) at time ``t``.

        Returns
        -------
        ndarray, shape (7,)
            Motor torque command, N m (not yet saturated: the drives do that).
        """
        model, data, g = self.model, self.data, self.gains
        self.t = t
        pin.computeJointJacobians(model, data, q)
        T_e = self.T_world_ee = pin.updateFramePlacement(
            model, data, self.arm.ee_frame_id).homogeneous
        J = pin.getFrameJacobian(model, data, self.arm.ee_frame_id, _LWA)
        h = pin.nonLinearEffects(model, data, q, dq)
        # (``a.dot(b)`` rather than ``a @ b``: half the overhead on these tiny arrays)
        # Pinocchio >= 3 fills the whole (symmetric) inverse; tested in test_sim_dynamics.
        Minv = pin.computeMinverse(model, data, q)
        MinvJt = Minv.dot(J.T)
        if self._cycles % g.damping_every == 0:
            self._update_damping(J, MinvJt)
        self._cycles += 1

        if not self._started:
            self._started = True
            if self.holding:  # no target yet: hold where the arm is
                self.hold()
        if not self.holding and t - self._rx_t > g.target_timeout:
            self.hold()
        T_t = self.T_world_target
        e = self.error
        e[:3] = T_t[:3, 3] - T_e[:3, 3]
        e[3:] = pin.log3(T_t[:3, :3].dot(T_e[:3, :3].T))
        n_p = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
        if n_p > g.max_error_trans:
            e[:3] *= g.max_error_trans / n_p
        n_r = math.sqrt(e[3] * e[3] + e[4] * e[4] + e[5] * e[5])
        if n_r > g.max_error_rot:
            e[3:] *= g.max_error_rot / n_r
        v = -J.dot(dq)
        if g.feedforward and t <= self._ff_until:
            v += self.v_target
        F = self._k * e + self.D.dot(v)

        # null space: tau0 - J^T Jbar^T tau0 = tau0 - J^T Lambda J M^-1 tau0
        tau_null = g.k_null * (self.q_rest - q) - g.d_null * dq
        A = J.dot(MinvJt)
        A.flat[::7] += self._lambda2
        _c, y, info = _dposv(A, MinvJt.T.dot(tau_null), overwrite_a=1, overwrite_b=1)
        if info == 0:
            tau_null -= J.T.dot(y)
        else:  # not positive definite (cannot happen with damping): drop null space
            tau_null[:] = 0.0
        self.tau = J.T.dot(F) + tau_null + h + self._friction * dq
        return self.tau

    def _update_damping(self, J: np.ndarray, MinvJt: np.ndarray) -> None:
        g = self.gains
        sigma = np.sqrt(max(np.linalg.eigvalsh(J @ J.T)[0], 0.0))
        if sigma < g.sigma_min:
            self._lambda2 = (g.damping_max * (1.0 - (sigma / g.sigma_min) ** 2)) ** 2
        else:
            self._lambda2 = 0.0
        Lam = np.linalg.inv(J @ MinvJt + (self._lambda2 + 1e-9) * self._eye6)
        self.Lambda = Lam
        Lam = 0.5 * (Lam + Lam.T)
        L = np.linalg.cholesky(Lam)
        Linv = np.linalg.inv(L)
        s, U = np.linalg.eigh(Linv @ self.K @ Linv.T)
        LU = L @ U
        self.D = 2.0 * g.zeta * (LU * np.sqrt(np.maximum(s, 0.0))) @ LU.T
