"""Cartesian impedance controller of the simulated arm (the robot's own controller).

Torque law, per cycle, everything in world axes at the ee origin::

    e     = [p_t - p ; log(R_t R^T)]                (pose error, rotation vector)
    F     = K e + D (v_t - J dq)                    (spring, damper, velocity feed-forward)
    tau   = J^T F + N^T (k_n sat(q_rest - q) + k_l lim(q) - d_n dq) + h(q, dq) + b dq

``h = C(q, dq) dq + g(q)`` (Pinocchio ``nonLinearEffects``) compensates gravity and
Coriolis, ``b dq`` the known viscous friction. ``sat`` bounds each joint's distance
from the rest posture at ``gains.null_error_max`` (below); ``lim`` is how far a joint is
inside ``gains.limit_margin`` of one of its limits, pushing it back out (``k_l``:
``gains.k_limit``), so that the arm's redundancy keeps its joints off their stops where
the task allows. ``N^T = I - J^T Jbar^T`` is the
dynamically consistent null-space projector with ``Jbar = M^-1 J^T Lambda`` and the
task-space inertia ``Lambda = (J M^-1 J^T + lambda^2 I)^-1``, where the damping
``lambda`` grows from 0 to ``gains.damping_max`` as the smallest singular value of
``J`` falls below ``gains.sigma_min`` (a damped pseudo-inverse, so nothing blows up
at singularities).

Why the rest posture's pull is bounded: the projector is exact only where ``J`` has
full rank and no damping. Near a singularity (a pour at full tilt brings the wrist's
middle joint to 0, where joints 5 and 7 line up) the damped ``Lambda`` lets part of
the null-space torque through to the hand, and an arm that has gone far from its rest
posture (the base turned 1.8 rad from it while carrying) pulls with tens of N m. Unbounded,
that torque swung the wrist through the singularity (joints 5 and 7 by 1.4-1.7 rad in
a second) and moved the hand 2-3 cm off a target that stood still: in a pour, the
bottle's opening off the mug's axis while it flowed. Bounded at 0.3 rad (2.4 N m at
``k_null`` 8), the same replay keeps the opening within 5 mm of the target's
(``tests/test_sim_controller.py``, the replay of a recorded pour). The same pour can
also wind joint 7 onto its stop; there the task itself may need the joint beyond it,
and the hand falls off its target whatever the null space does (1-2 cm), but where the
redundancy can keep the joint off the stop, the limit term does (a recorded case: the
opening 9 mm off its target instead of 16).

Damping ``D`` makes each of the six task-space modes critically damped (damping ratio
``zeta``) by double diagonalisation (Albu-Schaeffer et al., ICRA 2003): with
``Lambda = L L^T`` and ``L^-1 K L^-T = U S U^T``, ``D = 2 zeta L U S^1/2 U^T L^T``.
That is the symmetric positive definite solution of ``D Lambda^-1 D = 4 zeta^2 K``,
which for the diagonal ``K`` is also ``D = 2 zeta K^1/2 (K^1/2 Lambda^-1 K^1/2)^-1/2
K^1/2``: one symmetric eigen-decomposition of a 6x6 matrix, no inverse nor Cholesky
factor of ``Lambda``, which is how it is computed. It is recomputed every
``gains.damping_every`` cycles (Lambda changes slowly).

Load data: a payload set with :meth:`CartesianImpedanceController.set_payload` (mass
and centre of mass in the ee frame, as a real arm is configured with the tool and the
object it holds) has its weight compensated by a feed-forward wrench, so the arm holding
it rests at its target instead of sagging by ``m g / k``.

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
from scipy.linalg.lapack import dpotrf as _dpotrf
from scipy.linalg.lapack import dsyev as _dsyev

from .robot import ArmModel

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
GRAVITY = 9.81


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
    null_error_max : float
        Largest distance (rad) of a joint from the rest posture that the null-space
        stiffness pulls with: beyond it the pull stays ``k_null * null_error_max``
        (module doc: why).
    k_limit, limit_margin : float
        Null-space stiffness (N m / rad) pushing a joint that is within
        ``limit_margin`` (rad) of one of its limits back out of that margin.
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
    null_error_max: float = 0.3
    k_limit: float = 20.0
    limit_margin: float = 0.3
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
        self._q_inner_lo = np.asarray(arm.q_lower, dtype=float) + g.limit_margin
        self._q_inner_hi = np.asarray(arm.q_upper, dtype=float) - g.limit_margin
        self._k = np.array([g.k_trans] * 3 + [g.k_rot] * 3)
        self._k_floats = tuple(self._k.tolist())
        self.K = np.diag(self._k)
        self.D = np.zeros((6, 6))
        self.T_world_ee = np.eye(4)
        self.T_world_target = np.eye(4)
        self._target_rows = self.T_world_target.tolist()  # its rows, for the float arithmetic
        self.v_target = np.zeros(6)
        self._error = (0.0,) * 6
        self.tau = np.zeros(arm.nq)
        self.holding = True
        self.t = 0.0
        self._rx_t = -np.inf
        self._stamp: float | None = None
        self._ff_until = -np.inf
        self._lambda2 = 0.0
        self._cycles = 0
        self._started = False
        self._friction = g.friction_compensation * arm.damping
        self._ee_frame_id = arm.ee_frame_id
        self._kin_q = b""  # the q (bytes) that _kin is for
        self._kin: tuple[np.ndarray, np.ndarray] = (np.eye(4), np.zeros((6, arm.nq)))
        self._eye6 = np.eye(6)
        self._sigma2_eye6 = g.sigma_min**2 * self._eye6
        sqrt_k = np.sqrt(self._k)
        self._sqrt_k_diag = np.diag(sqrt_k)
        self._sqrt_kk = np.outer(sqrt_k, sqrt_k)
        self._payload_weight = 0.0  # m g of the configured load, N
        self._payload_com = (0.0, 0.0, 0.0)  # its centre of mass in the ee frame, m

    @property
    def error(self) -> np.ndarray:
        """Last pose error ``[e_p, e_r]`` (m, rad), shape (6,)."""
        return np.array(self._error)

    def set_payload(self, mass: float, com_in_ee) -> None:
        """Configure the load the arm holds: its weight is compensated from now on.

        Parameters
        ----------
        mass : float
            kg (0 for none).
        com_in_ee : array_like, shape (3,)
            Centre of mass in the ee frame, m.
        """
        self._payload_weight = float(mass) * GRAVITY
        # (set every cycle as the bottle empties: tolist rather than iterating an array)
        cx, cy, cz = com_in_ee.tolist() if isinstance(com_in_ee, np.ndarray) else com_in_ee
        self._payload_com = (float(cx), float(cy), float(cz))

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
        T_new = np.array(T_world_target, dtype=float)  # (a copy)
        rows = T_new.tolist()
        stamp = self.t if stamp is None else float(stamp)
        g = self.gains
        if twist is not None:
            self.v_target = np.asarray(twist, dtype=float).copy()
            self._ff_until = self.t + g.target_timeout
        elif self._stamp is not None and not self.holding and 0.0 < stamp - self._stamp <= 0.05:
            dt = stamp - self._stamp
            # on floats: [p_new - p_old, log(R_new R_old^T)] is the pose error of the old
            # target to the new one
            ex, ey, ez, w0, w1, w2 = pose_error(rows, self._target_rows)
            vx, vy, vz = ex / dt, ey / dt, ez / dt
            wx, wy, wz = w0 / dt, w1 / dt, w2 / dt
            if (vx * vx + vy * vy + vz * vz <= g.ff_max_speed**2
                    and wx * wx + wy * wy + wz * wz <= g.ff_max_rate**2):
                self.v_target = np.array((vx, vy, vz, wx, wy, wz))
                self._ff_until = self.t + 3.0 * dt
            else:
                self.v_target = np.zeros(6)
        else:
            self.v_target = np.zeros(6)
        self.T_world_target = T_new
        self._target_rows = rows
        self._stamp = stamp
        self._rx_t = self.t
        self.holding = False

    def hold_at(self, T_world_ee: np.ndarray) -> None:
        """Hold ``T_world_ee`` (the arm was put there: :meth:`SimArm.set_posture
        <sctd_sim.arm.SimArm.set_posture>`), as if it were the last measured pose."""
        self.T_world_ee = np.array(T_world_ee, dtype=float)
        self.hold()

    def hold(self) -> None:
        """Hold the last measured pose (as if the target had gone stale)."""
        self.holding = True
        self.T_world_target = self.T_world_ee.copy()
        self._target_rows = self.T_world_target.tolist()
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
        # Every Pinocchio term once, then as few array operations as the law allows:
        # at 7 joints each costs its call overhead, not its arithmetic.
        # (``a.dot(b)`` rather than ``a @ b``: half the overhead on these tiny arrays)
        model, data, g = self.model, self.data, self.gains
        self.t = t
        T_e, J = self.kinematics(q)
        self.T_world_ee = T_e
        h = pin.nonLinearEffects(model, data, q, dq)
        # Pinocchio >= 3 fills the whole (symmetric) inverse; tested in test_sim_dynamics.
        JMinv = J.dot(pin.computeMinverse(model, data, q))  # J M^-1, (6, 7)
        A = JMinv.dot(J.T)  # J M^-1 J^T = Lambda^-1 (undamped)
        if self._cycles % g.damping_every == 0:
            self._update_damping(J, A)
        self._cycles += 1

        if not self._started:
            self._started = True
            if self.holding:  # no target yet: hold where the arm is
                self.hold()
        if not self.holding and t - self._rx_t > g.target_timeout:
            self.hold()
        F = self._task_wrench(T_e, J, dq, t)

        # null space: tau0 - J^T Jbar^T tau0 = tau0 - J^T y, y = Lambda J M^-1 tau0
        tau_null = np.clip(self.q_rest - q, -g.null_error_max, g.null_error_max)
        tau_null *= g.k_null
        if g.k_limit:  # inside a limit's margin: pushed back out
            inside = np.maximum(self._q_inner_lo - q, 0.0)
            inside -= np.maximum(q - self._q_inner_hi, 0.0)
            tau_null += g.k_limit * inside
        tau_null -= g.d_null * dq
        if self._lambda2:
            A += self._lambda2 * self._eye6
        # A is symmetric: its transpose is the same matrix in Fortran order, which
        # LAPACK takes without a copy. (LAPACK arguments by position: f2py parses
        # keywords slowly; here upper triangle, overwrite A and b.)
        _c, y, info = _dposv(A.T, JMinv.dot(tau_null), 0, 1, 1)
        if info == 0:
            y0, y1, y2, y3, y4, y5 = y.tolist()  # J^T F + tau0 - J^T y
            F = [F[0] - y0, F[1] - y1, F[2] - y2, F[3] - y3, F[4] - y4, F[5] - y5]
        else:  # not positive definite (cannot happen with damping): drop null space
            tau_null[:] = 0.0
        tau = J.T.dot(np.array(F))
        tau += tau_null
        tau += h
        tau += self._friction * dq
        self.tau = tau
        return tau

    def kinematics(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``T_world_ee`` (4x4) and the ee Jacobian (6, 7; world axes at the ee) at the
        measured ``q``, computed once per ``q``: the simulator reports the pose of the
        measurement the next :meth:`update` works from. Read-only (they are shared)."""
        key = q.tobytes()
        if key != self._kin_q:
            ee = self._ee_frame_id
            J = pin.computeFrameJacobian(self.model, self.data, q, ee, _LWA)  # runs the kinematics
            T = pin.updateFramePlacement(self.model, self.data, ee).homogeneous
            T.setflags(write=False)  # (half the cost of T.flags.writeable = False)
            J.setflags(write=False)
            self._kin, self._kin_q = (T, J), key
        return self._kin

    def _task_wrench(self, T_world_ee: np.ndarray, J: np.ndarray, dq: np.ndarray, t: float
                     ) -> list[float]:
        """``F = K e + D (v_t - J dq)``, plus the payload's feed-forward (world axes at the
        ee; six floats). Sets :attr:`error`. (The products with the matrices are numpy's,
        whose rounding is BLAS's; the rest is on floats.)"""
        g = self.gains
        rows = T_world_ee.tolist()
        e0, e1, e2, e3, e4, e5 = self._saturated_error(rows)
        self._error = (e0, e1, e2, e3, e4, e5)
        v = J.dot(dq)
        if g.feedforward and t <= self._ff_until:
            v = np.subtract(self.v_target, v, out=v)
        else:
            v = np.negative(v, out=v)
        d0, d1, d2, d3, d4, d5 = self.D.dot(v).tolist()
        k0, k1, k2, k3, k4, k5 = self._k_floats
        F = [k0 * e0 + d0, k1 * e1 + d1, k2 * e2 + d2, k3 * e3 + d3, k4 * e4 + d4, k5 * e5 + d5]
        if self._payload_weight:
            self._add_payload_wrench(F, rows)
        return F

    def _saturated_error(self, rows: list[list[float]]) -> tuple[float, ...]:
        """Pose error ``[e_p, e_r]`` (m, rad; see :func:`pose_error`) to the target from the
        measured pose's rows, each part scaled down to ``gains.max_error_trans`` /
        ``max_error_rot``."""
        g = self.gains
        e0, e1, e2, e3, e4, e5 = pose_error(self._target_rows, rows)
        n_p = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
        if n_p > g.max_error_trans:
            s = g.max_error_trans / n_p
            e0, e1, e2 = s * e0, s * e1, s * e2
        n_r = math.sqrt(e3 * e3 + e4 * e4 + e5 * e5)
        if n_r > g.max_error_rot:
            s = g.max_error_rot / n_r
            e3, e4, e5 = s * e3, s * e4, s * e5
        return e0, e1, e2, e3, e4, e5

    def _add_payload_wrench(self, F: list[float], rows: list[list[float]]) -> None:
        """Add to ``F`` (6 floats, world axes at the ee) minus the load's weight
        ``(0, 0, -w)`` and its moment ``r x (0, 0, -w)``, ``r`` the centre of mass (the
        ee's rows give its orientation)."""
        w = self._payload_weight
        cx, cy, cz = self._payload_com
        (r0, r1, r2, _), (s0, s1, s2, _), _, _ = rows
        rx, ry = r0 * cx + r1 * cy + r2 * cz, s0 * cx + s1 * cy + s2 * cz
        F[2] += w
        F[3] += ry * w
        F[4] -= rx * w

    def _update_damping(self, J: np.ndarray, A: np.ndarray) -> None:
        """Null-space damping ``lambda`` from the smallest singular value of ``J``, and
        the damping matrix ``D`` from ``A = J M^-1 J^T`` (see the module docstring)."""
        g = self.gains
        # sigma_min(J) > sigma_min iff J J^T - sigma_min^2 I is positive definite: a
        # Cholesky factorisation decides that; the eigenvalue only when it fails.
        JJt = J.dot(J.T)
        JJt -= self._sigma2_eye6
        if _dpotrf(JJt, 0, 0, 1)[1] == 0:  # upper triangle, no clean-up, overwrite
            self._lambda2 = 0.0
        else:
            sigma = np.sqrt(max(np.linalg.eigvalsh(J.dot(J.T))[0], 0.0))
            if sigma < g.sigma_min:
                self._lambda2 = (g.damping_max * (1.0 - (sigma / g.sigma_min) ** 2)) ** 2
            else:
                self._lambda2 = 0.0
        # D = 2 zeta K^1/2 B^-1/2 K^1/2 with B = K^1/2 Lambda^-1 K^1/2 = P S P^T
        B = A * self._sqrt_kk
        B += (self._lambda2 + 1e-9) * self.K
        # vectors, upper triangle, default workspace (3n - 1), overwrite
        s, P, info = _dsyev(B.T, 1, 0, 17, 1)
        if info != 0:  # cannot happen for a symmetric matrix: keep the last D
            return
        KP = self._sqrt_k_diag.dot(P)
        c = 2.0 * g.zeta
        w = [c / math.sqrt(max(x, 1e-12)) for x in s.tolist()]  # B is positive definite
        self.D = (KP * w).dot(KP.T)


