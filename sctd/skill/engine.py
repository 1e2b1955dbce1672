"""Running a skill: the FSM with hysteresis, input mappings and active constraints.

:class:`SkillEngine` holds one skill's precomputed per-tick workspace (frame offsets,
KD-trees, the active state). The runtime calls, each tick, :meth:`SkillEngine.update`
with the measured end-effector pose (transitions) and :meth:`SkillEngine.command`
with the previous target and the user input (mappings, then constraints). Everything
is in the skill's object frame; no I/O, no clocks (time is passed in).
"""

from __future__ import annotations

import math

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
        self._frame_inv = {n: se3.invert_transform(T) for n, T in self.T_ee_frame.items()}
        self._trees: dict[int, _Neighbours] = {}
        for state in skill.states:
            for item in (*state.input_mappings, *state.active_constraints):
                model = getattr(item, "model", None)
                if model is not None and id(model) not in self._trees:
                    self._trees[id(model)] = _Neighbours(model)
        self._out_of = [[t for t in skill.transitions if t.source == s.name] for s in skill.states]
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
        for t in self._out_of[self.index]:
            if self._fires(t, T_obj_ee, now, force_obj):
                self.index = self.skill.state_index(t.target)
                self.entered = now
                return True
        return False

    def _frame_position(self, T_obj_ee: Array, frame: str) -> Array:
        T = self.T_ee_frame.get(frame)
        if T is None:  # ee itself
            return T_obj_ee[:3, 3]
        return T_obj_ee[:3, :3] @ T[:3, 3] + T_obj_ee[:3, 3]

    def _fires(self, t: Transition, T_obj_ee: Array, now: float, force: Array | None) -> bool:
        if t.type == "timeout":
            return now - self.entered >= t.threshold
        if t.type == "force":
            if force is None:
                return False
            f = float(np.dot(force, t.axis)) if t.axis is not None else float(np.linalg.norm(force))
            return f > t.threshold + t.margin
        p = self._frame_position(T_obj_ee, t.frame)
        if t.type == "hyperplane":
            assert t.normal is not None
            return float(np.dot(t.normal, p)) + t.offset > t.margin
        assert t.point is not None
        dx, dy, dz = (p - t.point).tolist()
        d = math.sqrt(dx * dx + dy * dy + dz * dz)
        if t.direction == "below":
            return d < t.threshold - t.margin
        return d > t.threshold + t.margin

    # --- command -----------------------------------------------------------------------

    def command(self, T_obj_ee: Array, u: Array, dt: float) -> Array:
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
        T = T_obj_ee.copy()
        for m in state.input_mappings:
            if isinstance(m, LinearMapping):
                T = self._linear(T, m, u, dt)
            else:
                T = self._vector_field(T, m, u, dt)
        T_f = None  # pose of the constraint's frame, reused while T and the frame stay
        frame = None
        for c in state.active_constraints:
            if c.frame != frame or T_f is None:
                T_f, frame = self.frame_pose(T, c.frame), c.frame
            T_next = self.project(T, c, T_f)
            if T_next is not T:
                T, T_f = T_next, None
        return T

    def _linear(self, T: Array, m: LinearMapping, u: Array, dt: float) -> Array:
        """Algorithm 2 with the displacement convention of :mod:`sctd.se3`."""
        k = m.matrix.shape[1]
        uk = u[:k] if len(u) >= k else np.concatenate([u, np.zeros(k - len(u))])
        d6 = m.matrix @ uk
        lim = self.skill.limits
        d = d6[:3] * (lim.max_linear_speed * dt)
        r = d6[3:] * (lim.max_angular_speed * dt)
        T_ee_f = self.T_ee_frame.get(m.frame)
        if T_ee_f is not None:
            T_f = T @ T_ee_f
        elif m.frame == "ee":
            T_f = T
        else:
            T_f = self.T_obj_frame[m.frame]
        if m.translation == "frame":
            d = T_f[:3, :3] @ d
        out = T.copy()
        if r.any():
            # Rotate about the frame's origin and axes: T_f Rot(r) T_f^-1 T.
            R_f = T_f[:3, :3]
            R_w = R_f @ se3.matrix3_from_rotvec(float(r[0]), float(r[1]), float(r[2])) @ R_f.T
            out[:3, :3] = R_w @ T[:3, :3]
            out[:3, 3] = R_w @ (T[:3, 3] - T_f[:3, 3]) + T_f[:3, 3]
        out[:3, 3] += d
        return out

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
        p = self._frame_position(T, m.frame)
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

    def project(self, T: Array, c, T_f: Array | None = None) -> Array:
        """Project pose T onto constraint c (moving the constrained frame minimally).

        Returns T itself (the same object) when it already satisfies c. ``T_f``, the
        constrained frame's pose for this T, may be passed in to save recomputing it.
        """
        if T_f is None:
            T_f = self.frame_pose(T, c.frame)
        if isinstance(c, Band):
            s = float(np.dot(c.normal, T_f[:3, 3] - c.point))
            delta = (c.lower - s) if s < c.lower else (c.upper - s) if s > c.upper else 0.0
            if delta == 0.0:
                return T
            out = T.copy()
            out[:3, 3] += delta * c.normal
            return out
        if isinstance(c, Box):
            p = T_f[:3, 3]
            q = np.minimum(np.maximum(p, c.lower), c.upper)
            if np.array_equal(p, q):
                return T
            out = T.copy()
            out[:3, 3] += q - p
            return out
        if isinstance(c, TiltCone):
            a = T_f[:3, :3] @ c.axis
            cos_a = float(np.dot(a, c.reference))
            if cos_a >= math.cos(c.max_angle):
                return T
            perp = a - cos_a * c.reference
            pn = float(np.linalg.norm(perp))
            if pn < 1e-9:  # exactly opposite: any boundary direction will do
                perp = np.cross(c.reference, [1.0, 0.0, 0.0])
                if np.linalg.norm(perp) < 1e-6:
                    perp = np.cross(c.reference, [0.0, 1.0, 0.0])
                pn = float(np.linalg.norm(perp))
            boundary = math.cos(c.max_angle) * c.reference + math.sin(c.max_angle) * perp / pn
            R_corr = se3.rotation_between(a, boundary)
            return self._rotate_about(T, T_f, R_corr)
        if isinstance(c, NeighbourOrientation):
            nb = self._trees[id(c.model)]
            i, w = nb.query(T_f[:3, 3], c.max_n, c.max_d)
            if len(i) == 0:
                return T
            q = c.model.quaternions[i]
            q = q * np.where(q @ q[0] < 0.0, -1.0, 1.0)[:, None]  # one hemisphere
            q_mean = w @ q
            q_mean /= np.linalg.norm(q_mean)
            R_goal = se3.matrix_from_quaternion(q_mean)
            return self._rotate_about(T, T_f, R_goal @ T_f[:3, :3].T)
        raise TypeError(f"unknown constraint {c!r}")

    @staticmethod
    def _rotate_about(T: Array, T_f: Array, R_corr: Array) -> Array:
        """Rotate pose T by R_corr (object axes) about the origin of frame pose T_f."""
        out = T.copy()
        out[:3, :3] = R_corr @ T[:3, :3]
        out[:3, 3] = R_corr @ (T[:3, 3] - T_f[:3, 3]) + T_f[:3, 3]
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
