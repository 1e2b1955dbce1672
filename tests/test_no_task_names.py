"""No package code names a task: knowledge about a task lives in its task file.

Every ``.py`` under the packages ``sctd``, ``sctd_services`` (``services/``) and
``sctd_sim`` (``sim/``) is parsed, and no string constant outside a docstring may equal
a name a task file gives: a known task's name, its object, its bodies, its joints, its
heads, the held object's name and its frames. The names come from the task files
(:func:`sctd.task.known_tasks`), not from a list here. Tests may name tasks freely; the
defaults a command takes are data (``sctd/app/defaults.yaml``).
"""

from __future__ import annotations

import ast
from pathlib import Path

import sctd
import sctd_services
import sctd_sim
from sctd.task import known_tasks, load_task
from sctd.task.model import Task

# The packages whose code is checked, found where they are imported from.
ROOTS = [Path(m.__file__).resolve().parent for m in (sctd, sctd_services, sctd_sim)]


def names_of(task: Task) -> dict[str, str]:
    """Each name ``task``'s file gives, and what it names."""
    sc = task.scene
    named = [(task.name, "task"), (task.object, "object"), *((b, "body") for b in sc.bodies),
             *((j, "joint") for j in sc.joints), *((h, "head") for h in sc.heads)]
    if sc.held is not None:
        named += [(sc.held.name, "held object"), *((f, "held frame") for f in sc.held.frames)]
    out: dict[str, str] = {}
    for name, what in named:  # a name given twice: what it is first
        out.setdefault(name, what if what == "task" else f"{what} of {task.name}")
    return out


def task_names() -> dict[str, str]:
    """The names every known task's file gives (a name two give: the first's)."""
    out: dict[str, str] = {}
    for known in known_tasks():
        for name, what in names_of(load_task(known.path)).items():
            out.setdefault(name, what)
    return out


def _docstrings(tree: ast.AST) -> set[int]:
    """The ids of the docstring constants of ``tree``: the first statement of the module,
    a class or a function, when it is a string."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) \
                    and isinstance(first.value.value, str):
                found.add(id(first.value))
    return found


def named_in(source: str, names: set[str] | dict[str, str]) -> list[tuple[int, str]]:
    """``(line, name)`` of each string constant of ``source`` outside its docstrings that
    equals one of ``names``, in the order of the source."""
    tree = ast.parse(source)
    docs = _docstrings(tree)
    hits = [(node.lineno, node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)
            and node.value in names and id(node) not in docs]
    return sorted(hits)


def hits_in_packages(names: dict[str, str]) -> list[str]:
    """``file:line: 'name' (what it names)`` for every package file (paths from the
    checkout, ``sctd/...``, ``services/...``, ``sim/...``)."""
    out = []
    for root in ROOTS:
        for path in sorted(root.rglob("*.py")):
            rel = path.relative_to(root.parent).as_posix()
            out += [f"{rel}:{line}: {name!r} ({names[name]})"
                    for line, name in named_in(path.read_text(encoding="utf-8"), names)]
    return out


def test_the_walker_finds_a_name_in_code_and_not_in_docstrings():
    source = '''"""A module about the pour."""
POUR = "pour"


class Scene:
    """pour"""

    def reset(self, task="drawer"):
        """drawer"""
        return f"{task}" + "mug"


async def run():
    "pour"
    x = "pour"
    return ["a pour", x]
'''
    assert named_in(source, {"pour", "drawer", "mug"}) == [(2, "pour"), (8, "drawer"), (10, "mug"),
                                                          (15, "pour")]
    assert named_in(source, {"bottle"}) == []


def test_the_names_come_from_the_task_files():
    names = task_names()
    for expected in ("pour", "drawer", "mug", "drawer_handle", "bottle", "bottle_tip"):
        assert expected in names
    assert names["bottle_tip"] == "held frame of pour"
    assert set(names) >= {k.name for k in known_tasks()}


def test_the_walker_reads_the_packages_from_where_they_are_imported():
    assert [r.name for r in ROOTS] == ["sctd", "services", "sim"] and all(r.is_dir() for r in ROOTS)
    files = [p for r in ROOTS for p in r.rglob("*.py")]
    assert any(p.name == "demogen.py" for p in files) and any(p.name == "options.py" for p in files)


def test_no_package_code_names_a_task():
    hits = hits_in_packages(task_names())
    assert not hits, "package code names a task (its task file should say it):\n" + "\n".join(hits)
