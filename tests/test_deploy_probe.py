"""The namespace probe (``python -m sctd.deploy.probe``), in process on loopback: what a
``put`` sends a ``listen`` counts, key by key and by mark, and a session the router
refuses is a result, not a crash."""

from __future__ import annotations

import json
import threading

from sctd.deploy import probe
from tests.conftest import free_port


def _config(path, **conf) -> str:
    conf.setdefault("scouting", {"multicast": {"enabled": False}})
    path.write_text(json.dumps(conf))
    return str(path)


def _results(text: str) -> list[dict]:
    return [json.loads(line) for line in text.splitlines() if line.startswith("{")]


def test_listen_counts_what_put_sends_per_key_and_mark(tmp_path, capsys):
    port = free_port()
    lis = _config(tmp_path / "lis.json5", mode="peer", listen={"endpoints": [f"tcp/127.0.0.1:{port}"]})
    put = _config(tmp_path / "put.json5", mode="peer", connect={"endpoints": [f"tcp/127.0.0.1:{port}"]},
                  listen={"endpoints": []})
    putter = threading.Thread(target=probe.main, args=(
        ["put", "--config", put, "--key", "sctd/probe/a", "--key", "sctd/probe/b", "--n", "20",
         "--rate", "200", "--settle", "1.0", "--payload", '{"who": "robot"}'],))
    putter.start()  # (the listener waits in the main thread: it takes the stop signals)
    rc = probe.main(["listen", "--config", lis, "--key", "sctd/probe/a", "--key", "sctd/probe/b",
                     "--mark", "who", "--seconds", "3"])
    putter.join(10)
    assert rc == 0 and not putter.is_alive()
    out = _results(capsys.readouterr().out)
    sent = next(r for r in out if "sent" in r)
    counts = next(r for r in out if "counts" in r)
    assert sent == {"sent": {"sctd/probe/a": 20, "sctd/probe/b": 20}, "tried": 40}
    assert counts["counts"] == {"sctd/probe/a": 20, "sctd/probe/b": 20}
    assert counts["marked"] == {"robot": {"sctd/probe/a": 20, "sctd/probe/b": 20}}


def test_a_refused_session_is_reported(tmp_path, capsys):
    nobody = _config(tmp_path / "client.json5", mode="client",
                     connect={"endpoints": [f"tcp/127.0.0.1:{free_port()}"], "timeout_ms": 300})
    assert probe.main(["put", "--config", nobody, "--key", "sctd/probe/a", "--n", "3"]) == 0
    [r] = _results(capsys.readouterr().out)
    assert r["sent"] == {"sctd/probe/a": 0} and r["tried"] == 3 and r["refused"]
