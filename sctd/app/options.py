"""Command-line flags derived from a dataclass: each parameter is defined once.

A parameter is a dataclass field; its default, type and documentation live there, and
the flag comes from it. The field's ``metadata`` (a plain dict, so the defining layer
needs no import from here) says how:

``help`` (required for a flag)
    The help text; fields without it get no flag (they keep their default).
``flag`` (optional)
    The flag's name when it is not ``--`` plus the field name with ``-`` for ``_``
    (``smoothness`` -> ``--lambda``, ``random_state`` -> ``--seed``).
``choices`` (optional)
    The allowed values.
``metavar`` (optional)
    The value's name in the usage line (default the field name in capitals).
``repeatable`` (optional)
    The flag may be given more than once, each time one element of the field's tuple
    (``--mistake 2 --mistake 5`` for ``mistakes: tuple[int, ...]``); without it a tuple
    of names is given comma-separated (``--frames a,b``).

Booleans become switches: a field defaulting to False is set by its flag
(``--dtw-align``), one defaulting to True is cleared by it (``--no-despike``, whose
name the ``flag`` entry gives). The argparse destination is always the field name, so
:func:`from_namespace` builds the dataclass back from the parsed namespace::

    add_arguments(parser, LinearIMLearner)
    learner = from_namespace(LinearIMLearner, parser.parse_args())

A default kept in ``sctd/app/defaults.yaml`` (:mod:`.defaults`) replaces the field's
with ``parser.set_defaults(name=...)`` after :func:`add_arguments`. Each flag made here
remembers its field (:func:`field_of`): ``tests/test_cli_fields.py`` fails when a flag
that sets a field of a command's options is written by hand instead.

Adding a parameter is adding a field with ``help`` metadata to the class the command
builds; its flag, help, default and type follow, and nothing else is written.
"""

from __future__ import annotations

import argparse
import dataclasses
import types
import typing
from collections.abc import Collection
from typing import Any, TypeVar

from ..wire import DEFAULT_ROBOT
from ..wire.session import add_zenoh_arguments

__all__ = ["SKILL_HELP", "TASK_HELP", "add_arguments", "add_deprecated_alias", "add_robot_argument",
           "add_task_argument", "add_zenoh_arguments", "check_ranges", "field_of", "flag_name",
           "from_namespace"]

T = TypeVar("T")
_FIELD = "sctd_field"  # the attribute of an argparse action made from a field: (class, field name)

# The help of every --skill / SKILL argument: how sctd.skill.catalog.find_skill resolves it.
SKILL_HELP = ("a skill: a path, a skill in the learner's store (NAME@ID, ID, or NAME: the newest), or "
              "the name of a shipped skill (pour, pour.yaml); sctd skills lists them")


def flag_name(field: dataclasses.Field) -> str:
    """The flag of a field: its ``flag`` metadata, else ``--`` + the name with dashes."""
    return str(field.metadata.get("flag") or "--" + field.name.replace("_", "-"))


