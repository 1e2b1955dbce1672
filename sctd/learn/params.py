"""Hyperparameters: each defined once, as a dataclass field of what it configures.

The learners (:class:`~sctd.learn.LinearIMLearner`, :class:`~sctd.learn.VectorFieldLearner`)
and the options around them (:class:`~sctd.learn.Preprocessing`,
:class:`~sctd.learn.SkillOptions`, :class:`~sctd.learn.VectorFieldOptions`) are
dataclasses: the field is the keyword argument, its default and its documentation.
:func:`hyperparameter` adds the one-line help and, where the command line has always
called it differently, the flag; ``sctd.app.options`` derives the flags of
``sctd learn`` from that metadata, so nothing is written twice.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any


class Valid:
    """What values a hyperparameter may take (scikit-learn's parameter constraints):
    :meth:`problem` says what is wrong with a value, "" when nothing is."""

    def problem(self, value: Any) -> str:
        raise NotImplementedError


def _number(value: Any, integer: bool) -> bool:
    if isinstance(value, bool):
        return False
    return isinstance(value, int) if integer else isinstance(value, int | float)


@dataclasses.dataclass(frozen=True)
class Interval(Valid):
    """A number (``integer``: an int) within ``low``..``high`` (None: unbounded), each end
    included unless ``open`` names it (``"low"``, ``"high"``, ``"both"``); ``none``: None
    is allowed too (a seed that means "any")."""

    low: float | None
    high: float | None
    integer: bool = False
    open: str = ""
    none: bool = False

    def __str__(self) -> str:
        left = "(" if self.open in ("low", "both") else "["
        right = ")" if self.open in ("high", "both") else "]"
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        return f"{'an integer' if self.integer else 'a number'} in {left}{lo}, {hi}{right}"

    def problem(self, value: Any) -> str:
        if value is None and self.none:
            return ""
        if not _number(value, self.integer) or not math.isfinite(value):
            return f"expected {self}, got {value!r}"
        lo_open, hi_open = self.open in ("low", "both"), self.open in ("high", "both")
        if self.low is not None and (value < self.low or (lo_open and value == self.low)):
            return f"{value!r} is not {self}"
        if self.high is not None and (value > self.high or (hi_open and value == self.high)):
            return f"{value!r} is not {self}"
        return ""


@dataclasses.dataclass(frozen=True)
class OneOf(Valid):
    """One of ``options`` (strings), or, with ``subset``, a non-empty tuple of them."""

    options: tuple[str, ...]
    subset: bool = False

    def problem(self, value: Any) -> str:
        if self.subset:
            ok = isinstance(value, tuple | list) and value and all(v in self.options for v in value)
            return "" if ok else f"expected a non-empty list of {', '.join(self.options)}, got {value!r}"
        return "" if isinstance(value, str) and value in self.options else \
            f"expected one of {', '.join(self.options)}, got {value!r}"


@dataclasses.dataclass(frozen=True)
class Flag(Valid):
    """true or false (not 0 or 1)."""

    def problem(self, value: Any) -> str:
        return "" if isinstance(value, bool) else f"expected true or false, got {value!r}"


@dataclasses.dataclass(frozen=True)
class Text(Valid):
    """A non-empty string of at most ``longest`` characters."""

    longest: int = 64

    def problem(self, value: Any) -> str:
        if not isinstance(value, str) or not value or len(value) > self.longest:
            return f"expected a non-empty string of at most {self.longest} characters, got {value!r:.40}"
        return ""


SEED = Interval(0, 2**32 - 1, integer=True, none=True)  # a random_state: an int, or None for any


def hyperparameter(default: Any, help: str | None = None, *, valid: Valid, flag: str | None = None,
                   choices: Sequence[str] | None = None, metavar: str | None = None) -> Any:
    """A dataclass field for one hyperparameter, with the values it may take.

    Parameters
    ----------
    default : immutable value
    help : str, optional
        One line for ``--help``; without it the field is no flag of the command line (it
        is still a keyword of :func:`~sctd.learn.learn` and a field of a learner's request).
    valid : Valid
        The values it may take (:func:`check_params` checks them; the command line and
        the learner's requests are refused naming the field).
    flag : str, optional
        The flag when it is not ``--`` plus the field name with dashes.
    choices : sequence of str, optional
        The allowed values the command line lists.
    metavar : str, optional
        The value's name in the usage line.
    """
    meta: dict[str, Any] = {"valid": valid}
    for key, value in (("help", help), ("flag", flag), ("choices", choices), ("metavar", metavar)):
        if value is not None:
            meta[key] = value
    return dataclasses.field(default=default, metadata=meta)


def param_problem(f: dataclasses.Field, value: Any) -> str:
    """What is wrong with ``value`` for the hyperparameter field ``f`` ("" when nothing)."""
    valid = f.metadata.get("valid")
    if valid is None:
        raise TypeError(f"hyperparameter {f.name} declares no valid values")
    return valid.problem(value)


class HyperparameterError(ValueError):
    """A hyperparameter value its field does not allow: ``name`` (the field) and what."""

    def __init__(self, name: str, problem: str):
        self.name, self.problem = name, problem
        super().__init__(f"{name}: {problem}")

    def __reduce__(self) -> tuple:  # it crosses a process (the learner trains in a child)
        return type(self), (self.name, self.problem)


def check_params(obj: Any) -> None:
    """Every hyperparameter of a dataclass estimator or option set is one its field
    allows (scikit-learn's ``_validate_params``).

    Raises
    ------
    HyperparameterError
        For the first one that is not.
    """
    for f in dataclasses.fields(obj):
        if f.init:
            problem = param_problem(f, getattr(obj, f.name))
            if problem:
                raise HyperparameterError(f.name, problem)


def get_params(obj: Any) -> dict[str, Any]:
    """The hyperparameters of a dataclass estimator or option set (scikit-learn's
    ``get_params(deep=False)``): every ``__init__`` field by name, in definition order."""
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.init}
