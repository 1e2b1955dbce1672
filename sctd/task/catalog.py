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

4. task files in the folders ``$SCTD_TASK_PATH`` lists (separated as ``PATH`` is), by
   their ``name`` field: a learner on another host finds a task written there by the
   name the demonstrations carry. ``sctd teach --task FILE`` adds the file's folder for
   the processes it starts.

A shipped name wins over a registered one of the same name, and both over one on the
path. An unknown name is a
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
PATH_VARIABLE = "SCTD_TASK_PATH"
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


def _on_path() -> list[Known]:
    """The task files in the folders of ``$SCTD_TASK_PATH``, by their ``name`` field, in
    the variable's order (a file that does not load as a task is passed over: a folder
    may hold skills too)."""
    out = []
    for folder in filter(None, os.environ.get(PATH_VARIABLE, "").split(os.pathsep)):
        for f in sorted(Path(folder).glob("*.yaml")):
            try:
                name = load_task(f).name
            except TaskError:
                continue
            out.append(Known(name, f"{PATH_VARIABLE} {folder}", f))
    return out


def add_to_path(ref: str | Path) -> None:
    """When ``ref`` is a task file, put its folder first on ``$SCTD_TASK_PATH`` of this
    process (and so of the processes it starts), so that they find the task by name."""
    path = Path(ref)
    if path.is_file():
        now = filter(None, os.environ.get(PATH_VARIABLE, "").split(os.pathsep))
        folders = [str(path.resolve().parent), *now]
        os.environ[PATH_VARIABLE] = os.pathsep.join(dict.fromkeys(folders))


def known_tasks() -> list[Known]:
    """The shipped tasks, then the registered ones not shadowed by a shipped name, then
    the ones on ``$SCTD_TASK_PATH`` not shadowed by either (nor by one earlier on it)."""
    shipped = [Known(p.stem, "shipped", p) for p in sorted(shipped_folder().glob("*.yaml"))]
    names = {k.name for k in shipped}
    extra = [Known(n, f"entry point {v}", _entry_point_path(n, v))
             for n, v in _registered() if n not in names]
    names |= {k.name for k in extra}
    on_path = []
    for k in _on_path():
        if k.name not in names:
            names.add(k.name)
            on_path.append(k)
    return shipped + extra + on_path


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
        on_path = {k.name: k.path for k in reversed(_on_path())} if value is None else {}
        if value is not None:
            found = _entry_point_path(name, value)
        elif name in on_path:
            found = on_path[name]
        else:
            names = [*sorted(p.stem for p in shipped_folder().glob("*.yaml")), *(n for n, _ in _registered()),
                     *sorted(on_path)]
            close = difflib.get_close_matches(name, names, n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise TaskError(str(ref), "", f"no such file, and no task of that name (known: "
                                          f"{', '.join(names)}){hint}")
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
