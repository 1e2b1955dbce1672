"""The daemon's tick thread timed part by part (sctd.bench.parts, ``sctd bench cost
--parts``): the wrappers, the figures a tick between two written sums, and a real
``sctd run`` with its loop's parts timed."""

from __future__ import annotations

import json
import time

import pytest

from sctd.bench import parts
from sctd.cli.main import main
from tests.conftest import Proc, free_port, port_is_free


def _sums(ticks: int, thread_s: float, s: dict[str, float], calls: dict[str, int], read: float = 0.0) -> dict:
    return {"ticks": ticks, "thread_s": thread_s, "clock_read_s": read,
            "parts": {p: {"s": s.get(p, 0.0), "calls": calls.get(p, 0)} for p in parts.PARTS}}


def test_a_timed_part_adds_its_cpu_and_its_calls_even_when_it_raises():
    clock = parts.PartClock()

    def busy(n: int) -> int:
        end = time.thread_time() + 0.002
        while time.thread_time() < end:
            pass
        if n < 0:
            raise ValueError("no")
        return n

    step = clock.timed("step", busy)
    assert step(3) == 3
    with pytest.raises(ValueError):
        step(-1)
    assert clock.calls["step"] == 2 and clock.s["step"] >= 0.004
    assert all(clock.s[p] == 0.0 and clock.calls[p] == 0 for p in parts.PARTS if p != "step")


def test_the_parts_a_tick_are_the_differences_with_each_calls_clock_read_taken_off():
    before = _sums(1000, 1.0, {"drain": 0.5, "step": 0.2}, {"drain": 1000, "step": 1000}, read=1e-6)
    after = _sums(2000, 1.15, {"drain": 0.54, "step": 0.25, "status": 0.001},
                  {"drain": 2000, "step": 2000, "status": 20}, read=1e-6)
    got = parts.per_tick(before, after)
    # 1000 ticks: drain 40 ms less 1000 reads of 1 us, step 50 ms less the same, status 1 ms
    # less 20 reads; the thread 150 ms; the rest what the parts leave of it
    assert got is not None
    assert got["drain"] == 39.0 and got["step"] == 49.0 and got["status"] == 1.0 and got["spin"] == 0.0
    assert got["thread"] == 150.0 and got["rest"] == pytest.approx(150.0 - 39.0 - 49.0 - 1.0, abs=0.05)
    assert parts.per_tick(before, before) is None


def test_the_wrapper_refuses_a_command_line_it_does_not_know(capsys):
    assert parts.main(["run", "--skill", "pour"]) == 2
    assert "usage: python -m sctd.bench.parts --out FILE run" in capsys.readouterr().err


def test_parts_are_for_this_tree_alone(capsys):
    assert main(["bench", "cost", "--parts", "--baseline", "HEAD"]) == 2
    assert "--parts times this tree's daemon only" in capsys.readouterr().err


@pytest.mark.slow
def test_a_real_daemon_writes_its_parts_and_they_fit_in_its_threads_cpu(tmp_path):
    """``sctd run`` for 2 s with no robot (nothing to publish): every tick drains, spins,
    steps and accounts, once each; nothing is put; 20 status maps a second; the parts add up to less than the
    thread's CPU, the rest being its sleeps and its loop."""
    port = free_port()
    out = tmp_path / "parts.json"
    proc = Proc("sctd.bench.parts", "--out", str(out), "run", "--skill", "pour", "--listen",
                f"tcp/127.0.0.1:{port}", "--duration", "2", log=tmp_path / "run.log")
    try:
        assert proc.p.wait(60) == 0, proc.output()
    finally:
        proc.stop()
    sums = json.loads(out.read_text())
    ticks, c = sums["ticks"], {p: v["calls"] for p, v in sums["parts"].items()}
    assert ticks > 1000, sums
    # each tick drains and spins (the ticker counts its ticks there), then steps and
    # accounts; the last one, at the run's end, stops before its step
    assert c["drain"] == c["spin"] == ticks and c["step"] == c["account"], sums
    assert 0 <= ticks - c["step"] <= 1, sums
    assert c["put"] == 0 and 20 <= c["status"] <= 60, sums  # no state: no target; 20 status maps a second
    spent = sum(v["s"] for v in sums["parts"].values())
    assert 0.0 < spent < sums["thread_s"], sums
    got = parts.per_tick(_sums(0, 0.0, {}, {}), sums)
    assert got is not None and got["step"] > 0.0 and got["rest"] > 0.0
    assert port_is_free(port)
