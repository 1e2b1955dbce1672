"""Demonstration CSV reader (every malformed-input path), preprocessing, DTW."""

from __future__ import annotations

import numpy as np
import pytest

from sctd.learn import (
    DemoError,
    dtw,
    read_demo_csv,
    read_demos,
    spike_mask,
    subsample_by_distance,
    tf_distance,
)
from sctd.task import find_task
from sctd_sim import demogen

HEADER = "t,x,y,z,qx,qy,qz,qw\n"


def _rows(n=12):
    return "".join(f"{0.1 * i},{0.01 * i},0,0,0,0,0,1\n" for i in range(n))


def _write(tmp_path, text, name="d.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize(
    ("text", "row", "reason"),
    [
        ("t,x,y,z,qx,qy,qz\n" + "0,0,0,0,0,0,0\n" * 12, None, "missing column(s) qw"),
        (HEADER + _rows(3) + "0.35,nan,0,0,0,0,0,1\n" + _rows(12)[300:], 4, "column x: not finite"),
        (HEADER + _rows(2) + "0.25,0,abc,0,0,0,0,1\n", 3, "column y: not a number"),
        (HEADER + _rows(5) + "0.55,0,0,0,0,0,0.5,0.5\n", 6, "not unit"),
        (HEADER + _rows(5) + "0.1,0,0,0,0,0,0,1\n", 6, "does not increase"),
        (HEADER + _rows(4) + "0.45,0,0\n", 5, "expected 8 values, got 3"),
        (HEADER + _rows(4), 4, "too few samples: 4 rows"),
        ("", None, "empty file"),
        (HEADER + _rows(2) + "0.25,inf,0,0,0,0,0,1\n", 3, "not finite"),
    ],
)
def test_malformed_files_name_file_row_and_reason(tmp_path, text, row, reason):
    p = _write(tmp_path, text)
    with pytest.raises(DemoError) as exc:
        read_demo_csv(p)
    msg = str(exc.value)
    assert str(p) in msg
    assert reason in msg
    assert exc.value.row == row
    if row is not None:
        assert f"row {row} (line {row + 1})" in msg


def test_missing_file_and_directory(tmp_path):
    with pytest.raises(DemoError, match=r"cannot open \(No such file"):
        read_demo_csv(tmp_path / "nope.csv")
    for device in ("/dev/zero", "/dev/urandom"):  # refused before a byte is read
        with pytest.raises(DemoError, match="a character device, not a regular file"):
            read_demo_csv(device)
    with pytest.raises(DemoError, match="not a directory"):
        read_demos(tmp_path / "nope")
    with pytest.raises(DemoError, match="no demonstration files"):
        read_demos(tmp_path)


def test_folder_is_all_or_nothing(tmp_path):
    _write(tmp_path, HEADER + _rows(), "a.csv")
    _write(tmp_path, HEADER + _rows(3) + "0.35,0,0,0,0,0,0,2\n" + _rows(12)[300:], "b.csv")
    with pytest.raises(DemoError, match=r"b\.csv: row 4"):
        read_demos(tmp_path)


def test_extra_columns_and_column_order(tmp_path):
    text = "qw,t,x,y,z,qx,qy,qz,force\n" + "".join(f"1,{i},{i},0,0,0,0,0,9\n" for i in range(12))
    d = read_demo_csv(_write(tmp_path, text))
    np.testing.assert_allclose(d.poses[:, 0], np.arange(12))
    np.testing.assert_allclose(d.poses[:, 6], 1.0)


def test_write_then_read(tmp_path):
    t = np.arange(20) * 0.02
    poses = np.tile([0.1, 0.2, 0.3, 0.0, 0.0, np.sin(0.2), np.cos(0.2)], (20, 1))
    rows = np.column_stack([t, poses])
    text = HEADER + "".join(",".join(f"{x:.6f}" for x in row) + "\n" for row in rows)
    d = read_demo_csv(_write(tmp_path, text, "x.csv"))
    np.testing.assert_allclose(d.t, t, atol=1e-6)
    np.testing.assert_allclose(d.poses, poses, atol=1e-6)


def test_spike_mask_finds_planted_outliers():
    for seed in range(5):
        ds = demogen.generate(find_task("pour"), 1, outliers=0.05, seed=seed)
        d = ds.demos[0]
        bad = np.flatnonzero(~spike_mask(d.poses))
        assert set(d.outlier_rows) <= set(bad)
        assert len(bad) <= len(d.outlier_rows) + 2


def test_subsample_by_distance_spacing():
    d = demogen.generate(find_task("pour"), 1, noise=0.0, seed=0).demos[0]
    keep = subsample_by_distance(d.poses, 0.02, alpha=0.4)
    gaps = tf_distance(d.poses[keep[1:]], d.poses[keep[:-1]], 0.4)
    assert keep[0] == 0 and np.all(np.diff(keep) > 0)
    assert np.all(gaps[:-1] >= 0.02)
    # Each kept sample is the first one that far away: its predecessor is closer.
    prev = tf_distance(d.poses[keep[1:-1] - 1], d.poses[keep[:-2]], 0.4)
    assert np.all(prev < 0.02)


def test_dtw_identity_shift_and_path():
    d = demogen.generate(find_task("drawer"), 1, noise=0.0, seed=0).demos[0].poses[::5]
    cost, path = dtw(d, d)
    assert cost == pytest.approx(0.0, abs=1e-9)
    np.testing.assert_array_equal(path, np.stack([np.arange(len(d))] * 2, axis=1))
    # Repeating samples (a slower demonstration) costs nothing either.
    slow = np.repeat(d, 2, axis=0)
    cost, path = dtw(d, slow)
    assert cost == pytest.approx(0.0, abs=1e-9)
    assert tuple(path[0]) == (0, 0) and tuple(path[-1]) == (len(d) - 1, len(slow) - 1)
    assert np.all(np.diff(path, axis=0) >= 0) and np.all(np.diff(path, axis=0).sum(axis=1) >= 1)
    # Against a brute-force DP on a small case.
    rng = np.random.default_rng(0)
    a, b = d[:7], d[3:12] + np.r_[rng.normal(0, 0.01, 3), 0, 0, 0, 0]
    C = tf_distance(a[:, None], b[None], 0.4)
    D = np.full((8, 10), np.inf)
    D[0, 0] = 0
    for i in range(1, 8):
        for j in range(1, 10):
            D[i, j] = C[i - 1, j - 1] + min(D[i - 1, j - 1], D[i - 1, j], D[i, j - 1])
    cost, path = dtw(a, b)
    assert cost == pytest.approx(D[7, 9])
    assert cost == pytest.approx(C[path[:, 0], path[:, 1]].sum())
