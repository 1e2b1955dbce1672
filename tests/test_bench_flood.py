"""``sctd bench flood``: rounds of the valid-input flood next to the simulator, the
daemon's Zenoh threads at ``--io-nice`` and at the baseline nice, interleaved; every
figure from the daemon's own status (its ticks, late ticks, long drains, lateness
windows) and the flooder's own count. The figures' values are the machine's: the
tests assert what each round is and reports, never how fast."""

from __future__ import annotations

import json

import pytest

from sctd.bench.flood import print_report
from sctd.cli.main import main
from tests.conftest import run_sctd


@pytest.mark.parametrize(("args", "message"), [
    (["--io-nice", "20"], "--io-nice: 20: a nice value is -20 to 19"),
    (["--baseline-io-nice", "-21"], "--baseline-io-nice: -21: a nice value is -20 to 19"),
    (["--rounds", "0"], "--rounds: 0: at least 1"),
    (["--seconds", "0"], "--seconds: 0.0: more than 0"),
    (["--devices", "0"], "--devices: 0: at least 1"),
    (["--flooders", "0"], "--flooders: 0: at least 1"),
])
def test_bad_arguments_are_refused_by_name_before_anything_starts(capsys, args, message):
    assert main(["bench", "flood", *args]) == 2
    assert message in capsys.readouterr().err


def test_the_report_has_a_row_a_round_and_a_line_for_each_nice(capsys):
    row = {"round": 0, "io_nice": -10, "asked_io_nice": -10, "sent_per_s": 400000, "ticks": 7600,
           "late_ticks": 1, "skipped_ticks": 0, "long_drains": 9, "long_drains_per_1000_ticks": 1.18,
           "lateness_p99_ms_worst_window": 0.03, "lateness_p99_ms_median_window": 0.005}
    summary = {"rounds": 1, "long_drains_per_1000_ticks_median": 1.18,
               "lateness_p99_ms_worst_window_median": 0.03, "rounds_within_goal": 1,
               "sent_per_s_median": 400000}
    print_report({"skill": "pour", "task": "pour", "io_nice": -10, "baseline_io_nice": 0, "seconds": 5.0,
                  "devices": 1, "flooders": 1,
                  "rounds": [row, {**row, "io_nice": 0, "asked_io_nice": 0}],
                  "summary": {"-10": summary, "0": summary}})
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("sctd bench flood: pour on pour, the daemon connected to the simulator")
    assert "Zenoh threads at nice -10 and (baseline) 0" in out[0]
    assert [ln.split()[1] for ln in out[2:4]] == ["-10", "0"]
    assert out[4].startswith("  nice -10: long drains per 1000 ticks (median of 1) 1.18")
    assert "within 0.2 ms in 1 of 1 rounds" in out[5]


@pytest.mark.slow
def test_one_round_of_each_nice_runs_the_flood_and_reads_the_daemons_counts(tmp_path):
    """A round of each, a second of flood from 2 processes on 4 device names: each round's daemon says it
    ran its Zenoh threads at the nice asked for (this runs as root, as CI does), ticked
    through the flood, and the flooder sent; the counts are the status' own."""
    r = run_sctd("bench", "flood", "--rounds", "1", "--seconds", "1", "--devices", "4", "--io-nice", "-5",
                 "--flooders", "2", "--json", "--logs", str(tmp_path), timeout=240)
    assert r.returncode == 0, r.stdout + r.stderr
    doc = json.loads(r.stdout)
    rounds = doc["rounds"]
    assert [(x["round"], x["asked_io_nice"], x["io_nice"]) for x in rounds] == [(0, 0, 0), (0, -5, -5)]
    for x in rounds:
        assert x["sent"] > 1000 and x["ticks"] > 1500  # the second of flood and the settling after it
        assert 0 <= x["long_drains"] <= x["ticks"] and x["skipped_ticks"] >= 0
        assert x["long_drains_per_1000_ticks"] == round(1000 * x["long_drains"] / x["ticks"], 2)
    assert set(doc["summary"]) == {"-5", "0"} and doc["summary"]["-5"]["rounds"] == 1
    # both flooders of each round ran (and sent: the round's count is theirs together)
    assert all((tmp_path / f"flood-0-{n}-{k}.log").read_text().startswith('{"sent": ')
               for n in (0, -5) for k in (0, 1))
    assert (tmp_path / "daemon-0-0.log").is_file()
