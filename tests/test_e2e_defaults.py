"""The defaults users rely on: a plain Zenoh client on tcp/127.0.0.1:7447 reaches a
flag-less `sctd run`, and `sctd demo` (the README's main command) runs end to end."""

from __future__ import annotations

import json

import msgpack
import pytest
import zenoh

from sctd.wire import Keys
from tests.conftest import ROOT, port_is_free, sctd, wait_for

pytestmark = pytest.mark.slow  # the daemon and its peers as processes


def plain_client(endpoint: str) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"client"')
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def test_default_run_is_reachable_on_7447(tmp_path):
    assert wait_for(lambda: port_is_free(7447), 30), "tcp/127.0.0.1:7447 is held by another program"
    proc = sctd("run", "--skill", str(ROOT / "skills" / "pour.yaml"), log=tmp_path / "d.log")
    try:
        assert wait_for(lambda: not port_is_free(7447), 20), proc.output()
        with plain_client("tcp/127.0.0.1:7447") as s:
            def summary():
                for reply in s.get(Keys().skill, timeout=2.0):
                    if reply.ok is not None:
                        return msgpack.unpackb(reply.ok.payload.to_bytes(), raw=False)
                return None

            got = wait_for(summary, 20)
            assert got and got["name"] == "pour" and got["object"] == "mug"
    finally:
        assert proc.stop() == 0, proc.output()
    assert port_is_free(7447)


def test_demo_runs_the_pour_skill_end_to_end(tmp_path):
    proc = sctd("demo", "--skill", str(ROOT / "skills" / "pour.yaml"), "--seconds", "60",
                "--logs", str(tmp_path / "logs"), log=tmp_path / "demo.log")
    assert proc.p.wait(240) == 0, proc.output()
    out = proc.output()
    # the simulated user (task intent, learned device model) carries the bottle over the
    # mug and pours with the hand-written skill
    assert "state - -> carry" in out and "carry -> approach" in out and "approach -> pour" in out, out
    assert "input -> target latency" in out and "tick lateness" in out
    assert "task outcome (sim): pour done" in out and "bottle.poured" in out, out  # the scene reported back
