"""What can be read can be written: a task file written from a task reads back as that
task, field by field (``task_from_document(task_to_yaml(t)) == t``), and writing what was
read back gives the same text. Checked for every shipped task (found through the
catalog), for tests/data/task_every_field.yaml (with them, every field of the model with
a value other than its default: the writer cannot leave one out unnoticed) and for
shipped tasks with their numbers perturbed (hypothesis).
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest
import yaml
from hypothesis import given, reject, settings
from hypothesis import strategies as st

from sctd.task import TaskError, known_tasks, load_task, task_from_document
from sctd.task import model as task_model
from sctd.task.compose import compose
from sctd.task.kinds.reach import Reach
from sctd.task.model import Scene, Step, Task
from sctd.task.reader import DEGREES, rpy_matrix
from sctd.task.writer import dump_task, rpy_from_matrix, task_to_yaml
from tests.conftest import ROOT

SHIPPED = [k.path for k in known_tasks() if k.origin == "shipped"]
EVERY_FIELD = ROOT / "tests" / "data" / "task_every_field.yaml"
TRANSFORM_TOLERANCE = 1e-12


def differences(a: Any, b: Any, path: str = "task") -> list[str]:
    """Where ``a`` and ``b`` differ, as paths (``task.scene.bodies.mug.T_world``); empty
    when they are equal field by field.

    Exact everywhere (the same types, dict keys in the same order, floats and arrays by
    value) but for a (4, 4) array, a transform: the reader rebuilds it from ``position``
    and ``rpy``, which the writer chooses to give the same matrix within
    :data:`TRANSFORM_TOLERANCE` (to the bit where it can, ``sctd.task.writer``). Nothing
    else is tolerated."""
    if type(a) is not type(b):
        return [f"{path}: {type(a).__name__} != {type(b).__name__}"]
    if isinstance(a, np.ndarray):
        if a.shape != b.shape:
            return [f"{path}: shape {a.shape} != {b.shape}"]
        if a.shape == (4, 4):
            return [] if float(np.max(np.abs(a - b))) <= TRANSFORM_TOLERANCE else [path]
        return [] if np.array_equal(a, b) else [path]
    if dataclasses.is_dataclass(a):
        return [d for f in dataclasses.fields(a)
                for d in differences(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")]
    if isinstance(a, dict):
        if list(a) != list(b):
            return [f"{path}: keys {list(a)} != {list(b)}"]
        return [d for k in a for d in differences(a[k], b[k], f"{path}.{k}")]
    if isinstance(a, tuple | list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} items != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in differences(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


def read_back(task: Task) -> Task:
    """The task the written text reads back as (through YAML text, as a file would)."""
    return task_from_document(yaml.safe_load(dump_task(task)), task.file)


def is_plain(doc: Any) -> bool:
    """Only dicts (of str keys), lists, str, float, int and bool."""
    if isinstance(doc, dict):
        return all(isinstance(k, str) and is_plain(v) for k, v in doc.items())
    if isinstance(doc, list):
        return all(is_plain(v) for v in doc)
    return type(doc) in (str, float, int, bool)


def leaves(doc: Any, path: str = "") -> dict[str, Any]:
    """The document's scalars by their path."""
    if isinstance(doc, dict):
        return {p: v for k, x in doc.items() for p, v in leaves(x, f"{path}.{k}" if path else k).items()}
    if isinstance(doc, list):
        return {p: v for i, x in enumerate(doc) for p, v in leaves(x, f"{path}[{i}]").items()}
    return {path: doc}


# -- the round trip ------------------------------------------------------------------------
def test_the_catalog_ships_tasks():
    assert {p.stem for p in SHIPPED} >= {"pour", "drawer", "cabinet", "light_switch", "drink", "oven"}


@pytest.mark.parametrize("path", [*SHIPPED, EVERY_FIELD], ids=lambda p: p.name)
def test_a_task_reads_back_what_is_written(path):
    task = load_task(path)
    doc = task_to_yaml(task)
    assert is_plain(doc)
    assert differences(task_from_document(doc, task.file), task) == []
    back = read_back(task)
    assert differences(back, task) == []
    assert dump_task(back) == dump_task(task) == dump_task(task)  # a fixed point, and the same twice


