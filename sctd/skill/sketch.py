"""What a skill's elements look like: plain shapes in the task object's frame.

Each kind of element draws itself (its class's ``sketch``): a tilt cone is a cone, a box
a box, a distance guard a sphere, a fitted sphere field its centre. The shapes are plain
data, in metres and the object frame, with a short label for a person; a view
(``sctd inspect --view``, the live view) decides colours and how to put them on screen.
Nothing here draws, prints or imports a graphics library.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]


def _vec(v) -> Array:
    a = np.asarray(v, dtype=float).reshape(3)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class Shape:
    """Base of the shapes; ``label`` says what it is in a few words."""

    label: str


@dataclass(frozen=True, eq=False)
class Arrow(Shape):
    """From ``origin`` (3,) along ``vector`` (3,; its length is drawn)."""

    origin: Array
    vector: Array

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin", _vec(self.origin))
        object.__setattr__(self, "vector", _vec(self.vector))


@dataclass(frozen=True, eq=False)
class Sphere(Shape):
    """Centred on ``centre`` (3,), of ``radius`` m (a zone, a guard's region)."""

    centre: Array
    radius: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "centre", _vec(self.centre))


@dataclass(frozen=True, eq=False)
class Cuboid(Shape):
    """The axis-aligned box [``lower``, ``upper``] (3, each)."""

    lower: Array
    upper: Array

    def __post_init__(self) -> None:
        object.__setattr__(self, "lower", _vec(self.lower))
        object.__setattr__(self, "upper", _vec(self.upper))


@dataclass(frozen=True, eq=False)
class Cone(Shape):
    """Apex at ``apex`` (3,), opening along the unit ``axis`` (3,) by the half-angle
    ``angle`` (rad), ``length`` m long (a tilt limit)."""

    apex: Array
    axis: Array
    angle: float
    length: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "apex", _vec(self.apex))
        object.__setattr__(self, "axis", _vec(self.axis))


@dataclass(frozen=True, eq=False)
class Plane(Shape):
    """A square of side ``size`` m through ``point`` (3,), normal to the unit ``normal``
    (3,) (a band's bound, a hyperplane guard)."""

    point: Array
    normal: Array
    size: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "point", _vec(self.point))
        object.__setattr__(self, "normal", _vec(self.normal))


@dataclass(frozen=True, eq=False)
class Line(Shape):
    """The segment from ``a`` to ``b`` (3, each) (a cylinder's axis)."""

    a: Array
    b: Array

    def __post_init__(self) -> None:
        object.__setattr__(self, "a", _vec(self.a))
        object.__setattr__(self, "b", _vec(self.b))


@dataclass(frozen=True, eq=False)
class Dots(Shape):
    """Points (n, 3) (a field's centre, the points a model was fitted on)."""

    points: Array

    def __post_init__(self) -> None:
        p = np.asarray(self.points, dtype=float).reshape(-1, 3)
        p.flags.writeable = False
        object.__setattr__(self, "points", p)


def plane_basis(normal: Array) -> tuple[Array, Array]:
    """Two unit vectors (3, each) that span the plane normal to the unit ``normal``."""
    n = np.asarray(normal, dtype=float)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    a = np.cross(n, helper)
    a /= np.linalg.norm(a)
    return a, np.cross(n, a)


def direction_words(v: Array) -> str:
    """A direction (3,) of the object frame in a few characters: ``+z`` along an axis,
    else its unit components ``(0.71, 0.00, -0.71)``."""
    a = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(a))
    if n < 1e-12:
        return "nowhere"
    a = a / n
    i = int(np.argmax(np.abs(a)))
    if abs(a[i]) > 0.995:
        return ("+" if a[i] > 0 else "-") + "xyz"[i]
    return "(" + ", ".join(f"{x:.2f}" for x in a + 0.0) + ")"
