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
from .fields import agreement3, guided_direction, sigmoid
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


# A neighbour query is reused while the frame stays this close to where it was made: well
# below the spacing of the demonstrations' points (sampled at 50 Hz, 1-2 mm apart at the
# demonstrated speeds), so the field does not change for it, and at the speed limits a
# KD-tree query then runs every few ticks rather than every tick.
REUSE_DISTANCE = 5e-4  # m
REUSE_ANGLE = 5e-3  # rad (pose queries)


class _Neighbours:
    """KD-tree over a vector-field model's demonstration points (Ch. 4.2.5), with the
    last answer to each kind of query kept for reuse (see ``REUSE_DISTANCE``)."""

    def __init__(self, model: VectorFieldModel):
        self.model = model
        self.tree = cKDTree(model.points)
        w = np.array([f.weight for f in model.fields], dtype=float)
        self.prior = w / w.sum() if w.sum() > 0 else np.full(len(w), 1.0 / len(w))
        self._last: dict[tuple, tuple] = {}
        self.queries = 0  # KD-tree queries made (the rest were reused)

    def _reuse(self, key: tuple, p: Array, q: Sequence[float] | None = None):
        """The kept answer for ``key`` if it was made within the reuse distance (and
        angle) of position ``p`` (and quaternion ``q``), else None."""
        last = self._last.get(key)
        if last is None:
            return None
        (x, y, z), q_last, answer = last
        px, py, pz = p.tolist()
        if (px - x) ** 2 + (py - y) ** 2 + (pz - z) ** 2 > REUSE_DISTANCE ** 2:
            return None
        if q is not None:
            c = abs(q[0] * q_last[0] + q[1] * q_last[1] + q[2] * q_last[2] + q[3] * q_last[3])
            if 2.0 * math.acos(min(1.0, c)) > REUSE_ANGLE:
                return None
        return answer

    def _keep(self, key: tuple, p: Array, q: Sequence[float] | None, answer):
        self._last[key] = (tuple(p.tolist()), q, answer)
        self.queries += 1
        return answer

    def query(self, p: Array, max_n: int, max_d: float) -> tuple[Array, Array]:
        """Indices and distance weights of up to ``max_n`` points within ``max_d``."""
        key = ("query", max_n, max_d)
        answer = self._reuse(key, p)
        return answer if answer is not None else self._keep(key, p, None, self._query(p, max_n, max_d))

    def _query(self, p: Array, max_n: int, max_d: float) -> tuple[Array, Array]:
        d, i = self.tree.query(p, k=max_n, distance_upper_bound=max_d)
        d = np.atleast_1d(d)
        i = np.atleast_1d(i)
        ok = np.isfinite(d)
        d, i = d[ok], i[ok]
        w = 1.0 / (d + 1e-3)
        return i, w / w.sum() if len(w) else w

    def query_pose(self, p: Array, q: Sequence[float], max_n: int, max_d: float,
                   rotation_weight: float) -> tuple[Array, Array]:
        """Like :meth:`query`, but the ``max_n`` nearest in pose: of the points within
        ``max_d`` (at most ``POSE_CANDIDATES * max_n`` of them), those with the smallest
        ``sqrt(|dp|^2 + (rotation_weight * angle)^2)`` to position ``p`` and unit
        quaternion ``q`` [x, y, z, w]."""
        key = ("pose", max_n, max_d, rotation_weight)
        answer = self._reuse(key, p, q)
        if answer is None:
            answer = self._keep(key, p, tuple(q), self._query_pose(p, q, max_n, max_d, rotation_weight))
        return answer

    def _query_pose(self, p: Array, q: Sequence[float], max_n: int, max_d: float,
                    rotation_weight: float) -> tuple[Array, Array]:
        d, i = self.tree.query(p, k=POSE_CANDIDATES * max_n, distance_upper_bound=max_d)
        d, i = np.atleast_1d(d), np.atleast_1d(i)
        ok = np.isfinite(d)
        d, i = d[ok], i[ok]
        if len(i) == 0:
            return i, d
        c = np.abs(self.model.quaternions[i] @ np.asarray(q, dtype=float))
        angle = 2.0 * np.arccos(np.clip(c, 0.0, 1.0))
        dist = np.sqrt(d * d + (rotation_weight * angle) ** 2)
        best = np.argsort(dist, kind="stable")[:max_n]
        w = 1.0 / (dist[best] + 1e-3)
        return i[best], w / w.sum()

    def membership(self, p: Array, max_n: int, max_d: float) -> Array:
        """P(F | p): neighbours' EM responsibilities, distance-weighted (the prior when
        no demonstration point is near)."""
        key = ("membership", max_n, max_d)
        answer = self._reuse(key, p)
        return answer if answer is not None else self._keep(key, p, None, self._membership(p, max_n, max_d))

    def _membership(self, p: Array, max_n: int, max_d: float) -> Array:
        i, w = self._query(p, max_n, max_d)
        if len(i) == 0:
            return self.prior
        r = w @ self.model.responsibilities[i]
        s = r.sum()
        return r / s if s > 1e-12 else self.prior


