"""sctd bench learn's field-type figures: the report covers every task with both
selections, the truth it is measured against, and the automatic frames."""

from __future__ import annotations

from sctd.app.defaults import defaults
from sctd.bench.fields import format_field_bench, run_field_bench

TASKS = defaults().bench_learn.fields  # what sctd bench learn generates: pour, drawer, crank, wipe


def test_the_field_report_compares_both_selections_on_every_task():
    r = run_field_bench(seeds=1)
    assert list(r["tasks"]) == list(TASKS) == ["pour", "drawer", "crank", "wipe"]
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


def test_the_learn_report_says_when_no_seed_found_the_sphere():
    """``sctd bench learn``'s report of a run in which the pour's sphere was never found
    (few demonstrations, one seed) marks it missing instead of failing on the blanks."""
    from sctd.bench.learn import format_bench

    r = {"seed": 0, "n_demos": 4, "outliers": 0.05, "noise": 0.001, "tilt": "pour", "pull": "drawer",
         "segmentation_accuracy": 0.97, "segmentation_accuracy_min_demo": 0.9,
         "tilt_state_tip_rotation_only": False, "states": ["s0", "s1"], "tilt_sphere_centre_error_m": None,
         "tilt_sphere_found": "0/1", "tilt_sphere_centre_spread_m": None, "tilt_tip_offset_from_sphere": None,
         "pull_direction_error_deg": {"pull": 1.5, "reach": None}, "linear_time_s": 0.4,
         "vf_tilt_time_s": 1.0, "vf_pull_time_s": 1.0, "sklearn_import_s": 0.3,
         "swap_vs_gco": {"available": False, "reason": "not installed", "install": "pip install gco-wrapper"}}
    text = format_bench(r)
    assert "[MISS] pour sphere centre error - (max over seeds, found 0/1), spread -" in text
    assert "[MISS] drawer field direction errors pull 1.50 deg, reach - deg" in text
