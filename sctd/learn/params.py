"""Hyperparameters: each defined once, as a dataclass field of what it configures.

The learners (:class:`~sctd.learn.LinearIMLearner`, :class:`~sctd.learn.VectorFieldLearner`)
and the options around them (:class:`~sctd.learn.Preprocessing`,
:class:`~sctd.learn.SkillOptions`, :class:`~sctd.learn.VectorFieldOptions`) are
dataclasses: the field is the keyword argument, its default and its documentation.
:func:`hyperparameter` adds the one-line help and, where the command line has always
called it differently, the flag; ``sctd.cli.options`` derives the flags of
``sctd learn`` from that metadata, so nothing is written twice.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any


def hyperparameter(default: Any, help: str, *, flag: str | None = None,
                   choices: Sequence[str] | None = None, metavar: str | None = None) -> Any:
    """A dataclass field for one hyperparameter shown on the command line.

    Parameters
    ----------
    default : immutable value
    help : str
        One line for ``--help``.
    flag : str, optional
        The flag when it is not ``--`` plus the field name with dashes.
    choices : sequence of str, optional
        The allowed values (checked by the command line; the estimator checks in ``fit``).
    metavar : str, optional
        The value's name in the usage line.
    """
    meta: dict[str, Any] = {"help": help}
    for key, value in (("flag", flag), ("choices", choices), ("metavar", metavar)):
        if value is not None:
            meta[key] = value
    return dataclasses.field(default=default, metadata=meta)


def get_params(obj: Any) -> dict[str, Any]:
    """The hyperparameters of a dataclass estimator or option set (scikit-learn's
    ``get_params(deep=False)``): every ``__init__`` field by name, in definition order."""
    return {f.name: getattr(obj, f.name) for f in dataclasses.fields(obj) if f.init}