Flat = se3.Flat
POSE_CANDIDATES = 8  # points within max_d a pose query ranks, per neighbour it keeps
INTENT_PRIOR = 0.1  # share of the fields' weights mixed into P(F | p) before the command's evidence


def intent_membership(P: Array, prior: Array, s: Sequence[float], kappa: float) -> Array:
    """``P(F | p, u)``: the position's membership ``P`` (mixed with ``INTENT_PRIOR`` of
    the fields' weights ``prior``, so that no field is ruled out by position alone)
    times each field's agreement with the command, ``exp(kappa * s_F)``, normalised."""
    post = ((1.0 - INTENT_PRIOR) * P + INTENT_PRIOR * prior) * np.exp(kappa * (np.asarray(s) - 1.0))
    total = float(post.sum())
    return post / total if total > 1e-300 else P


Rows9 = tuple[float, float, float, float, float, float, float, float, float]


def _matrix_of_quaternion(x: float, y: float, z: float, w: float) -> Rows9:
    """Row-major rotation matrix of the unit quaternion (x, y, z, w), as nine floats."""
    return (1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w),
            2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w),
            2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y))


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
    """A fixed ee -> frame offset, applied to a flat ee pose."""

    def __init__(self, T_ee_frame: Array):
        R = T_ee_frame[:3, :3]
        self.t = tuple(T_ee_frame[:3, 3].tolist())
        self.R: tuple[float, ...] | None = None if np.allclose(R, np.eye(3), atol=1e-15) \
            else tuple(R.ravel().tolist())
        self.flat = se3.flat_from_matrix4(T_ee_frame)

    def frame(self, F: Flat) -> Flat:
        """The frame's pose for the ee pose F."""
        if self.R is not None:
            return se3.compose_flat(F, self.flat)
        a, b, c, d, e, f, g, h, i, x, y, z = F
        tx, ty, tz = self.t
        return (a, b, c, d, e, f, g, h, i, a * tx + b * ty + c * tz + x,
                d * tx + e * ty + f * tz + y, g * tx + h * ty + i * tz + z)


def _rotation(r00: float, r01: float, r02: float, r10: float, r11: float, r12: float,
              r20: float, r21: float, r22: float, px: float, py: float, pz: float) -> Flat:
    """The rotation R (row-major) about the point p, as a flat transform [R, p - R p]."""
    return (r00, r01, r02, r10, r11, r12, r20, r21, r22,
            px - (r00 * px + r01 * py + r02 * pz), py - (r10 * px + r11 * py + r12 * pz),
            pz - (r20 * px + r21 * py + r22 * pz))


