"""Running a skill: the FSM with hysteresis, input mappings and active constraints.

:class:`SkillEngine` holds one skill's precomputed per-tick workspace (frame offsets,
KD-trees, the active state). The runtime calls, each tick, :meth:`SkillEngine.update`
with the measured end-effector pose (transitions) and :meth:`SkillEngine.command`
with the previous target and the user input (mappings, then constraints). Everything
is in the skill's object frame; no I/O, no clocks (time is passed in).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree

from .. import se3
from .fields import agreement, guided_direction, sigmoid
from .model import (
    Band,
    Box,
    LinearMapping,
    NeighbourOrientation,
    Skill,
    TiltCone,
    Transition,
    VectorFieldMapping,
    VectorFieldModel,
)

Array = NDArray[np.float64]


class _Neighbours:
    """KD-tree over a vector-field model's demonstration points (Ch. 4.2.5)."""

    def __init__(self, model: VectorFieldModel):
        self.model = model
        self.tree = cKDTree(model.points)
        w = np.array([f.weight for f in model.fields], dtype=float)
        self.prior = w / w.sum() if w.sum() > 0 else np.full(len(w), 1.0 / len(w))

    def query(self, p: Array, max_n: int, max_d: float) -> tuple[Array, Array]:
        """Indices and distance weights of up to ``max_n`` points within ``max_d``."""
        d, i = self.tree.query(p, k=max_n, distance_upper_bound=max_d)
        d = np.atleast_1d(d)
        i = np.atleast_1d(i)
        ok = np.isfinite(d)
        d, i = d[ok], i[ok]
        w = 1.0 / (d + 1e-3)
        return i, w / w.sum() if len(w) else w

    def membership(self, p: Array, max_n: int, max_d: float) -> Array:
        """P(F | p): neighbours' EM responsibilities, distance-weighted (the prior when
        no demonstration point is near)."""
        i, w = self.query(p, max_n, max_d)
        if len(i) == 0:
            return self.prior
        r = w @ self.model.responsibilities[i]
        s = r.sum()
        return r / s if s > 1e-12 else self.prior


Flat = tuple  # a frame as 12 floats: rotation row-major (9), then origin (3)


def _flat(rows: list[list[float]]) -> Flat:
    """The 12 floats of a 4x4 transform given as ``T.tolist()``."""
    (a, b, c, x), (d, e, f, y), (g, h, i, z) = rows[0], rows[1], rows[2]
    return (a, b, c, d, e, f, g, h, i, x, y, z)


def _floats_of(item) -> tuple:
    """The vectors a check reads, as tuples of floats (see SkillEngine._floats)."""
    if isinstance(item, Band):
        return tuple(item.normal.tolist()), tuple(item.point.tolist())
    if isinstance(item, Box):
        return tuple(item.lower.tolist()), tuple(item.upper.tolist())
    if isinstance(item, TiltCone):
        return tuple(item.axis.tolist()), tuple(item.reference.tolist()), math.cos(item.max_angle)
    if isinstance(item, Transition):
        v = item.point if item.point is not None else item.normal  # distance / hyperplane
        return () if v is None else tuple(v.tolist())
    return ()


class _Offset:
    """A fixed ee -> frame offset, applied to an ee pose on Python floats."""

    def __init__(self, T_ee_frame: Array):
        R = T_ee_frame[:3, :3]
        self.t = tuple(T_ee_frame[:3, 3].tolist())
        self.R: tuple[float, ...] | None = None if np.allclose(R, np.eye(3), atol=1e-15) \
            else tuple(R.ravel().tolist())

    def frame(self, rows: list[list[float]]) -> Flat:
        """The frame's rotation and origin for the ee pose ``rows`` (``T.tolist()``)."""
        (a, b, c, x), (d, e, f, y), (g, h, i, z) = rows[0], rows[1], rows[2]
        tx, ty, tz = self.t
        px = a * tx + b * ty + c * tz + x
        py = d * tx + e * ty + f * tz + y
        pz = g * tx + h * ty + i * tz + z
        if self.R is None:
            return (a, b, c, d, e, f, g, h, i, px, py, pz)
        r0, r1, r2, r3, r4, r5, r6, r7, r8 = self.R
        return (a * r0 + b * r3 + c * r6, a * r1 + b * r4 + c * r7, a * r2 + b * r5 + c * r8,
                d * r0 + e * r3 + f * r6, d * r1 + e * r4 + f * r7, d * r2 + e * r5 + f * r8,
                g * r0 + h * r3 + i * r6, g * r1 + h * r4 + i * r7, g * r2 + h * r5 + i * r8,
                px, py, pz)


