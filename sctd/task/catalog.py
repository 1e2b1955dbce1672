"""Where a task named on the command line is found, and the list ``sctd tasks`` shows.

``--task`` takes a name or a path, resolved in this order:

1. a path to a file that exists (``./tap.yaml``): the task is the file's ``name``
   field, which is what goes on ``sctd/<robot>/demos/<name>/...`` and in learner
   requests, so that another host finds the same task by that name;
2. the shipped tasks, by name (``pour``, ``pour.yaml``): the repository's ``tasks/``
   folder, which the wheel installs as the package data ``sctd_tasks``;
3. tasks other packages register under the entry-point group ``sctd.tasks``: the entry
   point's name is the task's name and its object a path to the task file (a ``str`` or
   ``os.PathLike``) or a function of no arguments that returns one::

       [project.entry-points."sctd.tasks"]
       tap = "mypackage.tasks:tap_file"

A shipped name wins over a registered one of the same name. An unknown name is a
:class:`~.reader.TaskError` that lists the known ones and the closest.
"""

from __future__ import annotations

import difflib
import importlib
import os
from dataclasses import dataclass
from importlib import resources
from importlib.metadata import entry_points
from pathlib import Path

from sctd.files import FileError, load_yaml

from .model import Task
from .reader import TaskError, task_from_document

SHIPPED_PACKAGE = "sctd_tasks"
GROUP = "sctd.tasks"
MAX_TASK_BYTES = 256 * 1024


def shipped_folder() -> Path:
    """The folder of the shipped task files (``tasks/`` of the checkout, or where the wheel
    installed them)."""
    return Path(str(resources.files(SHIPPED_PACKAGE)))


def load_task(path: str | Path) -> Task:
    """Read and validate the task file ``path`` (a regular file of at most 256 KiB)."""
    try:
        doc = load_yaml(path, MAX_TASK_BYTES)
    except FileError as e:
        raise TaskError(e.file, e.where, e.problem) from None
    return task_from_document(doc, os.fspath(path))


@dataclass(frozen=True)
class Known:
    """A task ``sctd tasks`` lists: its name, where it comes from and its file."""

    name: str
    origin: str  # "shipped" or "entry point <module:attr>"
    path: Path


def _registered() -> list[tuple[str, str]]:
    """(name, entry point value) of the ``sctd.tasks`` entry points."""
    return sorted((ep.name, ep.value) for ep in entry_points(group=GROUP))


def _entry_point_path(name: str, value: str) -> Path:
    module, _, attr = value.partition(":")
    try:
        obj = importlib.import_module(module)
        for part in filter(None, attr.split(".")):
            obj = getattr(obj, part)
        target = obj() if callable(obj) else obj
        return Path(os.fspath(target))
    except Exception as e:  # a broken plug-in: say which and why, keep the others
        raise TaskError(f"task {name!r}", "", f"entry point {value} ({GROUP}) does not give a task "
                                              f"file: {type(e).__name__}: {e}") from e


def known_tasks() -> list[Known]:
    """The shipped tasks, then the registered ones not shadowed by a shipped name."""
    shipped = [Known(p.stem, "shipped", p) for p in sorted(shipped_folder().glob("*.yaml"))]
    names = {k.name for k in shipped}
    extra = [Known(n, f"entry point {v}", _entry_point_path(n, v))
             for n, v in _registered() if n not in names]
    return shipped + extra


def find_task(ref: str | Path) -> Task:
    """The task ``ref`` names: a file, a shipped task or a registered one (see the module
    doc). A task found by name must carry that name."""
    path = Path(ref)
    if path.is_file():
        return load_task(path)
    name = path.name.removesuffix(".yaml") if path.suffix == ".yaml" else str(ref)
    shipped = shipped_folder() / f"{name}.yaml"
    if shipped.is_file():
        found = shipped
    else:
        value = dict(_registered()).get(name)
        if value is None:
            names = [*sorted(p.stem for p in shipped_folder().glob("*.yaml")), *(n for n, _ in _registered())]
            close = difflib.get_close_matches(name, names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise TaskError(str(ref), "", f"no such file, and no task of that name (known: "
                                          f"{', '.join(names)}){hint}")
        found = _entry_point_path(name, value)
    task = load_task(found)
    if task.name != name:
        raise TaskError(str(found), "name", f"the task found as {name!r} is named {task.name!r}")
    return task


def task_for_object(obj: str) -> Task | None:
    """The one known task whose task object is ``obj`` (a skill's ``object``), or None
    when no task or several have it. A registered task that does not load is passed
    over here: ``sctd tasks`` names it."""
    found = []
    for k in known_tasks():
        try:
            t = load_task(k.path)
        except TaskError:
            continue
        if t.object == obj:
            found.append(t)
    return found[0] if len(found) == 1 else None