def test_poses_read_back_to_the_bit_in_the_shipped_tasks():
    """The tolerance for transforms is not needed by what the reader makes of angles in
    range: the shipped tasks' poses come back exactly."""
    for path in SHIPPED:
        task = load_task(path)
        back = read_back(task)
        for name, body in task.scene.bodies.items():
            assert np.array_equal(back.scene.bodies[name].T_world, body.T_world), (path.name, name)
        assert np.array_equal(back.scene.start.T_world, task.scene.start.T_world)


def _model_classes() -> list[type]:
    return [c for _, c in inspect.getmembers(task_model, inspect.isclass)
            if dataclasses.is_dataclass(c) and c.__module__ == task_model.__name__]


def _set_fields(obj: Any, seen: dict[type, set[str]]) -> None:
    """Each dataclass's fields that ``obj`` gives a value other than their default."""
    if isinstance(obj, dict | tuple | list):
        for x in obj.values() if isinstance(obj, dict) else obj:
            _set_fields(x, seen)
        return
    if not dataclasses.is_dataclass(obj) or isinstance(obj, type):
        return
    got = seen.setdefault(type(obj), set())
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if f.default is not dataclasses.MISSING:
            default = f.default
        elif f.default_factory is not dataclasses.MISSING:
            default = f.default_factory()
        else:
            default = dataclasses.MISSING
        if default is dataclasses.MISSING or differences(value, default):
            got.add(f.name)
        _set_fields(value, seen)


def test_the_tasks_checked_set_every_field_of_the_model():
    """The shipped tasks and tests/data/task_every_field.yaml, together, give every field
    of every class of the task model a value other than its default (but the task's
    ``file`` and ``parts``, which are not in a file): a field added to the model fails
    here until a task the round trip above checks has it."""
    seen: dict[type, set[str]] = {}
    for path in [*SHIPPED, EVERY_FIELD]:
        _set_fields(load_task(path), seen)
    unset = {c.__name__: sorted({f.name for f in dataclasses.fields(c)} - seen.get(c, set()))
             for c in _model_classes()}
    unset["Task"] = [n for n in unset["Task"] if n not in ("file", "parts")]
    unset = {c: names for c, names in unset.items() if names}
    assert unset == {}, (f"no task the round trip checks sets these fields of sctd.task.model: {unset}; "
                         f"give them a value in {EVERY_FIELD.relative_to(ROOT)}")


# -- perturbed numbers ---------------------------------------------------------------------
PERTURBED = ("position", "com", "time_limit", "within", "radial", "height", "radius", "depth", "mass",
             "stiffness", "damping", "friction", "flow_rate", "off_by", "weight", "force", "travel", "miss")
"""The fields whose numbers the property test scales (positions in a body's or the hand's
frame, tolerances, time limits, physical constants); a few per cent either way keeps
every shipped task valid."""


def _angle(a: Any) -> float:
    m = DEGREES.match(a) if isinstance(a, str) else None
    return math.radians(float(m.group(1))) if m else float(a)


def _perturb(doc: dict[str, Any], draw) -> dict[str, Any]:
    """``doc`` moved as a whole by up to 3 cm along each world axis (the hand's start and
    every body: what stands on what still does), every ``rpy`` angle it gives moved by up
    to 0.05 rad, and each number under a :data:`PERTURBED` key elsewhere scaled by
    0.97-1.03 on its own."""
    offset = [draw(st.floats(-0.03, 0.03)) for _ in range(3)]

    def walk(v: Any, path: tuple[str, ...]) -> Any:
        key = path[-1] if path else ""
        world = path in (("scene", "start", "position"), ("scene", "bodies", *path[2:3], "position"))
        if world:
            return [x + d for x, d in zip(v, offset, strict=True)]
        if isinstance(v, dict):
            return {k: walk(x, (*path, str(k))) for k, x in v.items()}
        if key == "rpy":
            return [_angle(a) + draw(st.floats(-0.05, 0.05)) for a in v]
        if isinstance(v, list):
            return [walk(x, path) for x in v]
        if key in PERTURBED and isinstance(v, int | float) and not isinstance(v, bool):
            return v * draw(st.floats(0.97, 1.03))
        return v

    return walk(doc, ())