def _input_axes(mappings) -> tuple[int, ...]:
    """The input axes a state's mappings read: the non-zero columns of linear mappings,
    the first three for vector fields (a translation command)."""
    axes: set[int] = set()
    for m in mappings:
        if isinstance(m, LinearMapping):
            axes.update(j for j in range(m.matrix.shape[1]) if np.any(m.matrix[:, j] != 0.0))
        else:
            axes.update((0, 1, 2))
    return tuple(sorted(axes))


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
        self.rotate_in_object = m.rotation == "object"
        T_ee_f = T_ee_frame.get(m.frame)  # None: the ee itself or an object frame
        self.offset = None if T_ee_f is None else _Offset(T_ee_f)
        self.obj_frame: Flat | None = None  # a frame fixed in the object
        if T_ee_f is None and m.frame != "ee":
            self.obj_frame = se3.flat_from_matrix4(T_obj_frame[m.frame])
            self.obj_frame_inv = se3.invert_flat(self.obj_frame)

    def apply(self, F: Flat, u: Sequence[float], dt: float) -> Flat:
        """Algorithm 2 with the displacement convention of :mod:`sctd.se3` on the flat ee
        pose F: rotate about the frame's origin and axes (``T_f Rot(r) T_f^-1 T``), then
        translate (in the object's axes, or the frame's before the rotation)."""
        n = len(u)
        d = [0.0] * 6
        for i, row in enumerate(self.rows):
            for j, coeff in row:
                if j < n:
                    d[i] += coeff * u[j]
        dx, dy, dz, rx, ry, rz = d[0] * dt, d[1] * dt, d[2] * dt, d[3] * dt, d[4] * dt, d[5] * dt
        if self.obj_frame is not None:
            frame = self.obj_frame
        elif self.offset is not None:
            frame = self.offset.frame(F)
        else:
            frame = F
        out = F
        if rx or ry or rz:
            rot = se3.rows_from_rotvec(rx, ry, rz)
            if self.rotate_in_object:  # about the frame's origin, around the object's axes
                out = se3.compose_flat(_rotation(*rot, *frame[9:]), F)
            elif self.obj_frame is not None:  # T_f Rot T_f^-1 T, T_f fixed in the object
                M = se3.compose_flat(se3.compose_flat(frame, (*rot, 0.0, 0.0, 0.0)), self.obj_frame_inv)
                out = se3.compose_flat(M, F)
            elif self.offset is not None and self.offset.R is None:  # T [Rot about t]
                out = se3.compose_flat(F, _rotation(*rot, *self.offset.t))
            elif self.offset is not None:  # T T_e Rot T_e^-1
                T_e = self.offset.flat
                M = se3.compose_flat(se3.compose_flat(T_e, (*rot, 0.0, 0.0, 0.0)), se3.invert_flat(T_e))
                out = se3.compose_flat(F, M)
            else:  # about the ee itself
                out = se3.compose_flat(F, (*rot, 0.0, 0.0, 0.0))
        if self.in_frame:
            dx, dy, dz = (frame[0] * dx + frame[1] * dy + frame[2] * dz,
                          frame[3] * dx + frame[4] * dy + frame[5] * dz,
                          frame[6] * dx + frame[7] * dy + frame[8] * dz)
        return (*out[:9], out[9] + dx, out[10] + dy, out[11] + dz)


RIGID_MIN_RADIUS = 0.02  # m: closer to a field's centre or axis than this, no turning
RIGID_FULL = 0.035  # m: a field's pivot turns the hand fully within this of the field's
RIGID_REACH = 0.07  # centre or axis, not at all this far from it (not brought there yet)


def _norm3(v: Array) -> float:
    x, y, z = v.tolist()
    return math.sqrt(x * x + y * y + z * z)


def _cross3(a: Array, b: Array) -> Array:
    ax, ay, az = a.tolist()
    bx, by, bz = b.tolist()
    return np.array([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx])


def _rodrigues(w: Array) -> Array:
    """The rotation matrix of rotation vector ``w`` (Rodrigues' formula, on floats)."""
    x, y, z = w.tolist()
    th = math.sqrt(x * x + y * y + z * z)
    if th < 1e-12:
        return np.eye(3)
    kx, ky, kz = x / th, y / th, z / th
    c, s = math.cos(th), math.sin(th)
    v = 1.0 - c
    return np.array([[c + kx * kx * v, kx * ky * v - kz * s, kx * kz * v + ky * s],
                     [ky * kx * v + kz * s, c + ky * ky * v, ky * kz * v - kx * s],
                     [kz * kx * v - ky * s, kz * ky * v + kx * s, c + kz * kz * v]])


