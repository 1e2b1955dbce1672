"""`sctd bench input` runs end to end and reports what it measured (its figures are for
docs/benchmarks.md; the suite asserts no times)."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from tests.conftest import ROOT

pytestmark = pytest.mark.slow  # runs sctd bench as a process


def test_bench_input_answers_every_stick_event_and_reports_the_emg_chain(tmp_path):
    out = subprocess.run([sys.executable, "-m", "sctd.cli.main", "bench", "input", "--seconds", "3",
                          "--events", "20", "--emg-seconds", "1", "--json", "--logs", str(tmp_path)],
                         capture_output=True, text=True, cwd=ROOT, timeout=240,
                         env={**__import__("os").environ, "SDL_VIDEODRIVER": "dummy"})
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    g = r["gamepad"]
    assert g["events"] >= 20 and g["answered"] == g["events"]  # every move reached a target
    lat = g["event_to_target_ms"]
    assert lat["n"] == g["answered"] and 0 < lat["p50"] <= lat["p99"] <= lat["max"]
    assert r["criteria"]["bound_ms"] > 1e3 / g["bridge_rate_hz"]
    e = r["emg"]
    assert e["reads"] > 50 and all(math.isfinite(e[k]) and e[k] > 0 for k in ("p50_ms", "p99_ms"))
    assert e["envelope_group_delay_ms"] > 0
