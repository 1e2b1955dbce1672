"""sctd log --mcap records the contract into an MCAP file the mcap reader (Foxglove's)
decodes; sctd replay publishes its observation keys again, commands only with --all, and
never over a live daemon."""

from __future__ import annotations

import json
import math
import threading
import time
from pathlib import Path

import msgpack
import pytest
import zenoh
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader

from sctd.cli.log import kind_of, read_log, schema
from sctd.wire import codec
from sctd.wire.session import open_session

from .conftest import free_port, run_sctd, sctd, wait_for
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
    """Two seconds of a running daemon's ticks (2,000 targets by its seq, however the
    machine lags) and its test robot, logged from the moment ``sctd log`` subscribed
    until it is stopped (SIGTERM, as a person's Ctrl-C or a service manager's stop)."""
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
    log = sctd("log", "--mcap", str(path), "--connect", f"tcp/127.0.0.1:{port}", log=tmp_path / "log.log")
    try:
        assert wait_for(lambda: "->" in log.output(), 60), log.output()  # subscribed
        first = rig.last()["seq"]
        assert wait_for(lambda: rig.last()["seq"] >= first + 2000, 60), "the daemon stopped publishing"
    finally:
        rc = log.stop()
        done.set()
        t.join()
    assert rc == 0, log.output()
    return path, port


@pytest.mark.slow
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


@pytest.mark.slow
def test_replay_refuses_over_a_live_daemon(logged):
    path, port = logged
    out = run_sctd("replay", str(path), "--connect", f"tcp/127.0.0.1:{port}")
    assert out.returncode == 1 and "live program" in out.stderr


@pytest.mark.slow
def test_replay_publishes_observations_and_commands_only_with_all(tmp_path):
    # A log written without a daemon (its keys as a recorded run would have them).
    from sctd.cli.log import McapLog

    path = tmp_path / "made.mcap"
    t = time.time()
    with McapLog(path) as log:
        for k in range(20):
            pose = [0.1, 0, 0.5, 0, 0, 0, 1]
            log.add(KEYS.state, "state", codec.encode_state(k, t + k * 0.01, pose), t + k * 0.01)
            log.add(KEYS.target, "target", codec.encode_target(k, t + k * 0.01, [0.1, 0, 0.5, 0, 0, 0, 1],
                                                                  "s", "id", k), t + k * 0.01)
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


# --- a log file is input like any other: checked as it is read ---------------------------

def _log_file(path, n=20):
    from sctd.cli.log import McapLog

    t = 1_800_000_000.0
    with McapLog(path) as log:
        for k in range(n):
            log.add(KEYS.state, "state", codec.encode_state(k, t + k * 0.01, [0.1, 0, 0.5, 0, 0, 0, 1]),
                    t + k * 0.01)
    return path


@given(st.integers(0, 10**9), st.integers(0, 7))
@settings(max_examples=60, deadline=None)
def test_a_flipped_bit_is_an_error_or_changes_nothing(tmp_path_factory, where, bit):
    """The audit flipped single bits: 5 of 40 replayed with changed values. With the
    CRCs checked a flip is refused, or lands where it changes no message."""
    from sctd.cli.log import LogError, log_messages

    path = _log_file(tmp_path_factory.mktemp("flip") / "a.mcap")
    good = list(log_messages(path))
    data = bytearray(path.read_bytes())
    data[where % len(data)] ^= 1 << bit
    path.write_bytes(bytes(data))
    try:
        got = list(log_messages(path))
    except LogError as e:
        assert str(e).startswith(str(path))
    else:
        assert got == good


def _raw_mcap(path, *records):
    """An MCAP file of a header, ``records`` (mcap record objects) and a footer."""
    from mcap.data_stream import RecordBuilder
    from mcap.records import DataEnd, Footer, Header
    from mcap.writer import MCAP0_MAGIC

    b = RecordBuilder()
    b.write(MCAP0_MAGIC)
    Header(profile="", library="test").write(b)
    for r in records:
        r.write(b)
    DataEnd(0).write(b)
    Footer(0, 0, 0).write(b)
    b.write(MCAP0_MAGIC)
    path.write_bytes(b.end())
    return path


def _schema():
    from mcap.records import Schema

    return Schema(id=1, name="s", encoding="jsonschema", data=b"{}")


def _channel(topic):
    from mcap.records import Channel

    return Channel(id=1, topic=topic, message_encoding="json", metadata={}, schema_id=1)


def _message(data):
    from mcap.records import Message

    return Message(channel_id=1, log_time=0, data=data, publish_time=0, sequence=1)


@pytest.mark.parametrize("topic", ["sctd/edan/state/**", "sctd/edan/state//x", "sctd/*/state",
                                   "sctd/edan/objects", "other/edan/state", "sctd/../state"])
def test_topics_that_are_not_keys_of_the_contract_are_refused(tmp_path, topic):
    from sctd.cli.log import LogError, log_messages

    path = _raw_mcap(tmp_path / "t.mcap", _schema(), _channel(topic),
                     _message(b'{"seq": 1, "stamp": 1.0, "pose": [0,0,0,0,0,0,1]}'))
    with pytest.raises(LogError, match="topic"):
        list(log_messages(path))


@pytest.mark.parametrize("body, what", [(b"[1, 2]", "expected a JSON map, got list"),
                                        (b"null", "expected a JSON map, got NoneType"),
                                        (b"{", "not JSON")])
def test_a_body_that_is_not_a_json_map_is_refused(tmp_path, body, what):
    from sctd.cli.log import LogError, log_messages

    path = _raw_mcap(tmp_path / "b.mcap", _schema(), _channel(KEYS.state), _message(body))
    with pytest.raises(LogError, match=f"message 1: {what}"):
        list(log_messages(path))


def test_a_zstd_bomb_is_refused_without_inflating_it(tmp_path):
    """A few kB of zstd that claims, or inflates to, hundreds of megabytes."""
    import resource

    import zstandard
    from mcap.records import Chunk

    from sctd.cli.log import MAX_CHUNK, LogError, log_messages

    bomb = zstandard.ZstdCompressor(level=19).compress(b"\0" * (300 << 20))
    assert len(bomb) < 20_000
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    for declared, what in ((300 << 20, f"more than the {MAX_CHUNK} allowed"),
                           (1000, "unpacks to other than its 1000 bytes")):
        path = _raw_mcap(tmp_path / "bomb.mcap", Chunk(compression="zstd", data=bomb, message_end_time=0,
                                                       message_start_time=0, uncompressed_crc=0,
                                                       uncompressed_size=declared))
        with pytest.raises(LogError, match=what):
            list(log_messages(path))
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert grown_mb < 50


def test_a_device_is_no_log(tmp_path):
    from sctd.cli.log import LogError, log_messages

    with pytest.raises(LogError, match="/dev/zero: a character device"):
        list(log_messages(Path("/dev/zero")))
    assert len(list(log_messages(_log_file(tmp_path / "ok.mcap")))) == 20