class _LinearPlan:
    """A linear mapping prepared for the tick: the matrix's non-zero entries scaled by
    the skill's speeds, and how its frame hangs (ee, ee offset, or fixed in the object)."""

    def __init__(self, m: LinearMapping, limits, T_ee_frame: dict[str, Array],
                 T_obj_frame: dict[str, Array]):
        speed = (limits.max_linear_speed,) * 3 + (limits.max_angular_speed,) * 3
        self.rows = tuple(
            tuple((j, float(m.matrix[i, j]) * speed[i]) for j in range(m.matrix.shape[1])
                  if m.matrix[i, j] != 0.0)
            for i in range(6))
        self.in_frame = m.translation == "frame"
        self.T_ee_f = T_ee_frame.get(m.frame)  # None: the ee itself or an object frame
        self.T_obj_f = None if self.T_ee_f is not None or m.frame == "ee" else T_obj_frame[m.frame]
        self.offset = None if self.T_ee_f is None else _Offset(self.T_ee_f)
        if self.T_obj_f is not None:
            self.T_f_inv = se3.invert_transform(self.T_obj_f)
        if self.T_ee_f is not None:
            self.T_e_inv = se3.invert_transform(self.T_ee_f)

    def apply(self, T: Array, u: Sequence[float], dt: float) -> Array:
        """Algorithm 2 with the displacement convention of :mod:`sctd.se3`: rotate about
        the frame's origin and axes (``T_f Rot(r) T_f^-1 T``), then translate."""
        n = len(u)
        d = [0.0] * 6
        for i, row in enumerate(self.rows):
            for j, coeff in row:
                if j < n:
                    d[i] += coeff * u[j]
        dx, dy, dz, rx, ry, rz = d[0] * dt, d[1] * dt, d[2] * dt, d[3] * dt, d[4] * dt, d[5] * dt
        rows = T.tolist() if self.in_frame or rx or ry or rz else None
        if rx or ry or rz:
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = se3.rows_from_rotvec(rx, ry, rz)
            M = np.array([[r00, r01, r02, 0.0], [r10, r11, r12, 0.0], [r20, r21, r22, 0.0],
                          [0.0, 0.0, 0.0, 1.0]])
            if self.T_obj_f is not None:  # a frame fixed in the object: left-multiply
                out = self.T_obj_f @ M @ self.T_f_inv @ T
            else:  # a frame on the ee: T T_e Rot T_e^-1
                if self.offset is not None and self.offset.R is None:
                    tx, ty, tz = self.offset.t  # a pure translation t: [Rot, t - Rot t]
                    M[0, 3] = tx - (r00 * tx + r01 * ty + r02 * tz)
                    M[1, 3] = ty - (r10 * tx + r11 * ty + r12 * tz)
                    M[2, 3] = tz - (r20 * tx + r21 * ty + r22 * tz)
                elif self.offset is not None:
                    M = self.T_ee_f @ M @ self.T_e_inv
                out = T @ M
        else:
            out = T.copy()
        if self.in_frame:  # translation along the frame's axes (of the pose before rotating)
            assert rows is not None
            if self.T_obj_f is not None:
                F = _flat(self.T_obj_f.tolist())
            elif self.offset is not None:
                F = self.offset.frame(rows)
            else:
                F = _flat(rows)
            dx, dy, dz = (F[0] * dx + F[1] * dy + F[2] * dz, F[3] * dx + F[4] * dy + F[5] * dz,
                          F[6] * dx + F[7] * dy + F[8] * dz)
        out[0, 3] += dx
        out[1, 3] += dy
        out[2, 3] += dz
        return out


