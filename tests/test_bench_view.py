"""`sctd bench view`: the daemon's per-second tick figures in phases with the live view
and a headless Chromium attached and without, alternating in one run."""

from __future__ import annotations

import json
import os

import pytest

from tests import browser
from tests.conftest import run_sctd


@pytest.mark.slow
def test_bench_view_alternates_closed_and_open_phases_and_judges_them(tmp_path):
    """... and leaves nothing in the temp folder it ran with: not the Chromium it kills
    at the end (which left an org.chromium.Chromium.* folder there each run), not the
    programs it starts."""
    browser.require_chromium()
    temp = tmp_path / "tmp"
    temp.mkdir()
    r = run_sctd("bench", "view", "--phases", "1", "--phase", "3", "--json", timeout=240,
                 env={**os.environ, "TMPDIR": str(temp)})
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in temp.iterdir()) == []
    out = json.loads(r.stdout)
    assert [p["phase"] for p in out["phases"]] == ["closed", "open", "closed"]
    for p in out["phases"]:
        assert 2 <= p["seconds"] <= 4, p  # one figure a second of the daemon's status
        assert p["lateness_p99_ms"]["median"] >= 0.0 and p["compute_p99_ms"]["max"] > 0.0
    c = out["criteria"]
    lo, hi = c["closed_lateness_p99_ms_spread"]
    assert lo <= hi and isinstance(c["open_lateness_p99_ms_within_closed_spread"], bool)