def pose_error(T_world_target: list[list[float]], T_world_ee: list[list[float]]
               ) -> tuple[float, float, float, float, float, float]:
    """Pose error ``[p_t - p, log(R_t R^T)]`` of two poses given as nested lists.

    Plain float arithmetic: at 1 kHz this is several times cheaper than the same on
    3x3 arrays. Equal to ``pin.log3`` to rounding (tested), whose formula it uses
    away from a half turn; within about 8 degrees of it, it calls ``pin.log3``.

    Parameters
    ----------
    T_world_target, T_world_ee : list of list of float, shape (4, 4) (or (3, 4))
        Rows of the homogeneous transforms (``ndarray.tolist()``).

    Returns
    -------
    tuple of float, length 6
        Position error (m) and rotation vector (rad), world axes.
    """
    (r0, r1, r2, px), (s0, s1, s2, py), (t0, t1, t2, pz) = T_world_ee[:3]
    (a0, a1, a2, qx), (b0, b1, b2, qy), (c0, c1, c2, qz) = T_world_target[:3]
    # R = R_t R^T: R_ij = (row i of R_t) . (row j of R)
    cos = 0.5 * (a0 * r0 + a1 * r1 + a2 * r2 + b0 * s0 + b1 * s1 + b2 * s2
                 + c0 * t0 + c1 * t1 + c2 * t2 - 1.0)
    if cos < -0.99:  # near a half turn the skew part vanishes: Pinocchio's branch
        w = pin.log3(np.dot(np.array(T_world_target)[:3, :3],
                            np.array(T_world_ee)[:3, :3].T))
        return qx - px, qy - py, qz - pz, float(w[0]), float(w[1]), float(w[2])
    theta = math.acos(cos) if cos < 1.0 else 0.0
    # theta / (2 sin theta), with its Taylor series where sin theta loses digits
    k = 0.5 * theta / math.sin(theta) if theta > 1e-4 else 0.5 + theta * theta / 12.0
    return (qx - px, qy - py, qz - pz,
            k * (c0 * s0 + c1 * s1 + c2 * s2 - b0 * t0 - b1 * t1 - b2 * t2),
            k * (a0 * t0 + a1 * t1 + a2 * t2 - c0 * r0 - c1 * r1 - c2 * r2),
            k * (b0 * r0 + b1 * r1 + b2 * r2 - a0 * s0 - a1 * s1 - a2 * s2))
