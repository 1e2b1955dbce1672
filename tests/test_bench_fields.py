"""sctd bench learn's field-type figures: the report covers every task with both
selections, the truth it is measured against, and the automatic frames."""

from __future__ import annotations

from sctd.bench.fields import TASKS, format_field_bench, run_field_bench


def test_the_field_report_compares_both_selections_on_every_task():
    r = run_field_bench(seeds=1)
    assert set(r["tasks"]) == set(TASKS)
    for row in r["tasks"].values():
        for sel in ("likelihood", "inliers"):
            assert 0.0 <= row[sel]["accuracy"] <= 1.0 and row[sel]["time_s_max"] > 0
    assert r["tasks"]["crank"]["likelihood"]["accuracy"] == 1.0
    assert r["tasks"]["crank"]["likelihood"]["axis_error_deg_max"] < 3.0
    f = r["frames"]
    assert f["tip_offset_error_m_max"] < 0.01 and f["crank_axis_offset_error_m_max"] < 0.01
    text = "\n".join(format_field_bench(r))
    for task in TASKS:
        assert task in text
    assert "automatic frames" in text
