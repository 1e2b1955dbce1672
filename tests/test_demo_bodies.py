"""Demonstrations carry the scene's other bodies: seven named columns per body, its pose
in the task object's frame, in the CSV, on the wire and in the learner's store; old
demonstrations read and travel exactly as before."""

from __future__ import annotations

import io
import math
import threading
from pathlib import Path

import msgpack
import numpy as np
import pytest

from sctd import se3
from sctd.learn.demos import DemoError, read_demo_csv
from sctd.wire import codec
from sctd_services import record
from sctd_services.learner.store import csv_text

ROOT = Path(__file__).resolve().parents[1]
TABLE = [0.1, -0.3, -0.16, 0.0, 0.0, math.sin(0.2), math.cos(0.2)]  # T_cup_tabletop


def _rows(n: int = 20, grip: bool = False) -> list[list[float]]:
    """The hand going down onto the cup, the table top's pose beside it in every row."""
    rows = []
    for k in range(n):
        row = [0.01 * k, 0.0, 0.0, 0.2 - 0.005 * k, 1.0, 0.0, 0.0, 0.0]
        if grip:
            row += [0.08, 0.0]
        rows.append(row + TABLE)
    return rows


def _write(path: Path, header: str, rows: list[list[float]]) -> Path:
    path.write_text(header + "\n" + "".join(",".join(str(x) for x in r) + "\n" for r in rows))
    return path


HEADER = "t,x,y,z,qx,qy,qz,qw," + ",".join(codec.demo_body_columns("tabletop"))


def test_a_csv_with_a_bodys_columns_reads_its_poses_and_the_hand_in_its_frame(tmp_path):
    d = read_demo_csv(_write(tmp_path / "d.csv", HEADER, _rows()))
    assert list(d.bodies) == ["tabletop"] and d.width is None
    np.testing.assert_allclose(d.bodies["tabletop"], np.tile(TABLE, (20, 1)), atol=1e-12)
    in_table = d.poses_in("tabletop")
    T = np.linalg.inv(se3.transform_from_pose(np.array(TABLE))) @ se3.transform_from_pose(d.poses[3])
    np.testing.assert_allclose(se3.transform_from_pose(in_table[3]), T, atol=1e-9)
    assert np.all(in_table[:, 6] >= 0.0)
    assert d.poses_in("cup") is d.poses  # the task object: the rows' own poses
    kept = d.select(np.array([0, 5, 9]))
    assert kept.bodies["tabletop"].shape == (3, 7) and len(kept) == 3


def test_the_gripper_and_bodies_read_together(tmp_path):
    header = "t,x,y,z,qx,qy,qz,qw,gripper,grasped," + ",".join(codec.demo_body_columns("tabletop"))
    d = read_demo_csv(_write(tmp_path / "d.csv", header, _rows(grip=True)))
    assert d.width is not None and list(d.bodies) == ["tabletop"]


@pytest.mark.parametrize("task", ["pour", "drawer", "cabinet", "drink", "light_switch", "oven"])
def test_old_demonstrations_read_without_bodies(task):
    """The shipped demonstrations made before bodies were recorded read with none (those
    of the tasks with the fingers carry theirs: tests/test_learn_gripper.py)."""
    for f in sorted((ROOT / "skills" / "demos" / task).glob("*.csv"))[:3]:
        assert read_demo_csv(f).bodies == {}


@pytest.mark.parametrize(("header", "rows", "message"), [
    (HEADER.replace(",tabletop.qw", ""), [r[:-1] for r in _rows()],
     "d.csv: body tabletop: missing column(s) tabletop.qw"),
    (HEADER, [r if k != 4 else [*r[:10], "x", *r[11:]] for k, r in enumerate(_rows())],
     "d.csv: row 5 (line 6): column tabletop.z: not a number: 'x'"),
    (HEADER, [r if k != 2 else [*r[:8], 1e400, *r[9:]] for k, r in enumerate(_rows())],
     "d.csv: row 3 (line 4): column tabletop.x: not finite"),
    (HEADER, [r if k != 7 else [*r[:11], 0.5, *r[12:]] for k, r in enumerate(_rows())],
     "d.csv: row 8 (line 9): columns tabletop.qx..tabletop.qw: quaternion has norm"),
    (HEADER.replace("tabletop.", "table top."), _rows(),
     "d.csv: column table top.x: not a body's name"),
])
def test_a_bad_body_column_is_named_with_file_row_and_column(tmp_path, header, rows, message):
    with pytest.raises(DemoError) as e:
        read_demo_csv(_write(tmp_path / "d.csv", header, rows))
    assert message in str(e.value)