def _scalar_type(hint: Any) -> Any:
    """``int`` of ``int | None``; the hint itself otherwise."""
    if isinstance(hint, types.UnionType) or typing.get_origin(hint) is typing.Union:
        args = [a for a in typing.get_args(hint) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return hint


def _names(text: str) -> tuple[str, ...]:
    """A flag's comma-separated names (``a,b``) as a tuple."""
    return tuple(x.strip() for x in text.split(",") if x.strip())


def add_arguments(parser: argparse.ArgumentParser | argparse._ArgumentGroup, cls: type,
                  only: Collection[str] | None = None, exclude: Collection[str] = (),
                  show_default: bool = False, dest_prefix: str = "", help_prefix: str = "") -> None:
    """Add one flag per documented field of dataclass ``cls`` to ``parser``.

    Parameters
    ----------
    parser : ArgumentParser or argument group
    cls : dataclass type
        Fields with ``help`` metadata become flags, in definition order.
    only : collection of str, optional
        Field names to add (default: every documented field).
    exclude : collection of str
        Field names to leave out (a flag another call adds, or a differently grouped one).
    show_default : bool
        End each help text of a flag taking a value with ``(default <value>)`` (but for a
        default of None, which the help says in words).
    dest_prefix : str
        Prefix of the argparse destinations (``emg_`` keeps a device's filter settings
        apart from other flags); :func:`from_namespace` takes the same prefix.
    help_prefix : str
        Prefix of every help text (``--calibrate: ``: the flag matters only there).

    Raises
    ------
    TypeError
        ``cls`` is not a dataclass, or a name in ``only`` is no documented field of it.
    """
    documented = [f for f in dataclasses.fields(cls) if "help" in f.metadata]
    unknown = set(only or ()) - {f.name for f in documented}
    if unknown:
        raise TypeError(f"{cls.__name__} has no documented field {', '.join(sorted(unknown))}")
    hints = typing.get_type_hints(cls)
    for f in documented:
        if (only is not None and f.name not in only) or f.name in exclude:
            continue
        kind = _scalar_type(hints[f.name])
        kwargs: dict[str, Any] = {"dest": dest_prefix + f.name, "help": help_prefix + f.metadata["help"],
                                  "default": f.default}
        if f.metadata.get("repeatable"):  # one element each time (argparse appends to a list)
            kind, kwargs["action"] = typing.get_args(kind)[0], "append"
            kwargs["default"] = list(f.default)  # type: ignore[arg-type]
            kwargs["help"] += " (repeatable)"
        elif typing.get_origin(kind) is tuple:  # a list of names, given comma-separated
            kind = _names
        if kind is bool:
            kwargs["action"] = "store_false" if f.default else "store_true"
        else:
            if show_default and f.default is not None:
                kwargs["help"] += " (default %(default)s)"
            kwargs["type"] = kind
            if f.metadata.get("choices") is not None:
                kwargs["choices"] = tuple(f.metadata["choices"])
            if f.metadata.get("metavar") is not None:
                kwargs["metavar"] = f.metadata["metavar"]
        setattr(parser.add_argument(flag_name(f), **kwargs), _FIELD, (cls, f.name))


def field_of(action: argparse.Action) -> tuple[type, str] | None:
    """(dataclass, field name) of a flag :func:`add_arguments` made; None for a flag
    written by hand."""
    return getattr(action, _FIELD, None)


def from_namespace(cls: type[T], namespace: argparse.Namespace, dest_prefix: str = "") -> T:
    """An instance of dataclass ``cls`` with every field the namespace holds (by field
    name after ``dest_prefix``, as :func:`add_arguments` stores them); the other fields
    keep their defaults."""
    given = vars(namespace)
    values = {f.name: given[dest_prefix + f.name] for f in dataclasses.fields(cls)  # type: ignore[arg-type]
              if f.init and dest_prefix + f.name in given}
    for f in dataclasses.fields(cls):  # type: ignore[arg-type]
        if f.metadata.get("repeatable") and isinstance(values.get(f.name), list):
            values[f.name] = tuple(values[f.name])
    return cls(**values)


def check_ranges(obj: Any, zero_allowed: Collection[str] = ()) -> None:
    """Every float field of dataclass instance ``obj`` is > 0 (>= 0 for the names in
    ``zero_allowed``, where 0 means none); ValueError naming the flag otherwise (NaN
    fails both)."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        zero_ok = f.name in zero_allowed
        if isinstance(value, float) and not (value >= 0 if zero_ok else value > 0):
            raise ValueError(f"{flag_name(f)}: must be {'>= 0' if zero_ok else '> 0'}")


def add_robot_argument(parser: argparse.ArgumentParser | argparse._ArgumentGroup,
                       default: str | None = DEFAULT_ROBOT, help: str | None = None) -> None:
    """``--robot NAME``: the robot whose keys (``sctd/<robot>/...``) a program uses; one
    definition for every program. ``default`` None with a ``help`` of the caller's
    for a program that otherwise takes the name from elsewhere (a log's keys)."""
    parser.add_argument("--robot", default=default, metavar="NAME",
                        help=help or "the robot's name, the key prefix sctd/<robot> (default %(default)s)")


TASK_HELP = ("a task: the path of a task file, or the name of a shipped or registered one (pour, "
             "drawer); sctd tasks lists them")


class _DeprecatedAlias(argparse.Action):
    """Sets the destination like the flag it stands for, and says it is deprecated."""

    def __init__(self, option_strings: list[str], dest: str, instead: str = "", **kwargs: Any):
        self.instead = instead
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        import sys

        print(f"{parser.prog}: {option_string} is deprecated (it goes in the next release): use "
              f"{self.instead}", file=sys.stderr, flush=True)
        setattr(namespace, self.dest, values)


def add_deprecated_alias(parser: argparse.ArgumentParser | argparse._ArgumentGroup, option: str, dest: str,
                         instead: str, **kwargs: Any) -> None:
    """``option``, a flag of the previous release, kept as a deprecated alias: it sets
    ``dest`` as the flag ``instead`` does (``kwargs``: its ``type``, ...), is left out of
    ``--help`` and says on stderr that it is deprecated."""
    parser.add_argument(option, dest=dest, action=_DeprecatedAlias, instead=instead,
                        help=argparse.SUPPRESS, **kwargs)


class _Several(argparse.Action):
    """A repeatable flag whose default is one value: the first one given replaces the
    default, each further one is added (the destination becomes a list)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: Any,
                 option_string: str | None = None) -> None:
        now = getattr(namespace, self.dest, None)
        setattr(namespace, self.dest, [*now, values] if isinstance(now, list) else [values])


def add_task_argument(parser: argparse.ArgumentParser | argparse._ArgumentGroup,
                      default: str | None, help: str | None = None, several: bool = False) -> None:
    """``--task NAME|FILE`` (:func:`sctd.task.find_task` resolves it), and ``--scene``, its
    deprecated alias of the previous release, which says so on stderr. ``default``: a
    command's default task (from :mod:`sctd.app.defaults`), or None for none. With
    ``several``, ``--task`` may be given more than once (several tasks in one room,
    :func:`sctd.task.compose.compose`): the destination is then a list of them."""
    more = " (repeatable: several tasks' objects in one room)" if several else ""
    action: Any = _Several if several else "store"
    parser.add_argument("--task", default=default, metavar="NAME|FILE", action=action,
                        help=(help or TASK_HELP) + more + (" (default %(default)s)" if default else ""))
    parser.add_argument("--scene", dest="task", action=_DeprecatedAlias, instead="--task",
                        help=argparse.SUPPRESS)
