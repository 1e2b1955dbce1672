"""The tasks and skills sctd's commands and benchmarks take when not told, read from the
package data file ``defaults.yaml`` beside this module.

Knowledge about a task lives in its task file, and no code names a task; a command
still needs a task or skill to start with (``sctd sim``'s scene, ``sctd demo``'s skill,
a benchmark's workload). Those choices are data, in one file a user can read::

    sctd_defaults: 1
    task: pour              # sctd sim --task, the stand-in robot, the benchmarks' scene
    skill: pour             # a hand-written skill of it: sctd demo --skill, ...
    learned_skill: pour-vf  # a learned one: sctd bench eval --skill, sctd bench vf --skill
    bench_learn: {tilt: pour, pull: drawer, fields: [pour, drawer, crank, wipe]}
    gripper: {force: 20, open_hold: 0.5}  # sctd run --grasp-force, --grasp-open-hold

It lives here, not among the shipped tasks or skills: ``sctd_tasks`` and
``sctd_skills`` are catalogs that take every ``*.yaml`` in their folder for a task or
a skill, and this file chooses both.

Only the edge reads it (argument parsers, the benchmarks, the multihost cluster), once
per process. A missing or malformed file is a :class:`DefaultsError` naming the file,
the field and the problem; ``sctd`` reports it as ``sctd <command>: <file>: <field>:
<problem>`` and exits 2.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from ..files import FileError, load_yaml

__all__ = ["DEFAULTS_FILE", "BenchLearn", "Defaults", "DefaultsError", "GripperDefaults", "defaults",
           "defaults_from_document", "load_defaults"]

VERSION = 1
MAX_BYTES = 64 * 1024


DEFAULTS_FILE = Path(str(resources.files("sctd.app") / "defaults.yaml"))
"""The shipped file (package data of ``sctd.app``)."""


class DefaultsError(FileError):
    """The defaults file is missing or malformed: ``file: field: problem``."""


@dataclass(frozen=True)
class BenchLearn:
    """The generated demonstrations ``sctd bench learn`` measures on.

    Attributes
    ----------
    tilt : str
        A task whose held contents are tilted out (the linear IMs, the sphere).
    pull : str
        A task whose joint is pulled (the translation fields).
    fields : tuple of str
        The kinds whose field types the report compares, in its order.
    """

    tilt: str
    pull: str
    fields: tuple[str, ...]


@dataclass(frozen=True)
class GripperDefaults:
    """What the runtime's grasp button does (``sctd run --grasp-force``,
    ``--grasp-open-hold``; docs/wire-contract.md, "The gripper").

    Attributes
    ----------
    force : float
        N: the force bound of a close the grasp button asks for.
    open_hold : float
        s the grasp button must be held to open a hand that holds something.
    """

    force: float
    open_hold: float


@dataclass(frozen=True)
class Defaults:
    """What ``defaults.yaml`` says (its comments say who takes what).

    Attributes
    ----------
    task : str
        The task of the simulator, the stand-in robot and the simulated user.
    skill : str
        A hand-written skill of that task.
    learned_skill : str
        A learned skill of that task.
    bench_learn : BenchLearn
    gripper : GripperDefaults
    """

    task: str
    skill: str
    learned_skill: str
    bench_learn: BenchLearn
    gripper: GripperDefaults


def _name(doc: dict[str, Any], key: str, file: str, where: str = "") -> str:
    field = f"{where}.{key}" if where else key
    if key not in doc:
        raise DefaultsError(file, field, "missing")
    value = doc[key]
    if not isinstance(value, str) or not value.strip():
        raise DefaultsError(file, field, f"expected a task's or skill's name, got {value!r}")
    return value


def _mapping(doc: Any, file: str, where: str, keys: tuple[str, ...]) -> dict[str, Any]:
    if not isinstance(doc, dict):
        raise DefaultsError(file, where, f"expected a mapping, got {type(doc).__name__}")
    unknown = sorted(set(doc) - set(keys), key=str)
    if unknown:
        raise DefaultsError(file, where, f"unknown field {unknown[0]!r} (known: {', '.join(keys)})")
    return doc


def defaults_from_document(doc: Any, file: str) -> Defaults:
    """Validate a parsed defaults document (``file``: its name in errors), field by
    field in the file's order."""
    top = _mapping(doc, file, "", ("sctd_defaults", "task", "skill", "learned_skill", "bench_learn",
                                   "gripper"))
    if top.get("sctd_defaults") != VERSION:
        raise DefaultsError(file, "sctd_defaults", f"expected {VERSION}, got {top.get('sctd_defaults')!r}")
    task, skill, learned = (_name(top, key, file) for key in ("task", "skill", "learned_skill"))
    if "bench_learn" not in top:
        raise DefaultsError(file, "bench_learn", "missing")
    bl = _mapping(top["bench_learn"], file, "bench_learn", ("tilt", "pull", "fields"))
    tilt, pull = _name(bl, "tilt", file, "bench_learn"), _name(bl, "pull", file, "bench_learn")
    fields = bl.get("fields")
    if not isinstance(fields, list) or not fields:
        raise DefaultsError(file, "bench_learn.fields", f"expected a list of names, got {fields!r}")
    for k, name in enumerate(fields):
        if not isinstance(name, str) or not name.strip():
            raise DefaultsError(file, f"bench_learn.fields[{k}]", f"expected a name, got {name!r}")
    return Defaults(task, skill, learned, BenchLearn(tilt, pull, tuple(fields)), _gripper(top, file))


def _gripper(top: dict[str, Any], file: str) -> GripperDefaults:
    if "gripper" not in top:
        raise DefaultsError(file, "gripper", "missing")
    g = _mapping(top["gripper"], file, "gripper", ("force", "open_hold"))
    values = []
    for key, hi in (("force", 1000.0), ("open_hold", 10.0)):  # (force: the wire contract's bound)
        if key not in g:
            raise DefaultsError(file, f"gripper.{key}", "missing")
        x = g[key]
        if isinstance(x, bool) or not isinstance(x, int | float) or not 0.0 < x <= hi:
            raise DefaultsError(file, f"gripper.{key}", f"expected a number in (0, {hi:g}], got {x!r}")
        values.append(float(x))
    return GripperDefaults(*values)


def load_defaults(path: str | Path) -> Defaults:
    """Read and validate the defaults file ``path``."""
    try:
        doc = load_yaml(path, MAX_BYTES)
    except FileError as e:
        raise DefaultsError(e.file, e.where, e.problem) from None
    return defaults_from_document(doc, os.fspath(path))


@functools.cache
def defaults() -> Defaults:
    """The shipped defaults (:data:`DEFAULTS_FILE`), read once per process."""
    return load_defaults(DEFAULTS_FILE)
