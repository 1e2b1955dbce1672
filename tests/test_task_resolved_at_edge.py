"""A task is resolved from its name or file once, where a program starts; below, code
takes a :class:`~sctd.task.Task`.

Every ``.py`` of the packages ``sctd``, ``sctd_services`` (``services/``) and ``sctd_sim``
(``sim/``) is parsed, and a call of :func:`sctd.task.find_task` may stand only in the
places :data:`ALLOWED` lists: the command line's modules, and the few entry points that
read a program's own arguments or receive a task's name across a process or wire
boundary, where a name is what travels.
"""

from __future__ import annotations

import ast
from pathlib import Path

import sctd
import sctd_services
import sctd_sim

ROOTS = [Path(m.__file__).resolve().parent for m in (sctd, sctd_services, sctd_sim)]

ALLOWED_PACKAGES = {
    "sctd/cli/": "the command line: argument parsing turns --task NAME|FILE into a task",
    "sctd/bench/": "the `sctd bench` commands (the application layer beside sctd/cli): their "
                   "flags and the workloads sctd/app/defaults.yaml names",
}
"""Folders whose every module may resolve a task."""

ALLOWED: dict[tuple[str, str], str] = {
    ("sim/service.py", "_settings_from_args"): "`sctd sim`'s flags",
    ("sim/kinematic.py", "main"): "`python -m sctd_sim.kinematic`'s argv",
    ("sim/demogen.py", "main"): "`python -m sctd_sim.demogen`'s argv",
    ("services/simulated_user.py", "main"): "`python -m sctd_services.simulated_user`'s argv "
                                            "(a real-time trial starts it with --task)",
    ("services/robots/service.py", "_setup"): "`sctd robot NAME`'s flags",
    ("services/teach/demonstrator.py", "TeachOptions.__post_init__"):
        "`sctd teach`'s options, whose fields are its flags, checked as they are made",
    ("services/learner/check.py", "evaluable"): "a learner request names its task over the wire",
    ("services/eval/evaluate.py", "lockstep_job"): "a trial worker (another process, spawned or a "
                                                  "cluster's) receives the task's name in its TaskSpec",
}
"""(module, function) pairs that may resolve a task, and why."""


def calls_in(source: str) -> list[tuple[int, str]]:
    """``(line, enclosing function)`` of each call of ``find_task`` in ``source`` (by that
    name, as an attribute ``x.find_task``, or under a name it was imported as); the
    function is qualified by its classes and functions (``Class.method``), ``""`` at
    module level."""
    tree = ast.parse(source)
    names = {"find_task"} | {a.asname for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
                             for a in node.names if a.name == "find_task" and a.asname}
    out: list[tuple[int, str]] = []

    def visit(node: ast.AST, scope: tuple[str, ...]) -> None:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            scope = (*scope, node.name)
        if isinstance(node, ast.Call):
            f = node.func
            if (isinstance(f, ast.Name) and f.id in names) or (isinstance(f, ast.Attribute)
                                                               and f.attr == "find_task"):
                out.append((node.lineno, ".".join(scope)))
        for child in ast.iter_child_nodes(node):
            visit(child, scope)

    visit(tree, ())
    return sorted(out)


def allowed(module: str, function: str) -> bool:
    return any(module.startswith(p) for p in ALLOWED_PACKAGES) or (module, function) in ALLOWED


def violations(module: str, source: str) -> list[str]:
    """``file:line: in function`` for each call of ``find_task`` in ``source`` (the module
    ``module``, as ``sim/scenes.py``) that :data:`ALLOWED` does not list."""
    return [f"{module}:{line}: find_task in {fn or '<module>'}" for line, fn in calls_in(source)
            if not allowed(module, fn)]


def package_modules() -> list[tuple[str, Path]]:
    return [(p.relative_to(root.parent).as_posix(), p) for root in ROOTS for p in sorted(root.rglob("*.py"))]


def test_the_walker_finds_every_call_and_its_function():
    source = '''"""find_task(x) in a docstring is no call."""
from sctd import task
from sctd.task import find_task as resolve

T = find_task("a")


class Scene:
    def reset(self, ref):
        def inner():
            return task.find_task(ref)
        return inner()


def make(ref):
    return resolve(ref)
'''
    assert calls_in(source) == [(5, ""), (11, "Scene.reset.inner"), (16, "make")]
    assert violations("sim/scenes.py", source) == ["sim/scenes.py:5: find_task in <module>",
                                                   "sim/scenes.py:11: find_task in Scene.reset.inner",
                                                   "sim/scenes.py:16: find_task in make"]


def test_the_check_fails_on_a_call_below_the_edge_and_passes_the_listed_ones():
    source = "from sctd.task import find_task\n\ndef main(argv):\n    return find_task(argv[0])\n"
    assert violations("sim/kinematic.py", source) == []  # listed: the program's main
    assert violations("sctd/cli/anything.py", source) == []  # the command line
    assert violations("sim/scenes.py", source) == ["sim/scenes.py:4: find_task in main"]
    assert violations("services/eval/trial.py", source.replace("main", "run_trial")) == [
        "services/eval/trial.py:4: find_task in run_trial"]


def test_every_listed_entry_point_exists_and_resolves_a_task():
    modules = dict(package_modules())
    for module, function in ALLOWED:
        assert module in modules, f"{module}: listed, not in the packages"
        found = [fn for _, fn in calls_in(modules[module].read_text(encoding="utf-8"))]
        assert function in found, f"{module}: {function} is listed but calls no find_task (drop it)"


def test_a_task_is_resolved_only_at_the_edge():
    hits = [v for module, path in package_modules()
            for v in violations(module, path.read_text(encoding="utf-8"))]
    assert not hits, ("find_task called below a program's edge (take a Task; resolve a name where the "
                      "program starts or where it arrives, and list that place in ALLOWED):\n"
                      + "\n".join(hits))