@settings(max_examples=25)
@given(data=st.data())
@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_a_perturbed_task_reads_back_what_is_written(path, data):
    """Numbers of full precision (a position of 0.7123456789012345 m, a time limit of
    61.83 s, any rpy) come back to the bit, and the text is a fixed point."""
    doc = _perturb(yaml.safe_load(path.read_text()), data.draw)
    try:
        task = task_from_document(doc, str(path))
    except TaskError:  # (a perturbation outside what this task allows: not a task)
        reject()
    back = read_back(task)
    assert differences(back, task) == []
    assert dump_task(back) == dump_task(task)


@given(st.lists(st.floats(-math.pi, math.pi), min_size=3, max_size=3))
def test_rpy_from_matrix_gives_back_the_matrix(rpy):
    """To the bit for angles the reader makes a pose of (pitch inside (-pi/2, pi/2));
    within the tolerance and a fixed point for any others."""
    R = rpy_matrix(np.array(rpy))
    out = rpy_from_matrix(R)
    R_back = rpy_matrix(np.array(out))
    if abs(rpy[1]) < math.pi / 2:
        assert np.array_equal(R_back, R)
    assert float(np.max(np.abs(R_back - R))) <= TRANSFORM_TOLERANCE
    assert rpy_from_matrix(R_back) == out


# -- what is written -----------------------------------------------------------------------
def shipped(name: str) -> Path:
    return next(p for p in SHIPPED if p.stem == name)


def _pour() -> Task:
    return load_task(shipped("pour"))


def _changed(task: Task, where: str) -> Task:
    """``task`` with one field changed (by its place in the model)."""
    r = dataclasses.replace
    sc, o = task.scene, task.outcome
    if where == "outcome.time_limit":
        return r(task, outcome=r(o, time_limit=o.time_limit + 1.5))
    if where == "scene.bodies.mug.position":
        T = sc.bodies["mug"].T_world.copy()
        T[1, 3] += 0.01
        return r(task, scene=r(sc, bodies={**sc.bodies, "mug": r(sc.bodies["mug"], T_world=T)}))
    if where == "scene.bodies.mug.container.radius":
        mug = sc.bodies["mug"]
        assert mug.container is not None
        mug = r(mug, facets={**mug.facets, "container": r(mug.container, radius=0.045)})
        return r(task, scene=r(sc, bodies={**sc.bodies, "mug": mug}))
    if where == "intent[0].reach.to":
        step = task.intent[0]
        assert isinstance(step.action, Reach)
        reach = r(step.action, to=np.array([0.0, 0.01, 0.05]))
        return r(task, intent=(r(step, action=reach), *task.intent[1:]))
    assert where == "teach.speed"
    return r(task, teach=r(task.teach, speed=0.25))


@pytest.mark.parametrize("where", ["outcome.time_limit", "scene.bodies.mug.position",
                                   "scene.bodies.mug.container.radius", "intent[0].reach.to",
                                   "teach.speed"])
def test_a_change_in_one_field_is_written_in_that_field_only(where):
    task = _pour()
    before, after = leaves(task_to_yaml(task)), leaves(task_to_yaml(_changed(task, where)))
    differ = {p for p in before.keys() | after.keys() if before.get(p) != after.get(p)}
    assert differ and all(p.startswith(where) for p in differ), differ
    assert differences(read_back(_changed(task, where)), _changed(task, where)) == []


def test_a_change_in_one_number_changes_one_line():
    task = _pour()
    a, b = dump_task(task).splitlines(), dump_task(_changed(task, "outcome.time_limit")).splitlines()
    changed = [line for line in difflib.unified_diff(a, b, lineterm="", n=0)
               if line[:1] in "+-" and line[:3] not in ("+++", "---")]
    assert changed == ["-  time_limit: 60.0", "+  time_limit: 61.5"]


def test_angles_are_written_in_degrees_where_they_read_back_exactly():
    doc = task_to_yaml(load_task(shipped("cabinet")))
    assert doc["scene"]["joints"]["door"]["travel"] == "100 deg"
    assert doc["scene"]["bodies"]["door_handle"]["rpy"] == [0.0, 0.0, "180 deg"]
    assert doc["outcome"]["done"] == {"reading": "door.position", "at_least": "65 deg"}
    assert doc["intent"][0]["reach"] == {"frame": "hand", "handle": "door",
                                         "until": {"reading": "door.held", "is": True}}  # (free: left out)
    assert task_to_yaml(_pour())["intent"][1]["tilt"]["to"] == 1.65  # (94.538... deg: in rad)


