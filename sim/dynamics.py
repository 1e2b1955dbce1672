"""Forward dynamics of the arm: ABA, semi-implicit Euler, limits, friction, brakes.

One :meth:`ArmDynamics.step` of length ``dt`` does

1. motor torque saturated at the torque limits;
2. joint torque ``tau = tau_motor - b dq + J_ee^T w_ext`` (viscous friction ``b`` from
   the URDF, external wrench ``w_ext`` at the end effector);
3. ``ddq = ABA(q, dq, tau)`` (Pinocchio, with the reflected rotor inertia);
   with braked joints, the constrained dynamics of the free joints
   ``M_ff ddq_f = tau_f - h_f`` (braked joints have ``dq = ddq = 0``);
4. semi-implicit (symplectic) Euler: ``dq += ddq dt`` then ``q += dq dt``;
5. velocity limits: ``dq`` clipped to ``+-dq_max`` (the drive's speed limiter);
6. position limits as hard inelastic stops: a joint that passes a limit is put back
   on it and its velocity towards the limit is zeroed. This never adds energy, so
   the unforced arm stays passive; ``at_limit`` flags the joints on a stop.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from .robot import ArmModel

_LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED


class ArmDynamics:
    """The simulated arm's physical state and its integrator.

    Parameters
    ----------
    arm : ArmModel
        Shared immutable model; this object owns its own ``pinocchio.Data``.
    q0 : array_like, shape (7,), optional
        Initial joint positions (rad); default the rest posture.
    friction : bool, optional
        Apply the viscous joint friction of the URDF.

    Attributes
    ----------
    q, dq, ddq : ndarray, shape (7,)
        Joint positions (rad), velocities (rad/s), accelerations (rad/s^2).
    tau_motor : ndarray, shape (7,)
        Motor torque applied in the last step, after saturation (N m).
    wrench_ext : ndarray, shape (6,)
        External wrench ``[fx, fy, fz, mx, my, mz]`` acting on the end effector,
        expressed in world axes at the ee origin (N, N m).
    at_limit : ndarray of bool, shape (7,)
        Joints that sat on a position stop after the last step.
    t : float
        Simulated time, s.
    """

    def __init__(self, arm: ArmModel, q0: np.ndarray | None = None,
                 friction: bool = True) -> None:
        self.arm = arm
        self.model = arm.model
        self.data = arm.model.createData()
        self.friction = arm.damping.copy() if friction else np.zeros(arm.nq)
        self.q = np.array(arm.rest if q0 is None else q0, dtype=float)
        if self.q.shape != (arm.nq,):
            raise ValueError(f"q0: expected shape ({arm.nq},), got {self.q.shape}")
        self.q = np.clip(self.q, arm.q_lower, arm.q_upper)
        self.dq = np.zeros(arm.nq)
        self.ddq = np.zeros(arm.nq)
        self.tau_motor = np.zeros(arm.nq)
        self.wrench_ext = np.zeros(6)
        self.at_limit = np.zeros(arm.nq, dtype=bool)
        self.t = 0.0
        self._has_wrench = False
        self._tau_min = -arm.tau_max
        self._braked = np.zeros(arm.nq, dtype=bool)
        self._any_braked = False
        self._any_at_limit = False
        self._q_hold = self.q.copy()
        self._dq_max = arm.dq_max.tolist()
        self._q_lower = arm.q_lower.tolist()
        self._q_upper = arm.q_upper.tolist()
        self._kin_q = b""  # the q (bytes) that _kin is for
        self._kin: tuple[np.ndarray, np.ndarray] = (np.eye(4), np.zeros((6, arm.nq)))

    def set_external_wrench(self, wrench: np.ndarray) -> None:
        """Set the external wrench at the ee (world axes, ee origin) for the next steps."""
        self.wrench_ext[:] = wrench
        self._has_wrench = bool(np.count_nonzero(self.wrench_ext))  # (a fifth of .any()'s cost)

    def external_torque(self) -> np.ndarray:
        """Joint torque of the external wrench, ``J_ee^T w_ext``, N m."""
        return self._kinematics()[1].T.dot(self.wrench_ext)

    def _kinematics(self) -> tuple[np.ndarray, np.ndarray]:
        """``T_world_ee`` (4x4) and the ee Jacobian (6, 7; world axes at the ee) at the
        current ``q``, computed once per ``q``: a cycle asks for them three times (the
        scene's pose and twist, the external torque) at the same posture. Read-only
        (they are shared)."""
        key = self.q.tobytes()
        if key != self._kin_q:
            # the Jacobian's kinematics give the same placement as forwardKinematics
            J = pin.computeFrameJacobian(self.model, self.data, self.q, self.arm.ee_frame_id, _LWA)
            T = pin.updateFramePlacement(self.model, self.data, self.arm.ee_frame_id).homogeneous
            T.setflags(write=False)  # (half the cost of T.flags.writeable = False)
            J.setflags(write=False)
            self._kin, self._kin_q = (T, J), key
        return self._kin

    def step(self, tau_motor: np.ndarray, dt: float, braked: np.ndarray | None = None) -> None:
        """Advance by ``dt`` seconds under motor torque ``tau_motor`` (N m, shape (7,)).

        ``braked`` (bool, shape (7,)) marks joints held by their brake: they keep the
        position they had when the brake engaged.

        ``q`` and ``dq`` are updated in place; ``tau_motor``, ``ddq`` and ``at_limit``
        are new arrays.
        """
        # (at 7 joints every array operation costs its call overhead, not its
        # arithmetic: as few as possible, and plain floats where they do)
        arm = self.arm
        q, dq = self.q, self.dq
        self.tau_motor = tau_m = np.minimum(np.maximum(tau_motor, self._tau_min), arm.tau_max)
        tau = self.friction * dq
        np.subtract(tau_m, tau, out=tau)
        if self._has_wrench:
            tau += self.external_torque()
        if braked is not None and np.count_nonzero(braked):
            self.ddq = self._braked_acceleration(tau, braked)
        else:
            if self._any_braked:
                self._braked[:] = False
                self._any_braked = False
            self.ddq = pin.aba(self.model, self.data, q, dq, tau)
        # Semi-implicit Euler, the speed limiter, then the position stops; on plain
        # floats (seven joints: one pass is cheaper than ten array operations).
        q_next, dq_next = q.tolist(), dq.tolist()
        dq_max, q_lower, q_upper = self._dq_max, self._q_lower, self._q_upper
        stopped = False
        for i, a in enumerate(self.ddq.tolist()):
            v = dq_next[i] + a * dt
            if v > dq_max[i]:
                v = dq_max[i]
            elif v < -dq_max[i]:
                v = -dq_max[i]
            x = q_next[i] + v * dt
            if x < q_lower[i] or x > q_upper[i]:
                stopped = True
            dq_next[i] = v
            q_next[i] = x
        dq[:] = dq_next
        q[:] = q_next
        if stopped:
            self._stop_at_limits()
        elif self._any_at_limit:
            self.at_limit = np.zeros(arm.nq, dtype=bool)
            self._any_at_limit = False
        self.t += dt

    def _braked_acceleration(self, tau: np.ndarray, braked: np.ndarray) -> np.ndarray:
        """Hold the ``braked`` joints (at the position they had when their brake
        engaged, at rest) and return the acceleration of the others under ``tau``."""
        q, dq = self.q, self.dq
        newly = braked & ~self._braked
        self._q_hold[newly] = q[newly]
        dq[braked] = 0.0
        q[braked] = self._q_hold[braked]
        ddq = self._constrained_acceleration(tau, braked)
        self._braked = braked.copy()
        self._any_braked = True
        return ddq

    def _stop_at_limits(self) -> None:
        """Put joints past a position limit back on it, without velocity into it."""
        arm, q, dq = self.arm, self.q, self.dq
        low = q < arm.q_lower
        high = q > arm.q_upper
        q[low] = arm.q_lower[low]
        q[high] = arm.q_upper[high]
        dq[low] = np.maximum(dq[low], 0.0)
        dq[high] = np.minimum(dq[high], 0.0)
        self.at_limit = low | high
        self._any_at_limit = True

    def _constrained_acceleration(self, tau: np.ndarray, braked: np.ndarray) -> np.ndarray:
        free = ~braked
        M = pin.crba(self.model, self.data, self.q)
        M = np.triu(M) + np.triu(M, 1).T
        h = pin.nonLinearEffects(self.model, self.data, self.q, self.dq)
        ddq = np.zeros(self.arm.nq)
        if free.any():
            ddq[free] = np.linalg.solve(M[np.ix_(free, free)], (tau - h)[free])
        return ddq

    # -- measurements ----------------------------------------------------------------
    def ee_transform(self) -> np.ndarray:
        """``T_world_ee``, shape (4, 4), at the current ``q`` (read-only)."""
        return self._kinematics()[0]

    def ee_velocity(self) -> np.ndarray:
        """End-effector twist ``[v, w]`` in world axes at the ee origin, shape (6,)."""
        return self._kinematics()[1].dot(self.dq)

    def mass_matrix(self) -> np.ndarray:
        """Joint-space inertia ``M(q)`` (with armature), shape (7, 7)."""
        M = pin.crba(self.model, self.data, self.q)
        return np.triu(M) + np.triu(M, 1).T

    def kinetic_energy(self) -> float:
        """``0.5 dq^T M(q) dq``, J (rotor inertia included)."""
        return 0.5 * float(self.dq @ self.mass_matrix() @ self.dq)

    def potential_energy(self) -> float:
        """Gravitational potential energy, J (zero at the world origin's height)."""
        return float(pin.computePotentialEnergy(self.model, self.data, self.q))

    def energy(self) -> float:
        """Total mechanical energy, J."""
        return self.kinetic_energy() + self.potential_energy()
