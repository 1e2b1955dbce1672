"""Known answers of the demonstration generator (sim/demogen.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sctd import se3
from sctd.learn import read_demos
from sctd.task import find_task
from sctd_sim import demogen


def test_seeded_and_reproducible():
    a = demogen.generate(find_task("pour"), 3, seed=4, outliers=0.05)
    b = demogen.generate(find_task("pour"), 3, seed=4, outliers=0.05)
    c = demogen.generate(find_task("pour"), 3, seed=5, outliers=0.05)
    for x, y in zip(a.demos, b.demos, strict=True):
        np.testing.assert_array_equal(x.poses, y.poses)
    assert not np.allclose(a.demos[0].poses[:5], c.demos[0].poses[:5])


def test_pour_ground_truth_geometry():
    ds = demogen.generate(find_task("pour"), 4, noise=0.0, seed=1)
    centre = np.asarray(ds.truth["sphere_centre"])
    tip = np.asarray(ds.truth["tip_offset"])
    for d in ds.demos:
        T = se3.transform_from_pose(d.clean)
        tip_pos = T[:, :3, :3] @ tip + T[:, :3, 3]
        phase = d.phase
        assert phase[0] == 0 and phase[-1] == 1 and np.all(np.diff(phase) >= 0)
        pour_rows = np.flatnonzero(phase == 1) + 1
        # While pouring the tip stays at the pour point: the ee moves on a sphere.
        np.testing.assert_allclose(tip_pos[pour_rows], np.broadcast_to(centre, (len(pour_rows), 3)),
                                   atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(T[pour_rows, :3, 3] - centre, axis=1), 0.12,
                                   atol=1e-9)
        # Carrying, the bottle is upright (ee z up) and the tip moves on a straight line.
        carry_rows = np.flatnonzero(phase == 0)
        np.testing.assert_allclose(T[carry_rows, :3, 2], np.tile([0, 0, 1.0], (len(carry_rows), 1)),
                                   atol=1e-9)
        seg = tip_pos[carry_rows] - tip_pos[0]
        direction = np.asarray(d.info["carry_direction"])
        np.testing.assert_allclose(np.cross(seg, direction), 0.0, atol=1e-9)
        # In the tip frame the pour is a rotation about the tip's y axis only.
        Tt = T[pour_rows] @ se3.transform_from_pose([*tip, 0, 0, 0, 1])
        d6 = se3.displacement_from_transforms(Tt[:-1], Tt[1:])
        assert np.abs(d6[:, :3]).max() < 1e-9
        assert np.abs(d6[:, [3, 5]]).max() < 1e-9 and np.all(d6[:, 4] > 0)


def test_drawer_ground_truth():
    ds = demogen.generate(find_task("drawer"), 3, noise=0.0, seed=2)
    assert ds.truth["directions"]["pull"] == [1.0, 0.0, 0.0]
    for d in ds.demos:
        pull = np.flatnonzero(d.phase == 1) + 1
        p = d.clean[pull, :3]
        assert np.all(np.diff(p[:, 0]) > 0)
        np.testing.assert_allclose(p[:, 1:], 0.0, atol=1e-12)
        np.testing.assert_allclose(d.clean[0, :3] / np.linalg.norm(d.clean[0, :3]),
                                   -np.asarray(d.info["reach_direction"]))


def test_noise_and_outliers_where_reported():
    ds = demogen.generate(find_task("pour"), 2, noise=0.001, outliers=0.05, seed=3)
    for d in ds.demos:
        err = np.linalg.norm(d.poses[:, :3] - d.clean[:, :3], axis=1)
        rows = d.outlier_rows
        assert len(rows) == round(0.05 * len(d.t))
        assert np.all(err[rows] > 0.02)
        others = np.setdiff1d(np.arange(len(err)), rows)
        assert err[others].max() < 0.01
        np.testing.assert_allclose(np.linalg.norm(d.poses[:, 3:], axis=1), 1.0, atol=1e-12)


def test_write_demo_set_round_trip(tmp_path):
    ds = demogen.generate(find_task("drawer"), 3, seed=0, rate=40.0)
    demogen.write_demo_set(ds, tmp_path)
    truth = json.loads((tmp_path / "truth.json").read_text())
    demos = read_demos(tmp_path)
    assert [d.name for d in demos] == ["demo_00.csv", "demo_01.csv", "demo_02.csv"]
    for d, g in zip(demos, ds.demos, strict=True):
        assert len(truth["labels"][d.name]) == len(d.t) - 1
        np.testing.assert_allclose(d.poses[:, :3], g.poses[:, :3], atol=1e-6)
        assert np.allclose(np.diff(d.t), 1 / 40.0)


def test_rejects_bad_arguments():
    with pytest.raises(ValueError):
        demogen.generate(find_task("juggle"))
    with pytest.raises(ValueError):
        demogen.generate(find_task("pour"), outliers=0.7)


def test_the_kinds_come_from_the_task_files():
    """A task's shape, object, tilt phase and geometry are its file's: the pour is a tilt
    about the bottle's tip 0.12 m up the hand to 5 cm over the mug, the drawer a pull."""
    pour, drawer = demogen.kind_of(find_task("pour")), demogen.kind_of(find_task("drawer"))
    assert (pour.shape, pour.object, pour.phases, pour.fields) == ("tilt", "mug", ("carry", "pour"),
                                                                   ("translation", "sphere"))
    np.testing.assert_array_equal(pour.tip_offset, [0.0, 0.0, 0.12])
    np.testing.assert_array_equal(pour.tilt_point, [0.0, 0.0, 0.05])
    assert (drawer.shape, drawer.object, drawer.phases) == ("pull", "drawer_handle", ("reach", "pull"))
    assert demogen.SYNTHETIC["crank"].object == "crank" and demogen.SYNTHETIC["wipe"].object == "table"


