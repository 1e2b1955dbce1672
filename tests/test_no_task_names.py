"""No package code names a task: knowledge about a task lives in its task file.

Every ``.py`` under the packages ``sctd``, ``sctd_services`` (``services/``) and
``sctd_sim`` (``sim/``) is parsed, with two checks on the names the task files give: a
known task's name, its object, its bodies, its joints, its heads, the held object's name
and its frames. The names come from the task files (:func:`sctd.task.known_tasks`), not
from a list here. Tests may name tasks freely; the defaults a command takes are data
(``sctd/app/defaults.yaml``).

1. **Constants**: no string constant outside a docstring equals such a name.
2. **Names in code**: no identifier (a function's, class's, variable's, attribute's,
   parameter's or keyword argument's name, an import's alias), no default (a parameter's
   default, any ``default=`` argument, a class body's annotated default: a dataclass
   field's) and no option string (a string argument of a call that starts with ``-``:
   ``--pour-jitter``) *contains* such a name as a word part. Identifiers are split into
   lower-case word parts at ``_`` and at case changes (``PourGeometry``: ``pour``,
   ``geometry``); strings at every character that is not a letter or a digit as well
   (``skills/pour-vf.yaml``: ``skills``, ``pour``, ``vf``, ``yaml``). A name of several
   parts must appear as those parts in a row (``light_switch`` is in ``LightSwitchView``,
   not in ``light_or_switch``), and a part must equal a name's part: ``pouring`` and
   ``drawing`` contain neither ``pour`` nor ``drawer``. The rule is strict: every task
   name and every element name counts, except the single-word element names in
   :data:`PLAIN_WORDS`, which code uses as the plain word they are (a button's ``face``).
   Help texts and other strings are not read by this check (they are prose, as docstrings
   are); what genuinely must stay is in :data:`ALLOWED`, each with its reason.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterator
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


PLAIN_WORDS = {
    "face": "a surface's or a button's face: the task format's own word, in code the plain word",
}
"""Single-word element names the names check passes over, each with why: code uses them
as the plain word. Never a task's name."""

ALLOWED = {
    ("sim/demogen.py", "--pour-jitter"): "the flag of the previous release, kept as a deprecated "
                                         "alias of --tilt-jitter that says so on stderr",
}
"""``(file, text)`` the names check lets stand, each with why."""


def word_parts(text: str) -> list[str]:
    """The lower-case word parts of ``text``: split at every character that is not a
    letter or a digit, and at case changes (``HTTPServerError``: ``http``, ``server``,
    ``error``)."""
    spaced = re.sub(r"([a-z0-9])([A-Z])", r"\1 \2", text)
    spaced = re.sub(r"([A-Z]+)([A-Z][a-z])", r"\1 \2", spaced)
    return [p for p in re.split(r"[^a-z0-9]+", spaced.lower()) if p]


def strict_names(names: dict[str, str]) -> dict[tuple[str, ...], str]:
    """The names the names check looks for, as their word parts: each of ``names`` but
    the :data:`PLAIN_WORDS` (a task's name is never passed over)."""
    return {tuple(word_parts(n)): n for n, what in names.items() if what == "task" or n not in PLAIN_WORDS}


def contained(parts: list[str], strict: dict[tuple[str, ...], str]) -> str | None:
    """The first name of ``strict`` whose word parts are among ``parts``, in a row."""
    for key, name in strict.items():
        k = len(key)
        if any(tuple(parts[i:i + k]) == key for i in range(len(parts) - k + 1)):
            return name
    return None


def _identifiers(tree: ast.AST) -> Iterator[tuple[int, str, str]]:
    """``(line, what, identifier)`` of every name ``tree`` gives or uses."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            yield node.lineno, "name", node.name
        elif isinstance(node, ast.Name):
            yield node.lineno, "name", node.id
        elif isinstance(node, ast.Attribute):
            yield node.lineno, "attribute", node.attr
        elif isinstance(node, ast.arg):
            yield node.lineno, "parameter", node.arg
        elif isinstance(node, ast.keyword) and node.arg is not None:
            yield node.lineno, "keyword", node.arg
        elif isinstance(node, ast.alias):
            yield from ((node.lineno, "import", n) for n in (node.name, node.asname) if n)
        elif isinstance(node, ast.ExceptHandler) and node.name:
            yield node.lineno, "name", node.name


def _strings(values: list[ast.expr], what: str) -> Iterator[tuple[int, str, str]]:
    for v in values:
        for node in ast.walk(v):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                yield node.lineno, what, node.value


def _defaults(tree: ast.AST) -> Iterator[tuple[int, str, str]]:
    """``(line, what, text)`` of every string in a default or an option string of ``tree``:
    parameters' defaults, ``default=`` arguments, annotated defaults in a class body (not
    a call there: ``field(default=...)`` is a ``default=`` argument, its help is not read)
    and the string arguments of a call that start with ``-``."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            yield from _strings([*node.args.defaults, *(d for d in node.args.kw_defaults if d is not None)],
                                "default")
        elif isinstance(node, ast.Call):
            yield from _strings([k.value for k in node.keywords if k.arg == "default"], "default")
            yield from ((a.lineno, "option", a.value) for a in node.args if isinstance(a, ast.Constant)
                        and isinstance(a.value, str) and a.value.startswith("-"))
        elif isinstance(node, ast.ClassDef):
            yield from _strings([b.value for b in node.body if isinstance(b, ast.AnnAssign)
                                 and b.value is not None and not isinstance(b.value, ast.Call)], "default")