# --- on the wire and in the store -----------------------------------------------------------


def test_bodies_travel_in_the_message_and_the_store_writes_the_recorders_text(tmp_path):
    rows = _rows(grip=True)
    data = codec.encode_demo("cup_to_table", "d", "cup", rows, ("tabletop",))
    msg = codec.decode_demo(data)
    body_columns = codec.demo_body_columns("tabletop")
    assert msg.columns == codec.DEMO_COLUMNS + codec.DEMO_GRIPPER_COLUMNS + body_columns
    assert codec.demo_bodies(msg.columns) == ("tabletop",)
    assert msg.rows == rows
    text = csv_text(msg.rows, msg.columns)
    lines = [record.format_row(r, ("tabletop",)) for r in rows]
    assert text == "".join([",".join(msg.columns) + "\n", *lines])
    d = read_demo_csv(_write_text(tmp_path / "d.csv", text))
    np.testing.assert_allclose(d.bodies["tabletop"][0], TABLE, atol=1e-9)


def _write_text(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_a_message_without_bodies_is_as_before():
    rows = [r[:8] for r in _rows()]
    data = codec.encode_demo("cup", "d", "cup", rows)
    assert msgpack.unpackb(data)["columns"] == list(codec.DEMO_COLUMNS)
    assert codec.demo_bodies(codec.decode_demo(data).columns) == ()


def _bad(columns: list[str], rows: list[list[float]] | None = None, obj: str = "cup") -> str:
    data = codec.pack({"task": "t", "name": "d", "object": obj, "columns": columns,
                       "rows": rows if rows is not None else _rows()})
    with pytest.raises(codec.DecodeError) as e:
        codec.decode_demo(data)
    return str(e.value)


def test_the_message_refuses_bad_body_columns_and_names_row_and_column():
    cols = list(codec.DEMO_COLUMNS + codec.demo_body_columns("tabletop"))
    assert "column 'tabletop.x': body 'tabletop' is the task object" in _bad(cols, obj="tabletop")
    assert "twice" in _bad(cols + list(codec.demo_body_columns("tabletop")),
                           [r + TABLE for r in _rows()])
    assert "expected" in _bad(cols[:-1], [r[:-1] for r in _rows()])
    assert "column 'a b.x'" in _bad(list(codec.DEMO_COLUMNS + codec.demo_body_columns("a b")))
    rows = _rows()
    rows[6] = [*rows[6][:11], 0.3, *rows[6][12:]]
    assert "row 6: columns tabletop.qx..tabletop.qw: quaternion norm" in _bad(cols, rows)


# --- recording ----------------------------------------------------------------------------


class _Rec(record.Recorder):
    """A recorder whose state advances by itself (no Zenoh): the hand goes down in the
    world over a cup on a shelf, the table top and the shelf published too."""

    def __init__(self, bodies=None):
        super().__init__(None, "edan", "cup", task="cup_to_table", bodies=bodies)  # type: ignore[arg-type]
        self.objects = {"cup": [0.68, 0.18, 0.74, 0, 0, 0, 1], "tabletop": [0.6, -0.18, 0.58, 0, 0, 0, 1],
                        "shelf": [0.68, 0.18, 0.74, 0, 0, 0, 1]}
        self.k = 0

    def sample_gripper(self):
        self.k += 1
        return 0.01 * self.k, [0.68, 0.18, 0.9 - 0.001 * self.k, 1, 0, 0, 0], self.objects["cup"], None


@pytest.mark.parametrize(("bodies", "expect"), [
    (None, ("shelf", "tabletop")), (("tabletop", "cup"), ("tabletop",)), ((), ())])
def test_a_recording_carries_every_other_body_in_the_objects_frame(bodies, expect):
    rec, fh, rows = _Rec(bodies), io.StringIO(), []
    stop = threading.Event()
    threading.Timer(0.1, stop.set).start()
    got = record._record_rows(rec, fh, 500.0, 0.0, stop, None, rows)
    assert got == expect and len(rows) >= 5
    header = fh.getvalue().splitlines()[0].split(",")
    assert tuple(header) == codec.demo_columns(rows, expect)
    if "tabletop" in expect:
        i = header.index("tabletop.x")
        np.testing.assert_allclose(rows[0][i:i + 7], [-0.08, -0.36, -0.16, 0, 0, 0, 1], atol=1e-9)
    codec.decode_demo(codec.encode_demo("cup_to_table", "d", "cup", rows, got))  # the message agrees
