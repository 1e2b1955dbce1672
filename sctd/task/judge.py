"""A task's predicates on what the scene reports (pure).

Readings are ``{"<element>.<quantity>": value}`` (numbers and flags, :data:`~.model.READINGS`);
positions are the world positions of the published frames, the bodies' origins and
``hand``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from .model import AllOf, AnyOf, Compare, Near, Not, Predicate

Readings = Mapping[str, float | bool]
Positions = Mapping[str, np.ndarray]


def holds(p: Predicate, readings: Readings, positions: Positions) -> bool:
    """Whether ``p`` holds now. A reading or a frame the scene does not report yet makes
    a comparison or a distance false."""
    if isinstance(p, bool):
        return p
    if isinstance(p, Compare):
        x = readings.get(str(p.reading))
        if x is None:
            return False
        if p.is_ is not None:
            return bool(x) == p.is_
        v = float(x)
        return ((p.at_least is None or v >= p.at_least) and (p.at_most is None or v <= p.at_most)
                and (p.above is None or v > p.above) and (p.below is None or v < p.below))
    if isinstance(p, Near):
        a, b = positions.get(p.frame), positions.get(p.to)
        if a is None or b is None:
            return False
        return math.dist(a[:3].tolist(), b[:3].tolist()) < p.within
    if isinstance(p, AllOf):
        return all(holds(t, readings, positions) for t in p.terms)
    if isinstance(p, AnyOf):
        return any(holds(t, readings, positions) for t in p.terms)
    if isinstance(p, Not):
        return not holds(p.term, readings, positions)
    raise TypeError(f"not a predicate: {p!r}")


def thresholds(p: Predicate) -> dict[str, float]:
    """The ``at_least`` bound of each reading a conjunction requires (``{"bottle.poured":
    0.5}`` of ``all: [{reading: bottle.poured, at_least: 0.5}, ...]``): how far a reading
    must go for ``p`` to hold, what a person aims for (the fill target, the opening)."""
    if isinstance(p, Compare) and p.at_least is not None:
        return {str(p.reading): p.at_least}
    if isinstance(p, AllOf):
        out: dict[str, float] = {}
        for t in p.terms:
            out.update(thresholds(t))
        return out
    return {}


def readings_of(p: Predicate) -> list[str]:
    """The readings ``p`` compares, each once, in the order it names them (``near`` names
    frames, not readings)."""
    if isinstance(p, Compare):
        return [str(p.reading)]
    terms = p.terms if isinstance(p, (AllOf, AnyOf)) else (p.term,) if isinstance(p, Not) else ()
    return list(dict.fromkeys(r for t in terms for r in readings_of(t)))
