"""Basic vector fields (Ch. 4.2.2, Appendix A.1), one class per kind, and the sigmoid
of eqs. 4.31-4.34.

Shared by the runtime (evaluating a field at the end-effector, on Python floats) and
the learner (deviation angles for RANSAC and EM, vectorised over points). Each kind
holds its parameters, reads them from a model file, summarises itself and evaluates
itself; :data:`FIELDS` finds a kind by its ``type`` name. Pure numpy.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import SkillError
from .registry import Registry, plain

Array = NDArray[np.float64]

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
            a = a / n
        return a

    def num(self, key: str, default: float) -> float:
        """A finite number >= 0 (``default`` when absent)."""
        v = self.fd.get(key, default)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v) or v < 0:
            raise self.fail(key, f"expected a finite number >= 0, got {v!r}")
        return float(v)

    def pivot(self) -> Array | None:
        return None if self.fd.get("pivot") is None else self.vec("pivot")


@dataclass(frozen=True, kw_only=True)
class Field(ABC):
    """One basic vector field in the object frame.

    ``weight`` is its mixing proportion pi (eq. 4.29), ``sigma`` the angular spread
    (rad) of its vectors (eq. 4.30), ``inliers`` how many demonstration points it
    explained. ``pivot``: the centre (sphere) or an axis point (cylinder) as a fixed
    point of the mapping's frame (its offset in that frame), when the demonstrations
    turned about a point of the hand (a bottle's opening): rigid motion turns about it.
    """

    type: ClassVar[str]
    weight: float = 1.0
    sigma: float = 0.3
    inliers: int = 0
    pivot: Array | None = None

    @classmethod
    def from_doc(cls, fd: Any, path: str, where: str) -> Field:
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
        return FIELDS[kind].read(r, common)

    @classmethod
    @abstractmethod
    def read(cls, r: FieldReader, common: dict[str, Any]) -> Field:
        """This kind's parameters from ``r``, with the ``common`` ones already read."""

    def summary(self) -> dict[str, Any]:
        """The field as plain data (also what a model file stores)."""
        out: dict[str, Any] = {"type": self.type, "inliers": self.inliers, "weight": self.weight,
                               "sigma": self.sigma, **self._parameters()}
        if self.pivot is not None:
            out["pivot"] = plain(self.pivot)
        return out

    @abstractmethod
    def _parameters(self) -> dict[str, Any]:
        """This kind's own parameters for :meth:`summary`."""

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

    def rigid_part(self, p: Array, R_frame: Array, d: Array) -> tuple[Array, Array, Array] | None:
        """The part of the frame displacement ``d`` (3,) at the frame's position ``p``
        (orientation ``R_frame``) that turns the whole hand about this field, as
        ``(t, w, centre)``: the displacement of ``p`` it takes, the rotation vector and
        the point it turns about (object frame); None for a field that does not turn."""
        return None


def _pivot_reach(off: float) -> float:
    """How much of a turn a pivot ``off`` metres from the field's centre or axis makes."""
    return min(1.0, max(0.0, (RIGID_REACH - off) / (RIGID_REACH - RIGID_FULL)))


FIELDS: Registry[Field] = Registry("vector field")


@FIELDS.register
@dataclass(frozen=True, kw_only=True)
class TranslationField(Field):
    """Motion along the unit ``direction`` (3,), everywhere the same."""

    type: ClassVar[str] = "translation"
    direction: Array

    @classmethod
    def read(cls, r: FieldReader, common: dict[str, Any]) -> TranslationField:
        return cls(**common, direction=r.vec("direction", unit=True))

    def _parameters(self) -> dict[str, Any]:
        return {"direction": plain(self.direction)}

    def vectors(self, points: ArrayLike) -> Array:
        p = np.atleast_2d(np.asarray(points, dtype=float))
        return np.broadcast_to(self.direction, p.shape).copy()

    def vector3(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        dx, dy, dz = self.direction.tolist()
        return dx, dy, dz


@FIELDS.register
@dataclass(frozen=True, kw_only=True)
class CylinderField(Field):
    """Rotation about the line through ``point`` (3,) along the unit ``axis`` (3,)
    (circulation by the right-hand rule about ``axis``)."""

    type: ClassVar[str] = "cylinder"
    point: Array
    axis: Array

    @classmethod
    def read(cls, r: FieldReader, common: dict[str, Any]) -> CylinderField:
        pivot = r.pivot()
        return cls(**common, point=r.vec("point"), axis=r.vec("axis", unit=True), pivot=pivot)

    def _parameters(self) -> dict[str, Any]:
        return {"point": plain(self.point), "axis": plain(self.axis)}

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

    def rigid_part(self, p: Array, R_frame: Array, d: Array) -> tuple[Array, Array, Array] | None:
        """Around the axis: the part of ``d`` along the circulation at ``p``."""
        a, centre = self.axis, self.point
        if self.pivot is not None:
            centre = p + R_frame @ self.pivot
            v = centre - self.point
            d = d * _pivot_reach(_norm3(v - float(v @ a) * a))
        r = p - centre
        r_perp = r - float(r @ a) * a
        rho = _norm3(r_perp)
        if rho < RIGID_MIN_RADIUS:
            return None
        e = _cross3(a, r_perp) / rho  # around the axis
        along = float(d @ e)
        return along * e, a * (along / rho), centre


@FIELDS.register
@dataclass(frozen=True, kw_only=True)
class SphereField(Field):
    """Motion tangent to the spheres about ``centre`` (3,); ``radius`` the demonstrations'
    mean distance from it, if known.

    A sphere does not fix one direction (any tangent is allowed): its
    :meth:`vectors` are the radial unit vectors ``(p - c) / |p - c|``, the normals of the
    allowed planes, and agreement and deviation are measured against the plane.
    """

    type: ClassVar[str] = "sphere"
    centre: Array
    radius: float | None = None

    @classmethod
    def read(cls, r: FieldReader, common: dict[str, Any]) -> SphereField:
        pivot = r.pivot()
        radius = r.fd.get("radius")
        return cls(**common, centre=r.vec("centre"),
                   radius=None if radius is None else r.num("radius", 0.0), pivot=pivot)

    def _parameters(self) -> dict[str, Any]:
        out: dict[str, Any] = {"centre": plain(self.centre)}
        if self.radius is not None:
            out["radius"] = self.radius
        return out

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

    def rigid_part(self, p: Array, R_frame: Array, d: Array) -> tuple[Array, Array, Array] | None:
        """About the centre: the part of ``d`` tangent to the sphere through ``p``."""
        centre = self.centre
        if self.pivot is not None:
            centre = p + R_frame @ self.pivot
            d = d * _pivot_reach(_norm3(centre - self.centre))
        r = p - centre
        rho = _norm3(r)
        if rho < RIGID_MIN_RADIUS:
            return None
        n = r / rho
        t = d - float(d @ n) * n  # tangent to the sphere
        return t, _cross3(n, t) / rho, centre


def sigmoid(x: float | Array, k: float) -> float | Array:
    """Normalised tunable sigmoid of eq. 4.33: ``(x - k x) / (k - 2 k |x| + 1)``.

    Maps [-1, 1] onto [-1, 1] with f(0) = 0, f(+-1) = +-1 and f(x) = x at k = 0;
    k in (0, 1) makes it stricter (needs closer agreement), k in (-1, 0) more lenient.
    """
    return (x - k * x) / (k - 2.0 * k * np.abs(x) + 1.0)
