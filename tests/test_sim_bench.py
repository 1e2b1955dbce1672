"""The benchmark functions run and report (figures are checked, wall-clock is not)."""

from __future__ import annotations

import math

from sctd_sim.bench import format_report, measure_rtf, tracking


def test_measure_rtf_reports_its_figures():
    r = measure_rtf(seconds=0.1, chunk=0.05)
    assert r["sim_seconds"] == 0.1
    assert r["rtf"] > 0 and r["rtf_best_chunk"] >= r["rtf"] * 0.999
    assert r["frames_per_cycle"] == 15


def test_tracking_at_a_quarter_metre_per_second_is_within_5_mm():
    t = tracking(speed=0.25, distance=0.15, axis=2)
    assert t["max_error_m"] < 5e-3
    assert t["rms_error_m"] <= t["max_error_m"]


def test_format_report():
    result = {
        "rtf": {"rate_hz": 1000.0, "frames_per_cycle": 15, "sim_seconds": 3.0, "rtf": 4.2,
                "rtf_best_chunk": 4.5, "cycle_us_median": 230.0},
        "step": [{"axis": "x", "settling_time_s": 0.3, "overshoot_m": 0.0,
                  "final_error_m": 1e-6}],
        "tracking": [{"speed_m_s": 0.25, "axis": "y", "max_error_m": 0.003,
                      "rms_error_m": 0.001, "cruise_max_error_m": 0.002}],
        "pass": {"rtf>=4": True, "settle<1s": True},
    }
    text = format_report(result)
    assert "real-time factor" in text and "4.20" in text
    assert "settles < 1 mm in 300 ms" in text
    assert "max 3.00 mm" in text
    assert "rtf>=4 ok" in text
    assert not math.isnan(result["rtf"]["rtf"])