def _rigid_step(T: Array, p: Array, R_frame: Array, d: Array, P: Array, fields) -> Array:
    """Move the hand T (object frame) by the frame displacement ``d`` at the frame's
    position ``p`` (orientation ``R_frame``): the part of it along each rotational field
    (weighted by its membership ``P``) as a rotation of the whole hand about the field's
    centre (sphere) or axis (cylinder), the rest as a translation. A field with a
    ``pivot`` turns about that point of the hand (where the demonstrations turned)
    rather than about the centre fitted in the object frame, so that a bottle's opening
    stays where the user put it."""
    out = T.copy()
    rest = d.copy()
    for k, f in enumerate(fields):
        if f.type == "translation" or P[k] < 1e-6:
            continue
        dk = P[k] * d
        if f.pivot is not None:
            pivot = p + R_frame @ f.pivot
            if f.type == "sphere":
                off = _norm3(pivot - f.centre)
            else:
                v = pivot - f.point
                off = _norm3(v - float(v @ f.axis) * f.axis)
            dk = dk * min(1.0, max(0.0, (RIGID_REACH - off) / (RIGID_REACH - RIGID_FULL)))
        if f.type == "sphere":
            centre = f.centre if f.pivot is None else p + R_frame @ f.pivot
            r = p - centre
            rho = _norm3(r)
            if rho < RIGID_MIN_RADIUS:
                continue
            n = r / rho
            t = dk - float(dk @ n) * n  # tangent to the sphere
            w = _cross3(n, t) / rho  # the rotation that moves p by t
        else:
            a, centre = f.axis, f.point if f.pivot is None else p + R_frame @ f.pivot
            r = p - centre
            r_perp = r - float(r @ a) * a
            rho = _norm3(r_perp)
            if rho < RIGID_MIN_RADIUS:
                continue
            e = _cross3(a, r_perp) / rho  # around the axis
            along = float(dk @ e)
            t = along * e
            w = a * (along / rho)
        if not (t[0] or t[1] or t[2]):
            continue
        R = _rodrigues(w)
        out[:3, :3] = R @ out[:3, :3]
        out[:3, 3] = R @ (out[:3, 3] - centre) + centre
        rest -= t
    out[:3, 3] += rest
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
        # The per-tick paths work on flat poses (12 Python floats, see sctd.se3):
        # numpy's per-call overhead dominates on 3x3 and 4x4 arrays.
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
        self._axes = [_input_axes(s.input_mappings) for s in skill.states]
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
        self._turn_budget = math.inf  # rad a neighbour orientation may turn (command_flat sets it)

    # --- FSM ---------------------------------------------------------------------------

    @property
    def state(self) -> str:
        return self.skill.states[self.index].name

    @property
    def input_axes(self) -> tuple[int, ...]:
        """Indices of the input axes the active state's mappings read: how far the user
        pushes is measured on these alone, so an axis no mapping uses moves nothing."""
        return self._axes[self.index]

    @property
    def finished(self) -> bool:
        return self.state == self.skill.end

    def reset(self, now: float, state: str | None = None) -> None:
        """Enter ``state`` (default: the start state) at time ``now``."""
        self.index = self.skill.state_index(state or self.skill.start)
        self.entered = now

    def update(self, T_obj_ee: Array | Flat, now: float, force_obj: Array | None = None,
               pressed: frozenset[int] | set[int] = frozenset()) -> bool:
        """Evaluate the active state's transitions on the measured pose; follow the first
        that fires. Returns True when the state changed.

        Parameters
        ----------
        T_obj_ee : ndarray, shape (4, 4), or flat pose (12 floats, see :mod:`sctd.se3`)
            Measured end-effector pose in the object frame.
        now : float
            Monotonic time (s).
        force_obj : ndarray, shape (3,), optional
            Measured force at the end-effector, in the object frame (N).
        pressed : set of int
            Input buttons pressed since the last update (rising edges).
        """
        # A button press is an event, not a condition: it acts however long the state has
        # been active (the dwell only keeps geometric guards from chattering).
        if pressed:
            for t in self._out_of[self.index]:
                if t.type == "button" and t.button in pressed:
                    return self._enter(t.target, now)
        if now - self.entered < self.skill.min_dwell:
            return False
        F = T_obj_ee if isinstance(T_obj_ee, tuple) else se3.flat_from_matrix4(T_obj_ee)
        for t in self._out_of[self.index]:
            if t.type != "button" and self._fires(t, F, now, force_obj):
                return self._enter(t.target, now)
        return False

    def _enter(self, state: str, now: float) -> bool:
        self.index = self.skill.state_index(state)
        self.entered = now
        return True

    def frame_of(self, F: Flat, frame: str) -> Flat:
        """Flat pose of an ee-attached ``frame`` (or the ee itself) for flat ee pose F."""
        off = self._offsets.get(frame)
        return F if off is None else off.frame(F)

    def _fires(self, t: Transition, F: Flat, now: float, force: Array | None) -> bool:
        if t.type == "timeout":
            return now - self.entered >= t.threshold
        if t.type == "force":
            if force is None:
                return False
            f = float(np.dot(force, t.axis)) if t.axis is not None else float(np.linalg.norm(force))
            return f > t.threshold + t.margin
        G = self.frame_of(F, t.frame)
        v = self._floats.get(id(t)) or _floats_of(t)
        if t.type == "hyperplane":
            nx, ny, nz = v
            return nx * G[9] + ny * G[10] + nz * G[11] + t.offset > t.margin
        cx, cy, cz = v
        dx, dy, dz = G[9] - cx, G[10] - cy, G[11] - cz
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
        return se3.matrix4_from_flat(self.command_flat(se3.flat_from_matrix4(T_obj_ee), u, dt))

    def command_flat(self, F: Flat, u: Array | Sequence[float], dt: float) -> Flat:
        """:meth:`command` on a flat pose (12 floats, see :mod:`sctd.se3`), as the
        runtime's tick calls it: linear mappings and the band, box and tilt checks run
        on Python floats; vector fields and constraint projections that move the pose
        go through arrays."""
        state = self.skill.states[self.index]
        uu = u.tolist() if isinstance(u, np.ndarray) else u
        # How far a neighbour-orientation correction may turn this tick: as far as the
        # user's push lets the hand turn (the runtime bounds the whole step by the same
        # push), so that turning towards the demonstrations never uses up the step the
        # user's own motion needs, and zero input turns nothing.
        n = len(uu)
        push = min(1.0, math.sqrt(sum(uu[j] * uu[j] for j in self.input_axes if j < n)))
        self._turn_budget = push * self.skill.limits.max_angular_speed * dt
        for m in state.input_mappings:
            if isinstance(m, LinearMapping):
                F = self._linear_plans[id(m)].apply(F, uu, dt)
            else:
                T = self._vector_field(se3.matrix4_from_flat(F), m, np.asarray(u, dtype=float), dt)
                F = se3.flat_from_matrix4(T)
        G = None  # the constraint frame's pose, reused while F and the frame stay
        frame = None
        for c in state.active_constraints:
            if c.frame != frame or G is None:
                G, frame = self.frame_of(F, c.frame), c.frame
            F_next = self.project_flat(F, c, G)
            if F_next is not F:
                F, G = F_next, None
        self._turn_budget = math.inf  # a projection outside a command is a whole one
        return F

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
        G = self.frame_of(se3.flat_from_matrix4(T), m.frame)
        p = np.array(G[9:])
        nb = self._trees[id(m.model)]
        P = nb.membership(p, m.max_n, m.max_d)
        fields = m.model.fields
        agree = None
        p3 = (G[9], G[10], G[11])
        unit3 = tuple(unit.tolist())
        if m.combine == "intent":
            agree = [agreement3(f, p3, unit3) for f in fields]
            P = intent_membership(P, nb.prior, agree, m.intent_kappa)
        self.last_membership = P
        if m.mode == "scale":
            if m.combine == "most_probable":
                k = int(np.argmax(P))
                s = agreement3(fields[k], p3, unit3)
            else:
                if agree is None:
                    agree = [agreement3(f, p3, unit3) for f in fields]
                s = sum(float(P[k]) * a for k, a in enumerate(agree))
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
        d = step * (self.skill.limits.max_linear_speed * dt)  # the frame's displacement
        if m.motion == "rigid":
            return _rigid_step(T, p, np.array(G[:9]).reshape(3, 3), d, P, fields)
        out = T.copy()
        out[:3, 3] += d
        return out

    # --- constraints -------------------------------------------------------------------

    def frame_pose(self, T_obj_ee: Array, frame: str) -> Array:
        """Pose of an ee-attached ``frame`` (or the ee itself) for ee pose ``T_obj_ee``."""
        T_ee_f = self.T_ee_frame.get(frame)
        return T_obj_ee if T_ee_f is None else T_obj_ee @ T_ee_f

    def project(self, T: Array, c) -> Array:
        """Project pose T onto constraint c (moving the constrained frame minimally).

        Returns T itself (the same object) when it already satisfies c."""
        F = se3.flat_from_matrix4(T)
        G = self.project_flat(F, c)
        return T if G is F else se3.matrix4_from_flat(G)

    def project_flat(self, F: Flat, c, G: Flat | None = None) -> Flat:
        """:meth:`project` on a flat ee pose F; returns F itself when it satisfies c.
        ``G``, the constrained frame's flat pose for this F, may be passed in to save
        recomputing it. The checks run on Python floats; only a projection that moves
        the pose builds arrays."""
        if G is None:
            G = self.frame_of(F, c.frame)
        v = self._floats.get(id(c)) or _floats_of(c)
        if isinstance(c, Band):
            (nx, ny, nz), (cx, cy, cz) = v
            s = nx * (G[9] - cx) + ny * (G[10] - cy) + nz * (G[11] - cz)
            delta = (c.lower - s) if s < c.lower else (c.upper - s) if s > c.upper else 0.0
            if delta == 0.0:
                return F
            return (*F[:9], F[9] + delta * nx, F[10] + delta * ny, F[11] + delta * nz)
        if isinstance(c, Box):
            p = G[9:]
            q = [min(max(x, lo), hi) for x, lo, hi in zip(p, *v, strict=True)]
            if q[0] == p[0] and q[1] == p[1] and q[2] == p[2]:
                return F
            return (*F[:9], F[9] + q[0] - p[0], F[10] + q[1] - p[1], F[11] + q[2] - p[2])
        if isinstance(c, TiltCone):
            (ax, ay, az), (rx, ry, rz), cos_max = v
            a0 = G[0] * ax + G[1] * ay + G[2] * az
            a1 = G[3] * ax + G[4] * ay + G[5] * az
            a2 = G[6] * ax + G[7] * ay + G[8] * az
            cos_a = a0 * rx + a1 * ry + a2 * rz
            if cos_a >= cos_max:
                return F
            a = np.array([a0, a1, a2])
            perp = a - cos_a * c.reference
            pn = float(np.linalg.norm(perp))
            if pn < 1e-9:  # exactly opposite: any boundary direction will do
                perp = np.cross(c.reference, [1.0, 0.0, 0.0])
                if np.linalg.norm(perp) < 1e-6:
                    perp = np.cross(c.reference, [0.0, 1.0, 0.0])
                pn = float(np.linalg.norm(perp))
            boundary = math.cos(c.max_angle) * c.reference + math.sin(c.max_angle) * perp / pn
            return self._rotate_about(F, G, se3.rotation_between(a, boundary))
        if isinstance(c, NeighbourOrientation):
            nb = self._trees[id(c.model)]
            if c.rotation_weight > 0.0:
                i, w = nb.query_pose(np.array(G[9:]), se3.quaternion_from_rows(*G[:9]), c.max_n,
                                     c.max_d, c.rotation_weight)
            else:
                i, w = nb.query(np.array(G[9:]), c.max_n, c.max_d)
            if len(i) == 0:
                return F
            q = c.model.quaternions[i]
            q = q * np.where(q @ q[0] < 0.0, -1.0, 1.0)[:, None]  # one hemisphere
            gx, gy, gz, gw = (w @ q).tolist()
            # The correction q_goal * q_frame^-1 and its angle, on floats (this runs every
            # tick): turned towards the goal at most the budget.
            fx, fy, fz, fw = se3.quaternion_from_rows(*G[:9])
            cw = gw * fw + gx * fx + gy * fy + gz * fz
            cx = -gw * fx + gx * fw - gy * fz + gz * fy
            cy = -gw * fy + gy * fw - gz * fx + gx * fz
            cz = -gw * fz + gz * fw - gx * fy + gy * fx
            if cw < 0.0:
                cw, cx, cy, cz = -cw, -cx, -cy, -cz
            vn = math.sqrt(cx * cx + cy * cy + cz * cz)
            n = math.sqrt(cw * cw + vn * vn)
            if n < 1e-12:
                return F
            budget = self._turn_budget
            if vn > 1e-15 and 2.0 * math.atan2(vn, cw) > budget:
                h = 0.5 * budget
                k = math.sin(h) / vn
                cx, cy, cz, cw = cx * k, cy * k, cz * k, math.cos(h)
            else:
                cx, cy, cz, cw = cx / n, cy / n, cz / n, cw / n
            R9 = _matrix_of_quaternion(cx, cy, cz, cw)
            if c.pivot is not None:  # about a point of the hand (the opening of a bottle)
                px, py, pz = self._floats_pivot(c)
                o = (G[9] + G[0] * px + G[1] * py + G[2] * pz,
                     G[10] + G[3] * px + G[4] * py + G[5] * pz,
                     G[11] + G[6] * px + G[7] * py + G[8] * pz)
                return se3.compose_flat(_rotation(*R9, *o), F)
            return se3.compose_flat(_rotation(*R9, *G[9:]), F)
        raise TypeError(f"unknown constraint {c!r}")

    @staticmethod
    def _floats_pivot(c: NeighbourOrientation) -> tuple[float, float, float]:
        assert c.pivot is not None
        return float(c.pivot[0]), float(c.pivot[1]), float(c.pivot[2])

    @staticmethod
    def _rotate_about(F: Flat, G: Flat, R_corr: Array) -> Flat:
        """Rotate flat pose F by R_corr (object axes) about the origin of frame G."""
        return se3.compose_flat(_rotation(*R_corr.ravel().tolist(), *G[9:]), F)

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
