"""Demonstrations with the gripper's columns: reading and writing them, refusing bad
values, and the learner commanding the gripper where the demonstrations did (and the
same skills as before from demonstrations without them)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sctd.learn import DemoError, GripperError, learn, learn_skill, read_demo_csv, read_demos, skill_bundle
from sctd.learn.demos import Demo
from sctd.skill import Distance, Gripper, Timeout, load_skill, skill_from_bundle
from sctd.wire import codec
from sctd_services.learner.store import csv_text
from sctd_services.record import COLUMNS, GRIPPER_COLUMNS, format_row

ROOT = Path(__file__).resolve().parents[1]
GRASP = np.array([0.0, 0.0, 0.05])
PLACE = np.array([0.0, 0.30, 0.10])


def _line(rng: np.random.Generator, a: np.ndarray, b: np.ndarray, n: int) -> np.ndarray:
    s = np.linspace(0.0, 1.0, n)[:, None]
    return a + s * (b - a) + rng.normal(0, 0.0005, (n, 3))


def _demo(seed: int) -> tuple[list[list[float]], Demo]:
    """Reach the grasp point from a scattered start, close (the fingers hold 0.2 s
    later), carry up and over to the place point, open, retreat up: rows of 10 at 100 Hz."""
    rng = np.random.default_rng(seed)
    start = np.array([0.30, -0.10, 0.20]) + rng.uniform(-0.04, 0.04, 3)
    dwell = 30
    parts = [(_line(rng, start, GRASP, 120), 0), (np.repeat(GRASP[None], dwell, 0), 0),
             (_line(rng, GRASP, PLACE, 150), 1), (np.repeat(PLACE[None], dwell, 0), 1),
             (_line(rng, PLACE, PLACE + np.array([0, 0, 0.15]), 100), 0)]
    P = np.concatenate([p for p, _ in parts])
    held = np.concatenate([np.full(len(p), h, dtype=float) for p, h in parts])
    n0 = 120 + 20  # the fingers read holding 20 rows into the grasp's dwell ...
    held[120:n0] = 0.0
    held[n0:120 + dwell] = 1.0
    n1 = 120 + dwell + 150 + 20  # ... and empty 20 rows into the place's
    held[120 + dwell + 150:n1] = 1.0
    held[n1:120 + dwell + 150 + dwell] = 0.0
    width = np.where(held == 1.0, 0.07, 0.08)
    rows = [[0.01 * k, *P[k], 0.0, 0.0, 0.0, 1.0, width[k], held[k]] for k in range(len(P))]
    demo = Demo(f"demo_{seed:03d}", np.array([r[0] for r in rows]),
                np.array([r[1:8] for r in rows]), width, held == 1.0)
    return rows, demo


@pytest.fixture(scope="module")
def demos() -> list[Demo]:
    return [_demo(s)[1] for s in range(6)]


def _write(path: Path, rows: list[list[float]]) -> Path:
    header = GRIPPER_COLUMNS if len(rows[0]) == 10 else COLUMNS
    path.write_text(header + "\n" + "".join(format_row(r) for r in rows))
    return path


def test_gripper_columns_round_trip_through_the_file_the_message_and_the_store(tmp_path):
    rows, _ = _demo(0)
    path = _write(tmp_path / "d.csv", rows)
    assert path.read_text().splitlines()[0] == "t,x,y,z,qx,qy,qz,qw,gripper,grasped"
    assert path.read_text() == csv_text([[float(x) for x in format_row(r).split(",")] for r in rows])
    d = read_demo_csv(path)
    assert d.width is not None and d.grasped is not None
    np.testing.assert_allclose(d.width, [r[8] for r in rows])
    assert list(d.grasped) == [r[9] == 1.0 for r in rows]
    msg = codec.decode_demo(codec.encode_demo("cup", "d", "cup", rows))
    assert msg.columns == codec.DEMO_COLUMNS + codec.DEMO_GRIPPER_COLUMNS
    assert msg.rows == [[float(x) for x in r] for r in rows]


def test_demonstrations_without_the_columns_read_and_travel_as_before(tmp_path):
    rows = [r[:8] for r in _demo(1)[0]]
    path = _write(tmp_path / "d.csv", rows)
    text = path.read_text()
    assert text.splitlines()[0] == "t,x,y,z,qx,qy,qz,qw" and csv_text(
        [[float(x) for x in format_row(r).split(",")] for r in rows]) == text
    d = read_demo_csv(path)
    assert d.width is None and d.grasped is None
    data = codec.encode_demo("cup", "d", "cup", rows)
    import msgpack
    assert msgpack.unpackb(data)["columns"] == list(codec.DEMO_COLUMNS)
    assert codec.decode_demo(data).columns == codec.DEMO_COLUMNS
    shipped = sorted((ROOT / "skills" / "demos" / "pour").glob("*.csv"))[0]
    assert read_demo_csv(shipped).grasped is None


@pytest.mark.parametrize(("col", "value", "problem"), [
    (9, "2", "column grasped: '2' is not 0 or 1"),
    (9, "0.5", "column grasped"),
    (8, "-0.01", "column gripper: width -0.01 m not in [0, 0.5]"),
    (8, "0.6", "column gripper"),
    (8, "nan", "column gripper: not finite"),
    (9, "yes", "column grasped: not a number"),
])
def test_bad_gripper_values_are_refused_naming_file_row_and_column(tmp_path, col, value, problem):
    rows = _demo(2)[0]
    path = _write(tmp_path / "bad.csv", rows)
    lines = path.read_text().splitlines()
    cells = lines[5].split(",")
    cells[col] = value
    lines[5] = ",".join(cells)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DemoError, match=r"bad\.csv: row 5 \(line 6\): " + problem.replace("[", r"\[")
                       .replace("]", r"\]").replace("(", r"\(").replace(")", r"\)")):
        read_demo_csv(path)


def test_one_gripper_column_without_the_other_is_refused(tmp_path):
    rows = [r[:9] for r in _demo(3)[0]]
    path = tmp_path / "half.csv"
    path.write_text(COLUMNS + ",gripper\n" + "".join(format_row(r[:8])[:-1] + f",{r[8]}\n" for r in rows))
    with pytest.raises(DemoError, match=r"half\.csv: column gripper without column grasped"):
        read_demo_csv(path)


@pytest.mark.parametrize(("i", "value", "problem"), [
    (9, 2.0, "row 3: column grasped"), (8, 0.7, "row 3: column gripper"), (8, -1.0, "row 3: column gripper"),
])
def test_the_wire_refuses_bad_gripper_values_naming_row_and_column(i, value, problem):
    rows = _demo(4)[0]
    rows[3][i] = value
    with pytest.raises(codec.DecodeError, match=problem):
        codec.decode_demo(codec.encode_demo("cup", "d", "cup", rows))
    with pytest.raises(codec.DecodeError, match="bad_columns"):
        import msgpack
        doc = msgpack.unpackb(codec.encode_demo("cup", "d", "cup", _demo(4)[0]))
        doc["columns"] = doc["columns"][:9]
        codec.decode_demo(msgpack.packb(doc))


def _check_gripper_skill(skill, force: float = 20.0) -> None:
    actions = [(s.name, s.gripper.action, s.gripper.force) for s in skill.states if s.gripper is not None]
    assert [a for _, a, _ in actions] == ["close", "open"]
    assert actions[0][2] == force
    close, open_ = actions[0][0], actions[1][0]
    for name, point in ((close, GRASP), (open_, PLACE)):
        into = [t for t in skill.transitions if t.target == name]
        assert into and all(isinstance(t, Distance) for t in into)
        for t in into:
            assert np.linalg.norm(t.point - point) < 0.01 and t.threshold <= 0.05
        out = [t for t in skill.transitions if t.source == name]
        assert {type(t) for t in out} == {Gripper, Timeout}
        (g,) = [t for t in out if isinstance(t, Gripper)]
        assert g.grasped is (name == close)
        (to,) = [t for t in out if isinstance(t, Timeout)]
        assert to.after == 3.0 and to.target != g.target
    # nothing else commands the gripper, and the end comes after the open
    assert skill.state_index(skill.end) > skill.state_index(open_) > skill.state_index(close)


@pytest.mark.parametrize("method", ["linear", "vf"])
def test_the_learner_closes_and_opens_where_the_demonstrations_did(demos, method):
    skill = learn_skill(demos, method, name="cup", object="cup", random_state=0)
    _check_gripper_skill(skill)
    assert skill.start == "s0" and skill.states[0].gripper is None


def test_the_force_is_a_learner_parameter_and_the_yaml_says_it(demos):
    result = learn(demos, "vf", object="cup", random_state=0, grasp_force=35.0)
    bundle = skill_bundle(result, "cup")
    assert "gripper: {action: close, force: 35.0}" in bundle.yaml_text
    assert "gripper: {action: open}" in bundle.yaml_text
    assert "type: gripper" in bundle.yaml_text and "type: timeout" in bundle.yaml_text
    _check_gripper_skill(skill_from_bundle(bundle), force=35.0)
    assert result.hyperparameters()["grasp_force"] == 35.0


def test_a_place_the_position_does_not_tell_waits_for_the_reading(demos):
    """Carried in the cup's own frame the hand sits still from the close to the open: the
    open's state is entered when the fingers let go (the person's grasp button), never
    by the position, which would open at once after the grasp."""
    still = []
    for d in demos:
        P = d.poses.copy()
        i0, i1 = np.flatnonzero(d.grasped)[[0, -1]]
        P[i1 + 1:, :3] += P[i0, :3] - P[i1 + 1, :3]  # the retreat leaves from the cup
        P[i0:i1 + 1] = P[i0]
        still.append(Demo(d.name, d.t, P, d.width, d.grasped))
    skill = learn_skill(still, "vf", name="cup", object="cup", random_state=0)
    (open_,) = [s.name for s in skill.states if s.gripper is not None and s.gripper.action == "open"]
    into = [t for t in skill.transitions if t.target == open_]
    assert into and all(isinstance(t, Gripper) and t.grasped is False for t in into)


def test_demonstrations_that_disagree_or_mix_columns_are_refused(demos):
    no_cols = Demo("plain", demos[0].t, demos[0].poses)
    with pytest.raises(GripperError, match="plain: no gripper columns"):
        learn([*demos[:3], no_cols], "vf", random_state=0)
    never = Demo("never", demos[0].t, demos[0].poses, demos[0].width, np.zeros(len(demos[0].t), bool))
    with pytest.raises(GripperError,
                       match=r"never: gripper events none, but demo_000 has \['close', 'open'\]"):
        learn([*demos[:3], never], "vf", random_state=0)


def test_columns_without_events_learn_what_the_pose_alone_learns(demos):
    flat = [Demo(d.name, d.t, d.poses, d.width, np.zeros(len(d.t), bool)) for d in demos]
    bare = [Demo(d.name, d.t, d.poses) for d in demos]
    a = skill_bundle(learn(flat, "vf", object="cup", random_state=0), "x")
    b = skill_bundle(learn(bare, "vf", object="cup", random_state=0), "x")
    assert a.yaml_text == b.yaml_text and a.files.keys() == b.files.keys()


def test_the_shipped_drawer_demonstrations_still_learn_the_shipped_skill():
    """Known answer: skills/README.md's command for drawer-vf learns its file, text for
    text, and its model's arrays."""
    demos = read_demos(ROOT / "skills" / "demos" / "drawer")
    result = learn(demos, "vf", object="drawer_handle", random_state=0, vf_direction="both",
                   models=("translation", "cylinder", "sphere", "point", "general"))
    assert result.gripper is None and "grasp_force" not in result.hyperparameters()
    bundle = skill_bundle(result, "drawer-vf")
    assert bundle.yaml_text == (ROOT / "skills" / "drawer-vf.yaml").read_text()
    learned, shipped = skill_from_bundle(bundle), load_skill(ROOT / "skills" / "drawer-vf.yaml")
    assert [s.name for s in learned.states] == [s.name for s in shipped.states]
    assert learned.transitions == shipped.transitions and learned.start == shipped.start
    for (rel, a), (rel_b, b) in zip(learned.models().items(), shipped.models().items(), strict=True):
        assert rel == rel_b and [type(f) for f in a.fields] == [type(f) for f in b.fields]
        for x in ("points", "quaternions", "responsibilities"):
            np.testing.assert_allclose(getattr(a, x), getattr(b, x), atol=1e-9)
    assert all(s.gripper is None for s in learned.states)


