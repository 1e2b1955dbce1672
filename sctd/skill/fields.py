"""Basic vector fields (Ch. 4.2.2, Appendix A.1), one class per kind, and the sigmoid
of eqs. 4.31-4.34.

Shared by the runtime (evaluating a field at the end-effector, on Python floats) and
the learner (deviation angles for RANSAC and EM, vectorised over points). Each kind
holds its parameters, reads them from a model file (``from_yaml``, ``read``), writes
them back (``to_yaml``), summarises itself and evaluates itself; :data:`FIELDS` finds a
kind by its ``type`` name. Pure numpy.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import SkillError
from .registry import ByValue, Registry, summarised, unit_divisor
from .sketch import Arrow, Dots, Line, Shape, Sphere, direction_words

Array = NDArray[np.float64]

POINT_UNDEFINED = 1e-3  # m: a point field has no direction this close to its point
RIGID_MIN_RADIUS = 0.02  # m: closer to a field's centre or axis than this, no turning
RIGID_FULL = 0.035  # m: a field's pivot turns the hand fully within this of the field's
RIGID_REACH = 0.07  # centre or axis, not at all this far from it (not brought there yet)
# (a field's own ``pivot_within`` W: fully within W, not at all from 2 W)


Vec3 = tuple[float, float, float]


class RigidPart(NamedTuple):
    """What a rotational field makes of a frame displacement ``d`` (object frame) under
    rigid motion (:func:`sctd.skill.mappings.rigid_step`).

    ``t``: the part of ``d`` along the field's turn (tangent to a sphere through the
    frame, around a cylinder's axis); ``w``: the rotation vector that moves the frame
    by ``t`` about ``centre``; ``reach`` in [0, 1]: how much of ``t`` turns the hand
    (1 with the field's pivot on its centre or axis, 0 with the pivot not brought there
    yet, :data:`RIGID_FULL`, :data:`RIGID_REACH`, or the field's ``pivot_within``). The
    rest of ``d``, ``d - t``, is motion
    across the field.
    """

    t: Vec3
    w: Vec3
    centre: Vec3
    reach: float


def _dot3(a: Sequence[float], b: Sequence[float]) -> float:
    """``a . b`` of two 3-vectors, summed as numpy's dot sums them (from 0.0, in order)."""
    return 0.0 + a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _norm3(x: float, y: float, z: float) -> float:
    return math.sqrt(x * x + y * y + z * z)


def _cross3(a: Sequence[float], b: Sequence[float]) -> Vec3:
    """``a x b`` (the products and differences np.cross computes)."""
    ax, ay, az = a
    bx, by, bz = b
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


def _pivot_centre(G: Sequence[float], pivot: Array) -> Vec3:
    """The position ``p + R pivot`` of a pivot on the frame with pose ``G`` (flat:
    rotation R row-major, then position p)."""
    px, py, pz = pivot.tolist()
    return (G[9] + G[0] * px + G[1] * py + G[2] * pz, G[10] + G[3] * px + G[4] * py + G[5] * pz,
            G[11] + G[6] * px + G[7] * py + G[8] * pz)

SKETCH_LENGTH = 0.08  # m: how long a field's direction or axis is drawn


class FieldReader:
    """Checked reading of one field's entry ``path`` of model file ``where``."""

    def __init__(self, fd: dict, path: str, where: str):
        self.fd, self.path, self.where = fd, path, where

    def fail(self, key: str, problem: str) -> SkillError:
        return SkillError(self.where, f"{self.path}.{key}", problem)

    def vec(self, key: str, unit: bool = False) -> Array:
        """3 finite numbers (shape (3,)); normalised when ``unit``."""
        v = self.fd.get(key)
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise self.fail(key, f"expected 3 finite numbers, got {v!r}")
        if unit:
            n = float(np.linalg.norm(a))
            if n < 1e-9:
                raise self.fail(key, "direction of zero length")
            a = a / unit_divisor(n)
        return a

    def num(self, key: str, default: float) -> float:
        """A finite number >= 0 (``default`` when absent)."""
        v = self.fd.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
            raise self.fail(key, f"expected a finite number >= 0, got {v!r}")
        return float(v)

    def pivot(self) -> Array | None:
        return None if self.fd.get("pivot") is None else self.vec("pivot")

    def pivot_within(self) -> float | None:
        """m, > 0; None when absent."""
        if self.fd.get("pivot_within") is None:
            return None
        v = self.num("pivot_within", 0.0)
        if v <= 0.0:
            raise self.fail("pivot_within", f"expected a number > 0, got {v!r}")
        return v

    def rows(self, key: str, max_rows: int) -> Array:
        """A non-empty list of at most ``max_rows`` rows of 3 finite numbers (shape (n, 3))."""
        v = self.fd.get(key)
        try:
            a = np.asarray(v, dtype=float)
        except (TypeError, ValueError):
            a = np.zeros((0, 0))
        if a.ndim != 2 or a.shape[1] != 3 or not 0 < len(a) <= max_rows:
            raise self.fail(key, f"expected 1 to {max_rows} rows of 3 numbers, got shape {a.shape}")
        if not np.all(np.isfinite(a)):
            row = int(np.argwhere(~np.isfinite(a))[0, 0])
            raise self.fail(f"{key}[{row}]", "not finite")
        return a


@dataclass(frozen=True, kw_only=True, eq=False)
class Field(ByValue, ABC):
    """One basic vector field in the object frame.

    ``weight`` is its mixing proportion pi (eq. 4.29), ``sigma`` the angular spread
    (rad) of its vectors (eq. 4.30), ``inliers`` how many demonstration points it
    explained. ``pivot``: the centre (sphere) or an axis point (cylinder) as a fixed
    point of the mapping's frame (its offset in that frame), when the demonstrations
    turned about a point of the hand (a bottle's opening): rigid motion turns about it.
    """

    type: ClassVar[str]
    optional_keys: ClassVar[frozenset[str]] = frozenset({"pivot", "pivot_within"})
    """Keys an entry may hold that :meth:`to_yaml` leaves out when they are unset."""
    weight: float = 1.0
    sigma: float = 0.3
    inliers: int = 0
    pivot: Array | None = None
    # m: the pivot turns the hand fully within this of the centre or axis, not at all from
    # twice it (None: RIGID_FULL, RIGID_REACH); a hand still on its way there is moved, not turned
    pivot_within: float | None = None

    @classmethod
    def from_yaml(cls, fd: Any, path: str, where: str) -> Field:
        """Read one entry of a model file's ``fields`` list (any kind, by its ``type``)."""
        if not isinstance(fd, dict):
            raise SkillError(where, path, "expected a mapping")
        r = FieldReader(fd, path, where)
        common = {"weight": r.num("weight", 1.0), "sigma": r.num("sigma", 0.3),
                  "inliers": int(r.num("inliers", 0))}
        kind = fd.get("type")
        if not isinstance(kind, str) or kind not in FIELDS:
            names = FIELDS.names()
            raise r.fail("type", f"expected {', '.join(names[:-1])} or {names[-1]}, got {kind!r}")
        field = FIELDS[kind].read(r, common)
        known = set(field.to_yaml()) | field.optional_keys
        unknown = sorted(str(k) for k in fd if k not in known)
        if unknown:  # a misspelt parameter would silently take its default
            raise r.fail(unknown[0], f"unknown field of a {kind} field (allowed: {', '.join(sorted(known))})")
        return field

    @classmethod
    @abstractmethod
    def read(cls, r: FieldReader, common: dict[str, Any]) -> Field:
        """This kind's parameters from ``r``, with the ``common`` ones already read."""

    def to_yaml(self) -> dict[str, Any]:
        """The field as the plain dict :meth:`from_yaml` reads (an entry of a model file's
        ``fields`` list): every parameter, exactly."""
        out: dict[str, Any] = {"type": self.type, "inliers": self.inliers, "weight": self.weight,
                               "sigma": self.sigma, **self._parameters()}
        if self.pivot is not None:
            out["pivot"] = self.pivot.tolist()
        if self.pivot_within is not None:
            out["pivot_within"] = self.pivot_within
        return out

    def summary(self) -> dict[str, Any]:
        """The field as plain data (:meth:`to_yaml`, arrays rounded to 12 decimals)."""
        return summarised(self.to_yaml())

    def brief(self) -> dict[str, Any]:
        """:meth:`summary` short enough for a person (a comment, ``sctd inspect``)."""
        return self.summary()

    @abstractmethod
    def _parameters(self) -> dict[str, Any]:
        """This kind's own parameters for :meth:`to_yaml`."""

    def sketch(self, points: ArrayLike) -> tuple[Shape, ...]:
        """Its fitted parameters as shapes (:mod:`sctd.skill.sketch`, object frame),
        placed by the demonstration points it explains (n, 3): a centre, an axis."""
        return ()

    @abstractmethod
    def vectors(self, points: ArrayLike) -> Array:
        """Unit field direction at each point (shape (n, 3)); zero where undefined."""

    @abstractmethod
    def vector3(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """:meth:`vectors` at one point, on Python floats (the runtime's tick)."""

    def agreement3(self, p: tuple[float, float, float], unit: tuple[float, float, float]) -> float:
        """Cosine agreement ``s`` in [-1, 1] of a unit command with the field at ``p``
        (eq. 4.31), on Python floats."""
        gx, gy, gz = self.vector3(*p)
        return unit[0] * gx + unit[1] * gy + unit[2] * gz

    def agreement(self, point: ArrayLike, unit_command: ArrayLike) -> float:
        """:meth:`agreement3` on arrays (the same value): point and command shape (3,)."""
        return float(np.dot(unit_command, self.vectors(point)[0]))

    def deviation_angles(self, points: ArrayLike, vectors: ArrayLike) -> Array:
        """Angle (rad, shape (n,)) between each unit data vector (n, 3) and the field's
        direction at its point (n, 3) (A.1): in [0, pi], pi/2 where it is undefined."""
        v = np.atleast_2d(np.asarray(vectors, dtype=float))
        g = self.vectors(points)
        c = np.clip(np.sum(v * g, axis=1), -1.0, 1.0)
        defined = np.linalg.norm(g, axis=1) > 0.5
        return np.where(defined, np.arccos(c), np.pi / 2)

    def guided_direction(self, point: ArrayLike, unit_command: ArrayLike) -> Array:
        """The unit direction (3,) the field proposes at ``point`` for a command (eq.
        4.35's ``v_F``): its own direction there."""
        return self.vectors(point)[0]

    def rigid_part(self, G: Sequence[float], d: Vec3) -> RigidPart | None:
        """The part of the frame displacement ``d`` along this field's turn, for the frame
        at pose ``G`` (flat, see :mod:`sctd.se3`: its rotation, then its position p)
        (:class:`RigidPart`); None for a field that does not turn, or for a frame too
        close to its centre or axis to turn about it. On floats (the runtime's tick)."""
        return None

    def to_centre(self, G: Sequence[float]) -> Vec3 | None:
        """From where this field's ``pivot`` is, for the frame at pose ``G``, to the
        field's centre (sphere) or the nearest point of its axis (cylinder): where the
        pivot is to arrive before the turn is about it; None without a pivot or a turn."""
        return None


def _pivot_reach(off: float, within: float | None = None) -> float:
    """How much of a turn a pivot ``off`` metres from the field's centre or axis makes:
    all of it within ``within`` (:data:`RIGID_FULL` when None), none from twice that
    (:data:`RIGID_REACH`)."""
    full, none = (RIGID_FULL, RIGID_REACH) if within is None else (within, 2.0 * within)
    return min(1.0, max(0.0, (none - off) / (none - full)))


FIELDS: Registry[Field] = Registry("vector field")


@FIELDS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class TranslationField(Field):
    """Motion along the unit ``direction`` (3,), everywhere the same."""

    type: ClassVar[str] = "translation"
    direction: Array

    @classmethod
    def read(cls, r: FieldReader, common: dict[str, Any]) -> TranslationField:
        return cls(**common, direction=r.vec("direction", unit=True))

    def _parameters(self) -> dict[str, Any]:
        return {"direction": self.direction.tolist()}

    def sketch(self, points: ArrayLike) -> tuple[Shape, ...]:
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        at = p.mean(axis=0) if len(p) else np.zeros(3)
        return (Arrow(f"translation along {direction_words(self.direction)}", at,
                      SKETCH_LENGTH * self.direction),)

    def vectors(self, points: ArrayLike) -> Array:
        p = np.atleast_2d(np.asarray(points, dtype=float))
        return np.broadcast_to(self.direction, p.shape).copy()

    def vector3(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        dx, dy, dz = self.direction.tolist()
        return dx, dy, dz


@FIELDS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class CylinderField(Field):
    """Rotation about the line through ``point`` (3,) along the unit ``axis`` (3,)
    (circulation by the right-hand rule about ``axis``)."""

    type: ClassVar[str] = "cylinder"
    point: Array
    axis: Array

    @classmethod
    def read(cls, r: FieldReader, common: dict[str, Any]) -> CylinderField:
        return cls(**common, point=r.vec("point"), axis=r.vec("axis", unit=True), pivot=r.pivot(),
                   pivot_within=r.pivot_within())

    def _parameters(self) -> dict[str, Any]:
        return {"point": self.point.tolist(), "axis": self.axis.tolist()}

    def sketch(self, points: ArrayLike) -> tuple[Shape, ...]:
        """Its axis, centred where the points it explains lie along it."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        s = float(np.mean((p - self.point) @ self.axis)) if len(p) else 0.0
        mid = self.point + s * self.axis
        return (Line(f"turning about {direction_words(self.axis)}", mid - SKETCH_LENGTH * self.axis,
                     mid + SKETCH_LENGTH * self.axis),)

    def vectors(self, points: ArrayLike) -> Array:
        p = np.atleast_2d(np.asarray(points, dtype=float))
        v = np.cross(self.axis, p - self.point)
        n = np.linalg.norm(v, axis=1, keepdims=True)
        return np.where(n > 1e-9, v / np.maximum(n, 1e-9), 0.0)

    def vector3(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        (ax, ay, az), (cx, cy, cz) = self.axis.tolist(), self.point.tolist()
        rx, ry, rz = x - cx, y - cy, z - cz
        vx, vy, vz = ay * rz - az * ry, az * rx - ax * rz, ax * ry - ay * rx
        n = math.sqrt(vx * vx + vy * vy + vz * vz)
        return (vx / n, vy / n, vz / n) if n > 1e-9 else (0.0, 0.0, 0.0)

    def to_centre(self, G: Sequence[float]) -> Vec3 | None:
        if self.pivot is None:
            return None
        a0, a1, a2 = a = self.axis.tolist()
        o0, o1, o2 = self.point.tolist()
        c0, c1, c2 = _pivot_centre(G, self.pivot)
        v = (o0 - c0, o1 - c1, o2 - c2)
        va = _dot3(v, a)
        return v[0] - va * a0, v[1] - va * a1, v[2] - va * a2

    def rigid_part(self, G: Sequence[float], d: Vec3) -> RigidPart | None:
        """Around the axis: the part of ``d`` along the circulation at the frame."""
        a0, a1, a2 = a = self.axis.tolist()
        c0, c1, c2 = centre = self.point.tolist()
        k = 1.0
        if self.pivot is not None:
            o0, o1, o2 = centre
            c0, c1, c2 = centre = _pivot_centre(G, self.pivot)
            v = (c0 - o0, c1 - o1, c2 - o2)
            va = _dot3(v, a)
            k = _pivot_reach(_norm3(v[0] - va * a0, v[1] - va * a1, v[2] - va * a2), self.pivot_within)
        r = (G[9] - c0, G[10] - c1, G[11] - c2)
        ra = _dot3(r, a)
        r_perp = (r[0] - ra * a0, r[1] - ra * a1, r[2] - ra * a2)
        rho = _norm3(*r_perp)
        if rho < RIGID_MIN_RADIUS:
            return None
        x, y, z = _cross3(a, r_perp)  # around the axis
        e = (x / rho, y / rho, z / rho)
        along = _dot3(d, e)
        w = along / rho
        return RigidPart((along * e[0], along * e[1], along * e[2]), (a0 * w, a1 * w, a2 * w),
                         (c0, c1, c2), k)


@FIELDS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class SphereField(Field):
    """Motion tangent to the spheres about ``centre`` (3,); ``radius`` the demonstrations'
    mean distance from it, if known.

    A sphere does not fix one direction (any tangent is allowed): its
    :meth:`vectors` are the radial unit vectors ``(p - c) / |p - c|``, the normals of the
    allowed planes, and agreement and deviation are measured against the plane.
    """

    type: ClassVar[str] = "sphere"
    optional_keys: ClassVar[frozenset[str]] = frozenset({"pivot", "pivot_within", "radius"})
    centre: Array
    radius: float | None = None

    @classmethod
    def read(cls, r: FieldReader, common: dict[str, Any]) -> SphereField:
        radius = r.fd.get("radius")
        return cls(**common, centre=r.vec("centre"), radius=None if radius is None else r.num("radius", 0.0),
                   pivot=r.pivot(), pivot_within=r.pivot_within())

    def _parameters(self) -> dict[str, Any]:
        out: dict[str, Any] = {"centre": self.centre.tolist()}
        if self.radius is not None:
            out["radius"] = self.radius
        return out

    def sketch(self, points: ArrayLike) -> tuple[Shape, ...]:
        """Its centre, and the sphere of the demonstrations' mean radius when known."""
        shapes: list[Shape] = [Dots("sphere's centre", self.centre)]
        if self.radius is not None and self.radius > 0.0:
            shapes.append(Sphere(f"sphere of {self.radius:.3f} m", self.centre, self.radius))
        return tuple(shapes)

    def vectors(self, points: ArrayLike) -> Array:
        v = np.atleast_2d(np.asarray(points, dtype=float)) - self.centre
        n = np.linalg.norm(v, axis=1, keepdims=True)
        return np.where(n > 1e-9, v / np.maximum(n, 1e-9), 0.0)

    def vector3(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        cx, cy, cz = self.centre.tolist()
        vx, vy, vz = x - cx, y - cy, z - cz
        n = math.sqrt(vx * vx + vy * vy + vz * vz)
        return (vx / n, vy / n, vz / n) if n > 1e-9 else (0.0, 0.0, 0.0)

    def agreement3(self, p: tuple[float, float, float], unit: tuple[float, float, float]) -> float:
        """The cosine to the tangent plane, in [0, 1]."""
        c = super().agreement3(p, unit)
        return math.sqrt(max(0.0, 1.0 - c * c))

    def agreement(self, point: ArrayLike, unit_command: ArrayLike) -> float:
        c = super().agreement(point, unit_command)
        return float(np.sqrt(max(0.0, 1.0 - c * c)))

    def deviation_angles(self, points: ArrayLike, vectors: ArrayLike) -> Array:
        """The angle between each vector and the tangent plane, in [0, pi/2]."""
        v = np.atleast_2d(np.asarray(vectors, dtype=float))
        c = np.clip(np.sum(v * self.vectors(points), axis=1), -1.0, 1.0)
        return np.arcsin(np.abs(c))

    def guided_direction(self, point: ArrayLike, unit_command: ArrayLike) -> Array:
        """The command projected onto the tangent plane (zero when it is radial)."""
        g = self.vectors(point)[0]
        u = np.asarray(unit_command, dtype=float)
        t = u - np.dot(u, g) * g
        n = float(np.linalg.norm(t))
        return t / n if n > 1e-9 else np.zeros(3)

    def to_centre(self, G: Sequence[float]) -> Vec3 | None:
        if self.pivot is None:
            return None
        o0, o1, o2 = self.centre.tolist()
        c0, c1, c2 = _pivot_centre(G, self.pivot)
        return o0 - c0, o1 - c1, o2 - c2

    def rigid_part(self, G: Sequence[float], d: Vec3) -> RigidPart | None:
        """About the centre: the part of ``d`` tangent to the sphere through the frame."""
        c0, c1, c2 = centre = self.centre.tolist()
        k = 1.0
        if self.pivot is not None:
            s0, s1, s2 = centre
            c0, c1, c2 = centre = _pivot_centre(G, self.pivot)
            k = _pivot_reach(_norm3(c0 - s0, c1 - s1, c2 - s2), self.pivot_within)
        r0, r1, r2 = G[9] - c0, G[10] - c1, G[11] - c2
        rho = _norm3(r0, r1, r2)
        if rho < RIGID_MIN_RADIUS:
            return None
        n = (r0 / rho, r1 / rho, r2 / rho)
        dn = _dot3(d, n)
        t = (d[0] - dn * n[0], d[1] - dn * n[1], d[2] - dn * n[2])  # tangent to the sphere
        x, y, z = _cross3(n, t)
        return RigidPart(t, (x / rho, y / rho, z / rho), (c0, c1, c2), k)


@FIELDS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class PointField(Field):
    """Motion towards ``point`` (3,): a reach's goal, where demonstrations from different
    starts converge (a field of negative divergence, beyond the thesis' basic set: a
    translation field is the same direction from every start, so a reach from a start
    off its mean line agrees with it less the further off it starts, and ``scale`` mode
    slows a push straight at the goal). The direction is undefined (zero) within
    ``POINT_UNDEFINED`` of the point."""

    type: ClassVar[str] = "point"
    point: Array

    @classmethod
    def read(cls, r: FieldReader, common: dict[str, Any]) -> PointField:
        return cls(**common, point=r.vec("point"))

    def _parameters(self) -> dict[str, Any]:
        return {"point": self.point.tolist()}

    def sketch(self, points: ArrayLike) -> tuple[Shape, ...]:
        return (Dots("the point it goes to", self.point),)

    def vectors(self, points: ArrayLike) -> Array:
        v = self.point - np.atleast_2d(np.asarray(points, dtype=float))
        n = np.linalg.norm(v, axis=1, keepdims=True)
        return np.where(n > POINT_UNDEFINED, v / np.maximum(n, POINT_UNDEFINED), 0.0)

    def vector3(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        cx, cy, cz = self.point.tolist()
        vx, vy, vz = cx - x, cy - y, cz - z
        n = math.sqrt(vx * vx + vy * vy + vz * vz)
        return (vx / n, vy / n, vz / n) if n > POINT_UNDEFINED else (0.0, 0.0, 0.0)


GENERAL_MAX_CENTRES = 20000  # kernel centres of one general field in a model file
GENERAL_NEIGHBOURS = 8  # centres a general field's direction is averaged over
GENERAL_REUSE = 5e-4  # m: a single-point query reuses its neighbours this close to the last


@FIELDS.register
@dataclass(frozen=True, kw_only=True, eq=False)
class GeneralField(Field):
    """A non-parametric field (the thesis' future work, Ch. 7: "a general model ... a
    smoothed version of its neighbours"): at a point, the Gaussian-kernel mean
    (Nadaraya-Watson) of the demonstrated unit ``directions`` (m, 3) at the
    ``GENERAL_NEIGHBOURS`` nearest of its ``centres`` (m, 3), normalised.

    ``bandwidth`` (m) is the kernel's width; further from the centres than that, it
    widens to the nearest centre's distance, so the field stays defined (the nearest
    demonstrations' direction) away from them. Evaluating it costs one KD-tree query,
    O(log m); a single-point evaluation (the tick) reuses the last query's neighbours
    while the point stays within ``GENERAL_REUSE`` of it, and weighs them exactly.
    """

    type: ClassVar[str] = "general"
    centres: Array
    directions: Array
    bandwidth: float = 0.02

    def __post_init__(self) -> None:
        d = np.asarray(self.directions, dtype=float)
        n = unit_divisor(np.linalg.norm(d, axis=1, keepdims=True))
        object.__setattr__(self, "directions", np.where(n > 1e-12, d / np.maximum(n, 1e-12), 0.0))
        from scipy.spatial import cKDTree  # here: 0.6 s to import, and only these fields need it

        object.__setattr__(self, "_tree", cKDTree(np.asarray(self.centres, dtype=float)))
        object.__setattr__(self, "_last", [None])  # (x, y, z, neighbour rows) of a vector3

    @classmethod
    def read(cls, r: FieldReader, common: dict[str, Any]) -> GeneralField:
        centres = r.rows("centres", GENERAL_MAX_CENTRES)
        directions = r.rows("directions", GENERAL_MAX_CENTRES)
        if len(directions) != len(centres):
            raise r.fail("directions", f"expected {len(centres)} rows (one per centre), "
                         f"got {len(directions)}")
        bandwidth = r.num("bandwidth", 0.02)
        if bandwidth <= 0:
            raise r.fail("bandwidth", "expected a width > 0 (m)")
        return cls(**common, centres=centres, directions=directions, bandwidth=bandwidth)

    def _parameters(self) -> dict[str, Any]:
        return {"bandwidth": self.bandwidth, "centres": self.centres.tolist(),
                "directions": self.directions.tolist()}

    def brief(self) -> dict[str, Any]:
        """The summary with the number of centres in place of the centres and directions."""
        out = self.summary()
        del out["directions"]
        out["centres"] = len(self.centres)
        return out

    @property
    def _k(self) -> int:
        return min(GENERAL_NEIGHBOURS, len(self.centres))

    def sketch(self, points: ArrayLike) -> tuple[Shape, ...]:
        return (Dots(f"{len(self.centres)} demonstrated directions", self.centres),)

    def vectors(self, points: ArrayLike) -> Array:
        p = np.atleast_2d(np.asarray(points, dtype=float))
        d, i = self._tree.query(p, k=self._k)  # type: ignore[attr-defined]
        d, i = d.reshape(len(p), -1), i.reshape(len(p), -1)
        h = np.maximum(self.bandwidth, d[:, :1])
        w = np.exp(-0.5 * (d / h) ** 2)
        g = np.einsum("nk,nkj->nj", w, self.directions[i])
        n = np.linalg.norm(g, axis=1, keepdims=True)
        return np.where(n > 1e-9, g / np.maximum(n, 1e-9), 0.0)

    def vector3(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        last = self._last[0]  # type: ignore[attr-defined]
        if last is None or (x - last[0]) ** 2 + (y - last[1]) ** 2 + (z - last[2]) ** 2 > GENERAL_REUSE ** 2:
            _, i = self._tree.query((x, y, z), k=self._k)  # type: ignore[attr-defined]
            rows = [(c[0], c[1], c[2], v[0], v[1], v[2]) for c, v in
                    zip(self.centres[np.atleast_1d(i)].tolist(),
                        self.directions[np.atleast_1d(i)].tolist(), strict=True)]
            last = self._last[0] = (x, y, z, rows)  # type: ignore[attr-defined]
        rows = last[3]
        d2 = [(x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2 for cx, cy, cz, _, _, _ in rows]
        h2 = max(self.bandwidth * self.bandwidth, min(d2))
        gx = gy = gz = 0.0
        for r2, (_, _, _, vx, vy, vz) in zip(d2, rows, strict=True):
            w = math.exp(-0.5 * r2 / h2)
            gx, gy, gz = gx + w * vx, gy + w * vy, gz + w * vz
        n = math.sqrt(gx * gx + gy * gy + gz * gz)
        return (gx / n, gy / n, gz / n) if n > 1e-9 else (0.0, 0.0, 0.0)


def sigmoid(x: float | Array, k: float) -> float | Array:
    """Normalised tunable sigmoid of eq. 4.33: ``(x - k x) / (k - 2 k |x| + 1)``.

    Maps [-1, 1] onto [-1, 1] with f(0) = 0, f(+-1) = +-1 and f(x) = x at k = 0;
    k in (0, 1) makes it stricter (needs closer agreement), k in (-1, 0) more lenient.
    """
    ax = np.abs(x) if isinstance(x, np.ndarray) else abs(x)  # (np.abs costs the tick ~1 us)
    return (x - k * x) / (k - 2.0 * k * ax + 1.0)
