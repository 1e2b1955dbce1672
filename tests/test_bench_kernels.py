"""``sctd bench kernels``: the same suite trials with the CPU's BLAS kernels and with
Haswell's, compared trial for trial."""

import json
from pathlib import Path

import pytest

from sctd.bench.kernels import compare

from .conftest import run_sctd


def _suite(outcomes, times):
    per = [{"seed": k, "outcome": o, "time_s": t}
           for k, (o, t) in enumerate(zip(outcomes, times, strict=True))]
    result = {"skill": "skills/drawer-vf.yaml", "name": "drawer-vf", "per_trial": per}
    return {"results": {"drawer": [result]}}


def test_compare_names_each_trial_whose_outcome_differs_and_how_far_times_moved():
    own = _suite(["success", "success", "stuck"], [4.0, 5.0, None])
    forced = _suite(["success", "stuck", "stuck"], [4.25, None, None])
    (row,) = compare(own, forced)
    assert row["flips"] == [{"seed": 1, "own": "success", "forced": "stuck"}]
    assert row["max_time_change_s"] == 0.25 and row["trials"] == 3
    with pytest.raises(ValueError, match="ran with one set of kernels only"):
        compare(own, {"results": {"drawer": []}})


@pytest.mark.slow
@pytest.mark.timeout(900)  # two sctd suite runs: 300 s, the default, on a machine at load 8-20
def test_the_drawers_outcomes_are_the_same_with_haswells_kernels():
    """The forced run's OpenBLAS reports the kernels it was told to use; the drawer's
    skills and baselines come out the same, trial for trial."""
    run = run_sctd("bench", "kernels", "--task", "drawer", "--trials", "2", "--jobs", "2", "--json",
                   timeout=900)
    assert run.returncode == 0, run.stderr
    doc = json.loads(run.stdout)
    forced = doc["numerics"]["forced"]
    assert forced["openblas_coretype"] == "Haswell" and any("Haswell" in b for b in forced["blas"]), forced
    assert doc["numerics"]["own"]["openblas_coretype"] is None
    assert len(doc["rows"]) == 4 and all(r["trials"] == 2 for r in doc["rows"]) and doc["flips"] == 0
    # the task's two skills in the suite's order, and the baseline of each one's limits
    assert [r["skill"] for r in doc["rows"] if not r["baseline_of"]] == ["drawer-vf", "drawer"], doc["rows"]
    assert sorted(Path(r["baseline_of"]).stem for r in doc["rows"] if r["baseline_of"]) == \
        ["drawer", "drawer-vf"], doc["rows"]