def test_a_task_file_sets_what_is_generated(tmp_path):
    """Another task file of the same shape: its name, object, outlet and tilt point go into
    the demonstrations and their truth."""
    from sctd.task import shipped_folder

    text = (shipped_folder() / "pour.yaml").read_text()
    for old, new in (("\nname: pour\n", "\nname: tap\n"), ("object: mug", "object: glass"),
                     ("    mug:", "    glass:"), ("into: mug", "into: glass"), ("to: mug", "to: glass"),
                     ("position: [0.0, 0.0, 0.12]", "position: [0.0, 0.0, 0.15]"),
                     ("to: [0.0, 0.0, 0.05]", "to: [0.0, 0.0, 0.07]")):
        assert old in text
        text = text.replace(old, new)
    path = tmp_path / "tap.yaml"
    path.write_text(text)
    ds = demogen.generate(find_task(path), 2, noise=0.0, seed=1)
    assert (ds.task, ds.shape, ds.truth["object"]) == ("tap", "tilt", "glass")
    assert ds.truth["tip_offset"] == [0.0, 0.0, 0.15]
    np.testing.assert_allclose(ds.truth["sphere_centre"], [0.0, 0.0, 0.07], atol=1e-12)


def test_a_task_of_neither_shape_is_refused(tmp_path):
    from sctd.task import shipped_folder

    text = (shipped_folder() / "pour.yaml").read_text().replace("contents: {", "# contents: {")
    path = tmp_path / "hold.yaml"
    path.write_text(text.replace("name: pour", "name: hold"))
    with pytest.raises(ValueError, match="neither"):
        demogen.kind_of(find_task(path))


def test_the_tilt_jitter_flag_and_its_deprecated_alias_give_the_same_demonstrations(tmp_path, capsys):
    args = ["pour", "--n-demos", "2", "--seed", "3"]
    assert demogen.main([*args[:1], str(tmp_path / "new"), *args[1:], "--tilt-jitter", "0.01"]) == 0
    assert "deprecated" not in capsys.readouterr().err
    assert demogen.main([*args[:1], str(tmp_path / "old"), *args[1:], "--pour-jitter", "0.01"]) == 0
    assert "--pour-jitter is deprecated" in capsys.readouterr().err
    for name in ("demo_00.csv", "demo_01.csv", "truth.json"):
        assert (tmp_path / "new" / name).read_text() == (tmp_path / "old" / name).read_text()
    assert json.loads((tmp_path / "new" / "truth.json").read_text())["params"]["tilt_jitter"] == 0.01