def test_a_composed_task_is_not_written():
    room = compose([load_task(shipped("drawer")), load_task(shipped("cabinet"))])
    with pytest.raises(ValueError, match=r"task 'drawer\+cabinet' is composed of parts"):
        dump_task(room)


# -- elements of registered kinds ----------------------------------------------------------
@dataclass(frozen=True)
class Shelf:
    """A stand-in for a scene element of a kind registered in sctd.task.kinds."""

    height: float

    def to_yaml(self) -> dict[str, Any]:
        return {"height": self.height}


@dataclass(frozen=True)
class SceneWithShelves(Scene):
    shelves: dict[str, Shelf] = field(default_factory=dict)


@dataclass(frozen=True)
class Wave:
    """A stand-in for an intent step of a kind registered in sctd.task.kinds."""

    key: ClassVar[str] = "wave"
    times: int

    def to_yaml(self, scene: Scene) -> dict[str, Any]:
        return {"times": self.times}


def test_elements_of_registered_kinds_write_themselves():
    task = _pour()
    scene = SceneWithShelves(**{f.name: getattr(task.scene, f.name) for f in dataclasses.fields(Scene)},
                             shelves={"top": Shelf(1.2)})
    steps = (*task.intent, Step("wave", Wave(2)))  # type: ignore[arg-type]
    doc = task_to_yaml(dataclasses.replace(task, scene=scene, intent=steps))
    assert doc["scene"]["shelves"] == {"top": {"height": 1.2}}
    assert doc["intent"][-1] == {"name": "wave", "wave": {"times": 2}}
    bare = dataclasses.replace(task, scene=dataclasses.replace(scene, shelves={}))
    assert "shelves" not in task_to_yaml(bare)["scene"]


def test_a_field_the_writer_does_not_know_is_an_error_not_left_out():
    task = _pour()

    @dataclass(frozen=True)
    class SceneWithLight(Scene):
        light: float = 0.0

    scene = SceneWithLight(**{f.name: getattr(task.scene, f.name) for f in dataclasses.fields(Scene)},
                           light=0.5)
    with pytest.raises(ValueError, match=r"scene\.light: the task writer does not know this field"):
        task_to_yaml(dataclasses.replace(task, scene=scene))


# -- the comparison itself -------------------------------------------------------------------
def test_differences_tolerates_only_the_transforms_rounding():
    task = _pour()
    sc = task.scene
    mug = sc.bodies["mug"]

    def with_mug(**changes) -> Task:
        bodies = {**sc.bodies, "mug": dataclasses.replace(mug, **changes)}
        return dataclasses.replace(task, scene=dataclasses.replace(sc, bodies=bodies))

    assert differences(task, task) == []
    assert differences(with_mug(T_world=mug.T_world + 1e-13), task) == []
    assert differences(with_mug(T_world=mug.T_world + 1e-9), task) == ["task.scene.bodies.mug.T_world"]
    nudged = mug.vary.position.copy()
    nudged[0] = math.nextafter(nudged[0], 1.0)
    assert differences(with_mug(vary=dataclasses.replace(mug.vary, position=nudged)), task) == [
        "task.scene.bodies.mug.vary.position"]
    later = dataclasses.replace(task, outcome=dataclasses.replace(
        task.outcome, time_limit=math.nextafter(task.outcome.time_limit, 99.0)))
    assert differences(later, task) == ["task.outcome.time_limit: 60.00000000000001 != 60.0"]
    assert differences(dataclasses.replace(task, file="elsewhere.yaml"), task) != []


# -- the command line ------------------------------------------------------------------------
def test_sctd_tasks_show_yaml_prints_the_written_file(capsys, tmp_path):
    from sctd.cli.main import main

    assert main(["tasks", "show", "pour", "--yaml"]) == 0
    text = capsys.readouterr().out
    assert text == dump_task(_pour())
    copy = tmp_path / "pour.yaml"
    copy.write_text(text)
    assert differences(load_task(copy), dataclasses.replace(_pour(), file=str(copy))) == []
