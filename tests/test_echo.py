"""sctd echo / sctd hz decode what the daemon publishes, and every publication declares
its encoding (application/msgpack)."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import msgpack
import pytest
import zenoh

from sctd.cli.echo import Rates, decode, full_key
from sctd.wire import codec

from .conftest import ROOT, run_sctd, wait_for
from .test_e2e_runtime import KEYS, daemon  # noqa: F401  (the fixture)


def test_keys_values_and_payloads_decode():
    assert full_key("target", "edan") == "sctd/edan/target"
    assert full_key("/input/*", "arm2") == "sctd/arm2/input/*"
    assert full_key("sctd/x/status", "edan") == "sctd/x/status"
    kind, value = decode(codec.encode_input(3, 1.5, [0.1, 0.0, -0.2], (0, 1, 0)))
    assert kind == "msgpack" and value["seq"] == 3 and value["u"] == [0.1, 0.0, -0.2]
    kind, value = decode(msgpack.packb({"blob": b"\x00" * 10, 1: float("nan")}))
    assert value == {"blob": {"bytes": 10}, "1": "nan"}
    assert decode(b"7") == ("msgpack", 55)  # the digit 7 is also the msgpack integer 55 ...
    assert decode(b"7", "text/plain") == ("text", "7")  # ... so a declared encoding decides
    assert decode("héllo wörld".encode())[0] == "text"
    kind, value = decode(b"\xc1\xff\xfe")
    assert kind == "bytes" and value == {"bytes": 3, "head": "c1fffe"}


def test_rates_over_a_window():
    r = Rates(window=3)
    for t in (0.0, 0.1, 0.2, 0.3, 0.5):
        r.add("k", t)
    rep = r.report()["k"]
    assert rep["window"] == 3 and abs(rep["max_s"] - 0.2) < 1e-12 and abs(rep["min_s"] - 0.1) < 1e-12
    assert abs(rep["rate_hz"] - 3 / 0.4) < 1e-9


@pytest.mark.slow
def test_echo_and_hz_on_the_daemons_target(daemon):  # noqa: F811
    _, rig, port = daemon
    seen: list[str] = []
    sub = rig.session.declare_subscriber(KEYS.target, lambda s: seen.append(str(s.encoding)))
    stat: list[str] = []
    sub2 = rig.session.declare_subscriber(KEYS.status, lambda s: stat.append(str(s.encoding)))
    try:
        ep = f"tcp/127.0.0.1:{port}"
        out = run_sctd("echo", "target", "--json", "--count", "3", "--connect", ep)
        assert out.returncode == 0, out.stderr
        lines = [json.loads(x) for x in out.stdout.splitlines()]
        assert len(lines) == 3
        for d in lines:
            assert d["key"] == "sctd/edan/target" and d["encoding"] == "application/msgpack"
            assert d["as"] == "msgpack" and len(d["value"]["pose"]) == 7
            assert all(math.isfinite(x) for x in d["value"]["pose"])
        seqs = [d["value"]["seq"] for d in lines]
        assert seqs == sorted(seqs) and len(set(seqs)) == 3
        hz = run_sctd("hz", "target", "--json", "--timeout", "3", "--connect", ep)
        assert hz.returncode == 0, hz.stderr
        reports = [json.loads(x) for x in hz.stdout.splitlines()]
        last = reports[-1]["sctd/edan/target"]
        assert last["window"] > 10 and last["rate_hz"] > 0 and last["min_s"] <= last["max_s"]
        assert wait_for(lambda: seen and stat, 10)
        assert set(seen) == {"application/msgpack"} and set(stat) == {"application/msgpack"}
    finally:
        sub.undeclare()
        sub2.undeclare()


@pytest.mark.slow
def test_a_plain_text_sample_is_shown_as_text(daemon):  # noqa: F811
    _, rig, port = daemon
    proc = subprocess.Popen([sys.executable, "-m", "sctd.cli.main", "echo", "sctd/edan/note", "--json",
                             "--count", "1", "--connect", f"tcp/127.0.0.1:{port}"], cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        def sent_and_done() -> bool:
            rig.session.put("sctd/edan/note", "hello", encoding=zenoh.Encoding.TEXT_PLAIN)
            return proc.poll() is not None
        assert wait_for(sent_and_done, 30, interval=0.2)
        d = json.loads(proc.stdout.read().splitlines()[0])
        assert d["as"] == "text" and d["value"] == "hello" and d["encoding"].startswith("text/plain")
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
