"""Registries of skill elements: one per element kind, name -> class.

Each kind of element (input mapping, active constraint, transition, vector field) is
one class that holds its parameters, reads and validates them from a skill file
(``from_yaml``), writes them back (``to_yaml``: the plain dict ``from_yaml`` reads),
says what it is for the summary and evaluates itself; the class registers itself under
its ``type`` name where it is defined (``@CONSTRAINTS.register``), as python-can's bus
backends do. The loader finds a class by the ``type`` a skill file gives, so adding a
kind of element is adding one class.

What every kind shares: :class:`ByValue`, equality parameter by parameter (arrays by
value); :func:`summarised`, how a summary shows an element's document (:func:`plain`,
how it writes an array); :func:`unit_divisor`, how a reader normalises a direction so
that a direction written reads back the same.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any, ClassVar, Generic, Protocol, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray


class _Element(Protocol):
    type: ClassVar[str]


E = TypeVar("E", bound=_Element)


class Registry(Generic[E]):
    """The classes of one kind of element, by their ``type`` name, in registration order.

    Parameters
    ----------
    kind : str
        What the elements are (for messages): ``"active constraint"``, ...
    """

    def __init__(self, kind: str):
        self.kind = kind
        self._classes: dict[str, type[E]] = {}

    def register(self, cls: type[E]) -> type[E]:
        """Class decorator: register ``cls`` under ``cls.type``; a name is taken once."""
        name = cls.type
        if name in self._classes:
            raise ValueError(f"{self.kind} type {name!r} is already registered "
                             f"({self._classes[name].__qualname__})")
        self._classes[name] = cls
        return cls

    def names(self) -> tuple[str, ...]:
        """The registered ``type`` names, in registration order."""
        return tuple(self._classes)

    def __getitem__(self, name: str) -> type[E]:
        return self._classes[name]

    def __contains__(self, name: object) -> bool:
        return name in self._classes


def plain(a: ArrayLike) -> list:
    """An array as the nested list of floats (rounded to 12 decimals) a summary holds."""
    return np.asarray(a, dtype=float).round(12).tolist()


def summarised(doc: dict[str, Any]) -> dict[str, Any]:
    """An element's document (its ``to_yaml``) as a summary shows it: each array (a list
    of numbers, nested or not) written by :func:`plain`, the rest as it is."""
    return {k: plain(v) if isinstance(v, list) and _numbers(v) else v for k, v in doc.items()}


def _numbers(v: Any) -> bool:
    if isinstance(v, list):
        return all(_numbers(x) for x in v)
    return isinstance(v, int | float) and not isinstance(v, bool)


# A normalised vector's norm is within 1.5 ulps of 1 (measured over millions of 3- and
# 4-vectors); dividing it by that norm again moves a third of them by an ulp.
UNIT_ROUNDING = 4 * float(np.finfo(float).eps)


def unit_divisor(norm: NDArray[np.float64] | float) -> Any:
    """What to divide vectors of norm ``norm`` (a float, or an array of norms) by to
    make them unit: the norm, or 1 where the vector is unit already to within rounding
    (:data:`UNIT_ROUNDING`). Normalising a normalised vector then changes nothing, so a
    direction a skill file or model file holds reads back as the same numbers."""
    if isinstance(norm, float):
        return 1.0 if abs(norm - 1.0) <= UNIT_ROUNDING else norm
    return np.where(np.abs(norm - 1.0) <= UNIT_ROUNDING, 1.0, norm)


def equal(a: Any, b: Any) -> bool:
    """Whether two parameter values are the same: arrays by shape and value,
    dataclasses field by compared field, sequences and mappings item by item."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape
                and bool(np.array_equal(a, b)))
    if dataclasses.is_dataclass(a) and not isinstance(a, type):
        return type(a) is type(b) and all(equal(getattr(a, f.name), getattr(b, f.name))
                                          for f in dataclasses.fields(a) if f.compare)
    if isinstance(a, list | tuple):
        return (isinstance(b, list | tuple) and len(a) == len(b)
                and all(equal(x, y) for x, y in zip(a, b, strict=True)))
    if isinstance(a, Mapping):
        return isinstance(b, Mapping) and a.keys() == b.keys() and all(equal(a[k], b[k]) for k in a)
    return bool(a == b)


class ByValue:
    """Equality for frozen dataclasses of parameters (the elements, frames, vector-field
    models): the same class with the same parameters (:func:`equal`; a dataclass's own
    ``==`` cannot compare arrays). Each subclass is declared with ``eq=False`` so that
    it keeps this one."""

    def __eq__(self, other: object) -> bool:
        if type(other) is not type(self):
            return NotImplemented
        return equal(self, other)

    def __hash__(self) -> int:
        """From the kind and its scalar parameters (equal elements hash alike)."""
        return hash((type(self), *(v for f in dataclasses.fields(self)  # type: ignore[arg-type]
                                   if f.compare and isinstance(v := getattr(self, f.name),
                                                               str | int | float | None))))
