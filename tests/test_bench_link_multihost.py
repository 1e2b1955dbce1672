"""``sctd bench link`` end to end, one tiny point of its sweep: one real-time trial of the
default task's skill through the namespaced cluster with a 2 s stall on the input link
(``docs/multihost.md``). The trial's verdict is the simulated user's and the machine's;
what is asserted is that the bench ran it as the point says and judged it: the proxy
began the stall during the trial, the judge reported an outcome and the hand's
unintended motion, and the table has its row; nothing of the cluster is left.
Needs root; skips without it, except under CI."""

from __future__ import annotations

import math

import pytest

from sctd.app.defaults import defaults
from sctd.bench.link import run_link_bench, select_points
from sctd.deploy.netns import namespaces
from sctd.task import find_task
from tests.conftest import require_namespaces

pytestmark = [pytest.mark.slow, pytest.mark.realtime]  # namespaces, processes, a real-time trial


def test_one_point_of_the_sweep_runs_a_trial_with_its_fault_and_judges_it(tmp_path):
    require_namespaces()
    before = set(namespaces())
    r = run_link_bench([find_task(defaults().task)], None, select_points("input-stall-2"), trials=1, seed=0,
                       logdir=tmp_path, baseline=False)
    assert set(namespaces()) <= before, "the cluster's namespaces were left"
    (trial,) = r["trials"]
    assert trial["point"] == "input-stall-2" and trial["condition"] == "assisted", trial
    assert trial["stalls"] == 1, trial  # the proxy's count: the stall began while the trial ran
    assert trial["outcome"] in ("success", "failure", "stuck"), trial
    assert math.isfinite(trial["wander_m"]) and trial["wander_m"] >= 0.0, trial
    (row,) = r["rows"]
    assert (row["point"], row["trials"], row["successes"]) == \
        ("input-stall-2", 1, int(trial["outcome"] == "success")), row