class SkillEngine:
    """Per-tick workspace of one skill: active state, frame offsets, KD-trees.

    Parameters
    ----------
    skill : Skill
        The validated skill (immutable, shared).
    """

    def __init__(self, skill: Skill):
        self.skill = skill
        self.T_ee_frame: dict[str, Array] = {}
        self.T_obj_frame: dict[str, Array] = {}
        for name, f in skill.frames.items():
            if f.parent == "ee":
                self.T_ee_frame[name] = f.T_parent_frame
            else:
                self.T_obj_frame[name] = f.T_parent_frame
        # The per-tick paths read poses through one ``tolist`` and do 3-vector math on
        # Python floats: numpy's per-call overhead dominates on 3x3 arrays.
        self._offsets = {n: _Offset(T) for n, T in self.T_ee_frame.items()}
        self._linear_plans = {}
        for state in skill.states:
            for m in state.input_mappings:
                if isinstance(m, LinearMapping):
                    self._linear_plans[id(m)] = _LinearPlan(m, skill.limits, self.T_ee_frame,
                                                            self.T_obj_frame)
        self._trees: dict[int, _Neighbours] = {}
        for state in skill.states:
            for item in (*state.input_mappings, *state.active_constraints):
                model = getattr(item, "model", None)
                if model is not None and id(model) not in self._trees:
                    self._trees[id(model)] = _Neighbours(model)
        self._out_of = [[t for t in skill.transitions if t.source == s.name] for s in skill.states]
        # Constraint and guard vectors as Python floats, for the float-level checks.
        self._floats: dict[int, tuple] = {}
        for state in skill.states:
            for c in state.active_constraints:
                self._floats[id(c)] = _floats_of(c)
        for t in skill.transitions:
            self._floats[id(t)] = _floats_of(t)
        self.index = skill.state_index(skill.start)
        self.entered = 0.0
        self.last_scale = 1.0  # the vector-field scaling of the last command, for status
        self.last_membership: Array | None = None

    # --- FSM ---------------------------------------------------------------------------

    @property
    def state(self) -> str:
        return self.skill.states[self.index].name

    @property
    def finished(self) -> bool:
        return self.state == self.skill.end

    def reset(self, now: float, state: str | None = None) -> None:
        """Enter ``state`` (default: the start state) at time ``now``."""
        self.index = self.skill.state_index(state or self.skill.start)
        self.entered = now

    def update(self, T_obj_ee: Array, now: float, force_obj: Array | None = None) -> bool:
        """Evaluate the active state's transitions on the measured pose; follow the first
        that fires. Returns True when the state changed.

        Parameters
        ----------
        T_obj_ee : ndarray, shape (4, 4)
            Measured end-effector pose in the object frame.
        now : float
            Monotonic time (s).
        force_obj : ndarray, shape (3,), optional
            Measured force at the end-effector, in the object frame (N).
        """
        if now - self.entered < self.skill.min_dwell:
            return False
        rows = None
        for t in self._out_of[self.index]:
            if t.type in ("hyperplane", "distance") and rows is None:
                rows = T_obj_ee.tolist()
            if self._fires(t, rows, now, force_obj):
                self.index = self.skill.state_index(t.target)
                self.entered = now
                return True
        return False

    def _frame_values(self, rows: list[list[float]], frame: str) -> Flat:
        """Rotation and origin (12 floats) of ``frame`` for the ee pose ``rows``."""
        off = self._offsets.get(frame)
        return _flat(rows) if off is None else off.frame(rows)

    def _fires(self, t: Transition, rows, now: float, force: Array | None) -> bool:
        if t.type == "timeout":
            return now - self.entered >= t.threshold
        if t.type == "force":
            if force is None:
                return False
            f = float(np.dot(force, t.axis)) if t.axis is not None else float(np.linalg.norm(force))
            return f > t.threshold + t.margin
        F = self._frame_values(rows, t.frame)
        v = self._floats.get(id(t)) or _floats_of(t)
        if t.type == "hyperplane":
            nx, ny, nz = v
            return nx * F[9] + ny * F[10] + nz * F[11] + t.offset > t.margin
        cx, cy, cz = v
        dx, dy, dz = F[9] - cx, F[10] - cy, F[11] - cz
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if t.direction == "below":
            return d < t.threshold - t.margin
        return d > t.threshold + t.margin

    # --- command -----------------------------------------------------------------------

    def command(self, T_obj_ee: Array, u: Array | Sequence[float], dt: float) -> Array:
        """Apply the active state's input mappings to pose ``T_obj_ee`` for input ``u``
        over ``dt`` seconds, then project onto its active constraints.

        Parameters
        ----------
        T_obj_ee : ndarray, shape (4, 4)
            The pose to move (the previous target), object frame.
        u : ndarray, shape (k,)
            User input in [-1, 1]; axes beyond what a mapping uses are ignored, missing
            axes count as zero.
        dt : float
            Tick period (s).

        Returns
        -------
        ndarray, shape (4, 4)
            The new target pose in the object frame (a new array).
        """
        state = self.skill.states[self.index]
        uu = u.tolist() if isinstance(u, np.ndarray) else u
        T = T_obj_ee
        for m in state.input_mappings:
            if isinstance(m, LinearMapping):
                T = self._linear_plans[id(m)].apply(T, uu, dt)
            else:
                T = self._vector_field(T, m, np.asarray(u, dtype=float), dt)
        F = None  # the constraint frame's values, reused while T and the frame stay
        frame = None
        for c in state.active_constraints:
            if c.frame != frame or F is None:
                F, frame = self._frame_values(T.tolist(), c.frame), c.frame
            T_next = self.project(T, c, F)
            if T_next is not T:
                T, F = T_next, None
        return T.copy() if T is T_obj_ee else T

    def _vector_field(self, T: Array, m: VectorFieldMapping, u: Array, dt: float) -> Array:
        """Algorithm 7's translation part: scale (eqs. 4.31-4.34) or blend (eq. 4.35)."""
        u3 = np.zeros(3)
        n = min(3, len(u))
        u3[:n] = u[:n]
        mag = float(np.linalg.norm(u3))
        if mag < 1e-9:
            self.last_scale = 0.0
            return T
        if mag > 1.0:
            u3 /= mag
            mag = 1.0
        unit = u3 / mag
        p = np.array(self._frame_values(T.tolist(), m.frame)[9:])
        nb = self._trees[id(m.model)]
        P = nb.membership(p, m.max_n, m.max_d)
        self.last_membership = P
        fields = m.model.fields
        if m.mode == "scale":
            if m.combine == "most_probable":
                k = int(np.argmax(P))
                s = agreement(fields[k], p, unit)
            else:
                s = sum(P[k] * agreement(f, p, unit) for k, f in enumerate(fields))
            scale = min(1.0, max(m.min_v, float(sigmoid(s, m.k_s))))
            step = u3 * scale
        else:
            bend = np.zeros(3)
            for k, f in enumerate(fields):
                bend += P[k] * guided_direction(f, p, unit)
            direction = unit + m.blend * bend
            dn = float(np.linalg.norm(direction))
            direction = direction / dn if dn > 1e-6 else unit
            step = direction * mag
            scale = 1.0
        self.last_scale = scale
        out = T.copy()
        out[:3, 3] += step * (self.skill.limits.max_linear_speed * dt)
        return out

    # --- constraints -------------------------------------------------------------------

    def frame_pose(self, T_obj_ee: Array, frame: str) -> Array:
        """Pose of an ee-attached ``frame`` (or the ee itself) for ee pose ``T_obj_ee``."""
        T_ee_f = self.T_ee_frame.get(frame)
        return T_obj_ee if T_ee_f is None else T_obj_ee @ T_ee_f

    def project(self, T: Array, c, F: Flat | None = None) -> Array:
        """Project pose T onto constraint c (moving the constrained frame minimally).

        Returns T itself (the same object) when it already satisfies c. ``F``, the
        constrained frame's rotation and origin for this T as 12 floats, may be passed
        in to save recomputing it. The checks run on Python floats; only a projection
        that moves the pose builds arrays.
        """
        if F is None:
            F = self._frame_values(T.tolist(), c.frame)
        v = self._floats.get(id(c)) or _floats_of(c)
        if isinstance(c, Band):
            (nx, ny, nz), (cx, cy, cz) = v
            s = nx * (F[9] - cx) + ny * (F[10] - cy) + nz * (F[11] - cz)
            delta = (c.lower - s) if s < c.lower else (c.upper - s) if s > c.upper else 0.0
            if delta == 0.0:
                return T
            out = T.copy()
            out[:3, 3] += delta * c.normal
            return out
        if isinstance(c, Box):
            p = F[9:]
            q = [min(max(x, lo), hi) for x, lo, hi in zip(p, *v, strict=True)]
            if q[0] == p[0] and q[1] == p[1] and q[2] == p[2]:
                return T
            out = T.copy()
            out[0, 3] += q[0] - p[0]
            out[1, 3] += q[1] - p[1]
            out[2, 3] += q[2] - p[2]
            return out
        if isinstance(c, TiltCone):
            (ax, ay, az), (rx, ry, rz), cos_max = v
            a0 = F[0] * ax + F[1] * ay + F[2] * az
            a1 = F[3] * ax + F[4] * ay + F[5] * az
            a2 = F[6] * ax + F[7] * ay + F[8] * az
            cos_a = a0 * rx + a1 * ry + a2 * rz
            if cos_a >= cos_max:
                return T
            a = np.array([a0, a1, a2])
            perp = a - cos_a * c.reference
            pn = float(np.linalg.norm(perp))
            if pn < 1e-9:  # exactly opposite: any boundary direction will do
                perp = np.cross(c.reference, [1.0, 0.0, 0.0])
                if np.linalg.norm(perp) < 1e-6:
                    perp = np.cross(c.reference, [0.0, 1.0, 0.0])
                pn = float(np.linalg.norm(perp))
            boundary = math.cos(c.max_angle) * c.reference + math.sin(c.max_angle) * perp / pn
            R_corr = se3.rotation_between(a, boundary)
            return self._rotate_about(T, F, R_corr)
        if isinstance(c, NeighbourOrientation):
            nb = self._trees[id(c.model)]
            i, w = nb.query(np.array(F[9:]), c.max_n, c.max_d)
            if len(i) == 0:
                return T
            q = c.model.quaternions[i]
            q = q * np.where(q @ q[0] < 0.0, -1.0, 1.0)[:, None]  # one hemisphere
            q_mean = w @ q
            q_mean /= np.linalg.norm(q_mean)
            R_goal = se3.matrix_from_quaternion(q_mean)
            R_f = np.array(F[:9]).reshape(3, 3)
            return self._rotate_about(T, F, R_goal @ R_f.T)
        raise TypeError(f"unknown constraint {c!r}")

    @staticmethod
    def _rotate_about(T: Array, F: Flat, R_corr: Array) -> Array:
        """Rotate pose T by R_corr (object axes) about the origin of frame F."""
        p_f = np.array(F[9:])
        out = T.copy()
        out[:3, :3] = R_corr @ T[:3, :3]
        out[:3, 3] = R_corr @ (T[:3, 3] - p_f) + p_f
        return out

    def violation(self, T: Array, c) -> float:
        """How far pose T is outside constraint c (m or rad; 0 when satisfied)."""
        T_f = self.frame_pose(T, c.frame)
        if isinstance(c, Band):
            s = float(np.dot(c.normal, T_f[:3, 3] - c.point))
            return max(0.0, c.lower - s, s - c.upper)
        if isinstance(c, Box):
            p = T_f[:3, 3]
            return float(np.linalg.norm(p - np.clip(p, c.lower, c.upper)))
        if isinstance(c, TiltCone):
            a = T_f[:3, :3] @ c.axis
            ang = math.acos(max(-1.0, min(1.0, float(np.dot(a, c.reference)))))
            return max(0.0, ang - c.max_angle)
        return 0.0
