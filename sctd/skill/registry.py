"""Registries of skill elements: one per element kind, name -> class.

Each kind of element (input mapping, active constraint, transition, vector field) is
one class that holds its parameters, reads and validates them from a skill file, says
what it is for the summary and evaluates itself; the class registers itself under its
``type`` name where it is defined (``@CONSTRAINTS.register``), as python-can's bus
backends do. The loader finds a class by the ``type`` a skill file gives, so adding a
kind of element is adding one class. :func:`plain` is how every summary writes an
array.
"""

from __future__ import annotations

from typing import ClassVar, Generic, Protocol, TypeVar

import numpy as np
from numpy.typing import ArrayLike


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
