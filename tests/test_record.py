"""`sctd record`: demonstrations in the task object's frame, in the learner's CSV format,
written complete or not at all, numbered without overwriting."""

from __future__ import annotations

import argparse
import math
import signal
import threading
import time

import numpy as np
import pytest

from sctd import se3
from sctd.learn import demos
from sctd.learn.demos import MIN_SAMPLES, read_demo_csv, read_demos
from sctd.task.demos import DemosInfo, read_demos_info
from sctd.wire import Keys, codec
from sctd.wire.session import open_session
from sctd_services import record
from sctd_services.record import MIN_ROWS, publish_final, row_from_poses
from tests.conftest import free_port, port_is_free, sctd, wait_for

KEYS = Keys("edan")
YAW180 = [0.0, 0.0, 1.0, 0.0]  # object x towards the robot (world -x), z up


def test_min_rows_and_columns_match_the_learner():
    """The recorder's CSV and the demonstration message are what the learner reads (the
    wire codec and the learner are independent layers, so each has its constants)."""
    assert MIN_ROWS == codec.MIN_DEMO_ROWS == MIN_SAMPLES
    assert codec.DEMO_COLUMNS == demos.COLUMNS
    assert codec.DEMO_QUAT_TOLERANCE == demos.QUAT_TOLERANCE


def test_a_failed_recording_leaves_no_part_file(tmp_path, monkeypatch):
    """An error while recording (any exception out of the row loop) removes the hidden
    part file: only complete demonstrations ever appear in the folder."""
    class Boom(Exception):
        pass

    def failing(*a, **k):
        raise Boom

    monkeypatch.setattr(record, "_record_rows", failing)
    args = argparse.Namespace(rate=100.0, min_distance=0.0, duration=None)
    with pytest.raises(Boom):
        record._record_file(None, tmp_path, args, threading.Event(), [])
    assert list(tmp_path.iterdir()) == []


def test_row_is_the_ee_in_the_object_frame():
    obj = [0.75, 0.0, 0.65, *YAW180]
    ee = [0.45, 0.1, 0.68, 0.0, 0.0, 0.0, 1.0]
    row = row_from_poses(0.0, ee, obj)
    T_obj_ee = se3.invert_transform(se3.transform_from_pose(obj)) @ se3.transform_from_pose(ee)
    np.testing.assert_allclose(row[1:4], T_obj_ee[:3, 3], atol=1e-12)
    np.testing.assert_allclose(row[1:4], [0.30, -0.1, 0.03], atol=1e-12)
    assert row[7] >= 0.0 and math.isclose(np.linalg.norm(row[4:]), 1.0)


def test_publish_final_never_overwrites(tmp_path):
    (tmp_path / "demo_000.csv").write_text("keep me")
    tmp = tmp_path / ".x.part"
    tmp.write_text("new")
    final = publish_final(tmp, tmp_path)
    assert final.name == "demo_001.csv" and final.read_text() == "new" and not tmp.exists()
    assert (tmp_path / "demo_000.csv").read_text() == "keep me"


@pytest.mark.slow
def test_record_until_sigint_against_a_fake_robot(tmp_path):
    """A robot that moves the ee along world +x in front of a turned object: rows are
    in the object frame (x decreasing), t from 0; SIGINT finishes the file; a second
    recording gets the next number; a recording too short for the learner is dropped."""
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    out = tmp_path / "demos"
    stop = threading.Event()
    published: list[tuple[str, codec.DemoMsg]] = []
    with open_session(listen=[ep]) as s:
        pub_s, pub_o = s.declare_publisher(KEYS.state), s.declare_publisher(KEYS.objects("box"))
        sub_d = s.declare_subscriber(KEYS.demos(), lambda m: published.append(
            (str(m.key_expr), codec.decode_demo(m.payload.to_bytes()))))

        def robot() -> None:
            k = 0
            while not stop.is_set():
                pose = [0.3 + 0.001 * k, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0]
                pub_s.put(codec.encode_state(k, time.time(), pose))
                pub_o.put(codec.encode_object(k, time.time(), [0.8, 0.0, 0.5, *YAW180]))
                k += 1
                time.sleep(0.004)

        th = threading.Thread(target=robot, daemon=True)
        th.start()
        try:
            for expect in ("demo_000.csv", "demo_001.csv"):
                rec = sctd("record", "--out", str(out), "--object", "box", "--rate", "100",
                           "--connect", ep, log=tmp_path / "rec.log")
                assert wait_for(lambda r=rec: "recording" in r.output(), 30), rec.output()
                time.sleep(0.6)
                rec.p.send_signal(signal.SIGINT)
                assert rec.p.wait(20) == 0, rec.output()
                rec.stop()
                assert (out / expect).exists(), rec.output()
            short = sctd("record", "--out", str(out), "--object", "box", "--duration", "0.05",
                         "--rate", "20", "--connect", ep, log=tmp_path / "short.log")
            assert short.p.wait(30) == 1 and "nothing written" in short.output()
            short.stop()
        finally:
            stop.set()
            th.join()
            pub_s.undeclare()
            pub_o.undeclare()
            sub_d.undeclare()
    demos = read_demos(out)
    assert [d.name for d in demos] == ["demo_000.csv", "demo_001.csv"]
    # each finished one was also published, rows as written (no scene: task = the object)
    assert [k for k, _ in published] == [KEYS.demos("box", "demo_000"), KEYS.demos("box", "demo_001")]
    for (_, msg), d in zip(published, demos, strict=True):
        assert (msg.task, msg.object) == ("box", "box")
        np.testing.assert_array_equal(np.asarray(msg.rows)[:, 0], d.t)
        np.testing.assert_array_equal(np.asarray(msg.rows)[:, 1:], d.poses)
    assert not list(out.glob(".*"))  # no partial files left
    for d in demos:
        assert d.t[0] == 0.0 and len(d) >= MIN_SAMPLES
        x = d.poses[:, 0]
        assert np.all(np.diff(x) < 0) and np.all(x <= 0.5)  # world +x is object -x, from 0.8 - 0.3
        np.testing.assert_allclose(np.abs(d.poses[:, 5]), 1.0, atol=1e-9)  # ee yawed 180 deg in it
    assert port_is_free(port)