def named_by_parts(source: str, strict: dict[tuple[str, ...], str]) -> list[tuple[int, str, str, str]]:
    """``(line, what, text, name)`` of each identifier, default and option string of
    ``source`` that contains one of the ``strict`` names (:func:`strict_names`), in the
    order of the source."""
    tree = ast.parse(source)
    found = set()
    for line, what, text in [*_identifiers(tree), *_defaults(tree)]:
        name = contained(word_parts(text), strict)
        if name is not None:
            found.add((line, what, text, name))
    return sorted(found)


def part_hits_in_packages(names: dict[str, str]) -> list[str]:
    """``file:line: what 'text' contains 'name' (what it names)`` for every package file,
    :data:`ALLOWED` left out."""
    strict = strict_names(names)
    out = []
    for root in ROOTS:
        for path in sorted(root.rglob("*.py")):
            rel = path.relative_to(root.parent).as_posix()
            out += [f"{rel}:{line}: {what} {text!r} contains {name!r} ({names[name]})"
                    for line, what, text, name in named_by_parts(path.read_text(encoding="utf-8"), strict)
                    if (rel, text) not in ALLOWED]
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


NAMES = {"pour": "task", "light_switch": "task", "drawer": "task", "mug": "object of pour",
         "bottle_tip": "held frame of pour", "face": "head of drink"}


def test_word_parts_split_at_underscores_case_changes_and_punctuation():
    assert word_parts("PourGeometry") == ["pour", "geometry"]
    assert word_parts("_bench_vf_pour") == ["bench", "vf", "pour"]
    assert word_parts("HTTPServerError") == ["http", "server", "error"]
    assert word_parts("DRAWER_DEPTH") == ["drawer", "depth"]
    assert word_parts("--pour-jitter") == ["pour", "jitter"]
    assert word_parts("skills/pour-vf.yaml") == ["skills", "pour", "vf", "yaml"]


def test_the_names_walker_finds_task_names_in_identifiers():
    source = '''"""The pour, the mug, the light switch: docstrings are prose."""
from sim.scenes import pour_flow as flow_of
import numpy as mug_np


class PourGeometry:
    def tip(self, drawer_handle, bottle_tip_offset=0.0):
        """pour_point"""
        self.mug_pose = drawer_handle
        return LightSwitchView(pour_jitter=1)


def pouring(drawing, light_or_switch, face_centre, mugs, drawer_handle_x):
    try:
        pass
    except ValueError as pour_error:
        raise
    return drawing.bottle_tip
'''
    hits = [(line, what, text) for line, what, text, _ in named_by_parts(source, strict_names(NAMES))]
    assert hits == [(2, "import", "pour_flow"), (3, "import", "mug_np"), (6, "name", "PourGeometry"),
                    (7, "parameter", "bottle_tip_offset"), (7, "parameter", "drawer_handle"),
                    (9, "attribute", "mug_pose"), (9, "name", "drawer_handle"),
                    (10, "keyword", "pour_jitter"), (10, "name", "LightSwitchView"),
                    (13, "parameter", "drawer_handle_x"), (16, "name", "pour_error"),
                    (18, "attribute", "bottle_tip")]


def test_the_names_walker_finds_task_names_in_defaults_and_option_strings():
    source = '''from dataclasses import dataclass, field


def run(skill="skills/pour.yaml", *, task: str = "light-switch", count=3, label="a wiping"):
    p.add_argument("--pour-jitter", type=float, default=0.0, help="how the pour varies")
    p.add_argument("--skills", default=[defaults().skill, "pour-vf"], help="(default pour,pour-vf)")
    p.add_argument("-v", "--verbose", choices=["pour", "drawer"])
    print("--a-drawer-is-not-an-option-here", f"{task} pour")


@dataclass
class Bench:
    task: str = "drawer"
    skill: str = field(default="mug", metadata={"help": "the mug's skill"})
    other: str = field(default_factory=lambda: "pour")
'''
    hits = [(line, what, text) for line, what, text, _ in named_by_parts(source, strict_names(NAMES))]
    assert hits == [(4, "default", "light-switch"), (4, "default", "skills/pour.yaml"),
                    (5, "option", "--pour-jitter"), (6, "default", "pour-vf"),
                    (8, "option", "--a-drawer-is-not-an-option-here"),
                    (13, "default", "drawer"), (14, "default", "mug")]


def test_plain_words_are_single_word_element_names_and_no_task_names():
    names = task_names()
    for word in PLAIN_WORDS:
        assert word_parts(word) == [word] and names.get(word, "task") != "task", word
    assert strict_names({"face": "task"}) == {("face",): "face"}, "a task's name is never plain"


def test_no_package_code_has_a_task_name_in_its_names():
    hits = part_hits_in_packages(task_names())
    assert not hits, ("package code has a task's name in a name, a default or a flag (name it for "
                      "what it is; the task file says the rest):\n" + "\n".join(hits))


def test_every_allowance_is_still_in_its_file():
    stale = []
    for rel, text in ALLOWED:
        root = next(r for r in ROOTS if r.name == rel.split("/")[0])
        tree = ast.parse((root.parent / rel).read_text(encoding="utf-8"))
        if text not in {t for _, _, t in [*_identifiers(tree), *_defaults(tree)]}:
            stale.append((rel, text))
    assert not stale, f"allowances for what is no longer there: {stale}"
