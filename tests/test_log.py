"""sctd log --mcap records the contract into an MCAP file the mcap reader (Foxglove's)
decodes; sctd replay publishes its observation keys again, commands only with --all, and
never over a live daemon."""

from __future__ import annotations

import json
import math
import threading
import time

import msgpack
import pytest
import zenoh
from mcap.reader import make_reader

from sctd.cli.log import kind_of, read_log, schema
from sctd.runtime import codec
from sctd.runtime.zsession import open_session

from .conftest import free_port, run_sctd, wait_for
from .test_e2e_runtime import KEYS, daemon  # noqa: F401  (the fixture)


def test_kinds_and_schemas():
    assert kind_of("sctd/edan/objects/mug", "sctd/edan") == "objects"
    assert kind_of("sctd/edan/input/pad", "sctd/edan") == "input"
    assert kind_of("sctd/edan/skill", "sctd/edan") is None
    assert kind_of("sctd/other/target", "sctd/edan") is None
    s = json.loads(schema("target"))
    assert s["type"] == "object" and s["properties"]["pose"]["minItems"] == 7


@pytest.fixture
def logged(daemon, tmp_path):  # noqa: F811
    """Two seconds of a running daemon and its test robot, logged."""
    _, rig, port = daemon
    path = tmp_path / "run.mcap"
    done = threading.Event()

    def inputs() -> None:  # a held-still stick, as a bridge sends it
        k = 0
        while not done.wait(0.02):
            k += 1
            rig.pub_in.put(codec.encode_input(k, time.time(), [0.0, 0.0, 0.0], [0, 1, 0]))

    t = threading.Thread(target=inputs, daemon=True)
    t.start()
    try:
        out = run_sctd("log", "--mcap", str(path), "--duration", "3", "--connect", f"tcp/127.0.0.1:{port}")
    finally:
        done.set()
        t.join()
    assert out.returncode == 0, out.stderr
    return path, port


def test_the_log_holds_every_contract_key_as_json_with_its_schema(logged):
    path, _ = logged
    with path.open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None
        topics = {c.topic: c for c in summary.channels.values()}
        for key in (KEYS.target, KEYS.status, KEYS.state, KEYS.objects("mug"), KEYS.input("test")):
            assert key in topics, sorted(topics)
            ch = topics[key]
            assert ch.message_encoding == "json"
            assert summary.schemas[ch.schema_id].encoding == "jsonschema"
        seqs = []
        for _, _channel, message in reader.iter_messages(topics=[KEYS.target]):
            value = json.loads(message.data)
            assert len(value["pose"]) == 7 and all(math.isfinite(x) for x in value["pose"])
            assert message.publish_time == pytest.approx(value["stamp"] * 1e9, abs=1e3)
            seqs.append(value["seq"])
        assert len(seqs) > 100 and seqs == sorted(seqs)


def test_replay_refuses_over_a_live_daemon(logged):
    path, port = logged
    out = run_sctd("replay", str(path), "--connect", f"tcp/127.0.0.1:{port}")
    assert out.returncode == 1 and "live program" in out.stderr


def test_replay_publishes_observations_and_commands_only_with_all(tmp_path):
    # A log written without a daemon (its keys as a recorded run would have them).
    from sctd.cli.log import McapLog

    path = tmp_path / "made.mcap"
    log = McapLog(path)
    t = time.time()
    for k in range(20):
        pose = [0.1, 0, 0.5, 0, 0, 0, 1]
        log.add(KEYS.state, "state", codec.encode_state(k, t + k * 0.01, pose), t + k * 0.01)
        log.add(KEYS.target, "target", codec.encode_target(k, t + k * 0.01, [0.1, 0, 0.5, 0, 0, 0, 1], "s",
                                                              "id", k), t + k * 0.01)
    log.close()
    assert len(read_log(path)) == 40
    port = free_port()
    s = open_session(listen=[f"tcp/127.0.0.1:{port}"])  # the listening side: replay connects here
    try:
        got: dict[str, list] = {"state": [], "target": []}
        lock = threading.Lock()

        def on(kind):
            def f(sample: zenoh.Sample) -> None:
                with lock:
                    msg = msgpack.unpackb(sample.payload.to_bytes())
                    got[kind].append((str(sample.encoding), msg))
            return f

        subs = [s.declare_subscriber(KEYS.state, on("state")),
                s.declare_subscriber(KEYS.target, on("target"))]
        try:
            time.sleep(0.5)
            out = run_sctd("replay", str(path), "--speed", "4", "--connect", f"tcp/127.0.0.1:{port}")
            assert out.returncode == 0, out.stderr
            assert wait_for(lambda: len(got["state"]) == 20, 10), (out.stderr, len(got["state"]))
            assert got["target"] == []
            assert {e for e, _ in got["state"]} == {"application/msgpack"}
            assert [m["seq"] for _, m in got["state"]] == list(range(20))
            out = run_sctd("replay", str(path), "--all", "--connect", f"tcp/127.0.0.1:{port}")
            assert out.returncode == 0, out.stderr
            assert wait_for(lambda: len(got["target"]) == 20, 10), (out.stderr, len(got["target"]))
        finally:
            for sub in subs:
                sub.undeclare()
    finally:
        s.close()