@pytest.mark.parametrize("task, obj", [("tap", "tap"), ("cup_to_table", "cup"),
                                       ("bottle_to_fridge", "bottle")])
def test_the_shipped_demonstrations_with_the_fingers_learn_the_shipped_skills(task, obj):
    """Known answer: skills/README.md's commands for the skills taught with the fingers
    learn their files, text for text: one state closes where the demonstrations closed,
    within 8 mm of the grip, one opens where they opened (or on the fingers' reading),
    and every state is reachable (a learned state the demonstrations used after the grasp
    but never entered there is left out)."""
    demos = read_demos(ROOT / "skills" / "demos" / task)
    result = learn(demos, "linear", object=obj, random_state=0)
    name = f"{task}-linear"
    bundle = skill_bundle(result, name)
    assert bundle.yaml_text == (ROOT / "skills" / f"{name}.yaml").read_text()
    skill = skill_from_bundle(bundle)
    actions = [(s.name, s.gripper.action) for s in skill.states if s.gripper is not None]
    assert [a for _, a in actions] == ["close", "open"]
    into_close = [t for t in skill.transitions if t.target == actions[0][0] and isinstance(t, Distance)]
    assert into_close and all(t.threshold == 0.008 for t in into_close)
    reached, todo = {skill.start}, [skill.start]
    while todo:
        here = todo.pop()
        for t in skill.transitions:
            if t.source == here and t.target not in reached:
                reached.add(t.target)
                todo.append(t.target)
    assert reached == {s.name for s in skill.states}