@pytest.mark.slow
def test_record_from_the_sim_with_the_announced_task_object(tmp_path):
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    sim = sctd("sim", "--task", "pour", "--listen", ep, log=tmp_path / "sim.log")
    published: list[str] = []
    watch = open_session(connect=[ep])
    watch.declare_subscriber(KEYS.demos(), lambda m: published.append(str(m.key_expr)))
    try:
        rec = sctd("record", "--out", str(tmp_path), "--duration", "1.0", "--connect", ep, "--wait", "60",
                   log=tmp_path / "rec.log")
        assert rec.p.wait(90) == 0, rec.output() + sim.output()
        rec.stop()
    finally:
        watch.close()
        assert sim.stop() == 0, sim.output()
    assert "'mug'" in rec.output()
    assert published == [KEYS.demos("pour", "demo_000")]  # the task the simulator announces
    demo = read_demo_csv(tmp_path / "demo_000.csv")
    assert demo.t[0] == 0.0 and len(demo) >= 50
    # the arm holds its start pose: bottle upright 0.3 m in front of the mug (mug x
    # points back at the robot), 3 cm above its opening
    np.testing.assert_allclose(demo.poses[-1, :3], [0.30, 0.0, 0.03], atol=0.01)
    assert port_is_free(port)


def test_a_take_is_kept_or_discarded(tmp_path):
    """The recorder as a library: a take sampled in the background and discarded leaves no
    file and publishes nothing; the next one, kept, is demo_000.csv, published once on
    sctd/edan/demos/<task>/demo_000 with the file's rows; a take too short for the learner
    is not kept."""
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    stop = threading.Event()
    published: list[tuple[str, codec.DemoMsg]] = []
    with open_session(listen=[ep]) as robot_s, open_session(connect=[ep]) as s:
        pub_s = robot_s.declare_publisher(KEYS.state)
        pub_o = robot_s.declare_publisher(KEYS.objects("box"))
        sub_d = robot_s.declare_subscriber(KEYS.demos(), lambda m: published.append(
            (str(m.key_expr), codec.decode_demo(m.payload.to_bytes()))))

        def robot() -> None:
            k = 0
            while not stop.is_set():
                pub_s.put(codec.encode_state(k, time.time(), [0.3 + 0.001 * k, 0, 0.5, 0, 0, 0, 1]))
                pub_o.put(codec.encode_object(k, time.time(), [0.8, 0.0, 0.5, *YAW180]))
                k += 1
                time.sleep(0.004)

        th = threading.Thread(target=robot, daemon=True)
        th.start()
        try:
            with record.Recorder(s, "edan", "box", task="slide") as rec:
                assert wait_for(lambda: rec.sample() is not None, 10)
                with record.Take(rec, tmp_path, rate=100.0) as take:
                    take.start()
                    assert wait_for(lambda: len(take.rows) >= 20, 10)
                    assert take.stop() >= 20 and take.long_enough
                    take.discard()
                assert list(tmp_path.iterdir()) == [] and take.path is None
                with record.Take(rec, tmp_path, rate=100.0) as take:
                    take.start()
                    assert wait_for(lambda: len(take.rows) >= 20, 10)
                    kept = take.keep()
                assert kept == tmp_path / "demo_000.csv" and take.key == KEYS.demos("slide", "demo_000")
                with record.Take(rec, tmp_path, rate=100.0) as short:
                    assert short.keep() is None  # no rows: not kept
            assert wait_for(lambda: published, 5)
        finally:
            stop.set()
            th.join()
            pub_s.undeclare()
            pub_o.undeclare()
            sub_d.undeclare()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo_000.csv", "demos.yaml"]
    assert read_demos_info(tmp_path) == DemosInfo("slide", "box")
    assert [k for k, _ in published] == [KEYS.demos("slide", "demo_000")]
    msg = published[0][1]
    assert (msg.task, msg.object) == ("slide", "box")
    written = np.loadtxt(kept, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(np.asarray(msg.rows), written)
    assert len(take.rows) == len(written) and written[0, 0] == 0.0
    assert port_is_free(port)
