"""Basic vector fields (Ch. 4.2.2, Appendix A.1) and the scaling of eqs. 4.31-4.34.

Shared by the runtime (evaluating a field at the end-effector) and the learner
(deviation angles for RANSAC and EM). Pure numpy; functions over many points are
vectorised.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .model import Field

Array = NDArray[np.float64]


def field_vectors(f: Field, points: ArrayLike) -> Array:
    """Unit field direction at each point (n, 3); zero where it is undefined.

    A sphere field does not fix one direction (any tangent is allowed): this returns
    the radial unit vector ``(p - c) / |p - c|``, the normal of the allowed plane.
    """
    p = np.atleast_2d(np.asarray(points, dtype=float))
    if f.type == "translation":
        assert f.direction is not None
        return np.broadcast_to(f.direction, p.shape).copy()
    if f.type == "cylinder":
        assert f.axis is not None and f.point is not None
        v = np.cross(f.axis, p - f.point)
    else:
        assert f.centre is not None
        v = p - f.centre
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return np.where(n > 1e-9, v / np.maximum(n, 1e-9), 0.0)


def field_vector3(f: Field, p: tuple[float, float, float]) -> tuple[float, float, float]:
    """:func:`field_vectors` at one point, on Python floats (the runtime's tick)."""
    x, y, z = p
    if f.type == "translation":
        assert f.direction is not None
        dx, dy, dz = f.direction.tolist()
        return dx, dy, dz
    if f.type == "cylinder":
        assert f.axis is not None and f.point is not None
        (ax, ay, az), (cx, cy, cz) = f.axis.tolist(), f.point.tolist()
        rx, ry, rz = x - cx, y - cy, z - cz
        vx, vy, vz = ay * rz - az * ry, az * rx - ax * rz, ax * ry - ay * rx
    else:
        assert f.centre is not None
        cx, cy, cz = f.centre.tolist()
        vx, vy, vz = x - cx, y - cy, z - cz
    n = math.sqrt(vx * vx + vy * vy + vz * vz)
    return (vx / n, vy / n, vz / n) if n > 1e-9 else (0.0, 0.0, 0.0)


def agreement3(f: Field, p: tuple[float, float, float], unit: tuple[float, float, float]) -> float:
    """:func:`agreement` on Python floats (the same value)."""
    gx, gy, gz = field_vector3(f, p)
    c = unit[0] * gx + unit[1] * gy + unit[2] * gz
    if f.type == "sphere":
        return math.sqrt(max(0.0, 1.0 - c * c))
    return c


def deviation_angles(f: Field, points: ArrayLike, vectors: ArrayLike) -> Array:
    """Angle (rad) between each unit data vector and what the field allows there (A.1).

    Translation and cylinder fields are directed (angle in [0, pi]); a sphere field
    allows any tangent, so the angle is the one between the vector and the tangent
    plane (in [0, pi/2]).
    """
    v = np.atleast_2d(np.asarray(vectors, dtype=float))
    g = field_vectors(f, points)
    c = np.clip(np.sum(v * g, axis=1), -1.0, 1.0)
    if f.type == "sphere":
        return np.arcsin(np.abs(c))
    defined = np.linalg.norm(g, axis=1) > 0.5
    return np.where(defined, np.arccos(c), np.pi / 2)


def agreement(f: Field, point: ArrayLike, unit_command: ArrayLike) -> float:
    """Cosine agreement ``s`` in [-1, 1] of a unit command with the field at ``point``
    (eq. 4.31); for a sphere field the cosine to the tangent plane, in [0, 1]."""
    g = field_vectors(f, point)[0]
    c = float(np.dot(unit_command, g))
    if f.type == "sphere":
        return float(np.sqrt(max(0.0, 1.0 - c * c)))
    return c


def guided_direction(f: Field, point: ArrayLike, unit_command: ArrayLike) -> Array:
    """The unit direction the field proposes at ``point`` for a command (eq. 4.35's
    ``v_F``): its direction, or for a sphere the command projected onto the tangent
    plane (zero when the command is radial)."""
    g = field_vectors(f, point)[0]
    if f.type != "sphere":
        return g
    u = np.asarray(unit_command, dtype=float)
    t = u - np.dot(u, g) * g
    n = float(np.linalg.norm(t))
    return t / n if n > 1e-9 else np.zeros(3)


def sigmoid(x: float | Array, k: float) -> float | Array:
    """Normalised tunable sigmoid of eq. 4.33: ``(x - k x) / (k - 2 k |x| + 1)``.

    Maps [-1, 1] onto [-1, 1] with f(0) = 0, f(+-1) = +-1 and f(x) = x at k = 0;
    k in (0, 1) makes it stricter (needs closer agreement), k in (-1, 0) more lenient.
    """
    return (x - k * x) / (k - 2.0 * k * np.abs(x) + 1.0)
