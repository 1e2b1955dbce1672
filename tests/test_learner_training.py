"""The learner trains in a child process with a memory cap, a time limit and a lower
priority (services/learner/training.py): a request cannot take the machine from the
daemon beside it."""

from __future__ import annotations

import os
import resource

import pytest

from sctd.learn import STAGES
from sctd.learn.demos import read_demos
from sctd_services.learner.training import Trainer, TrainingError, TrainingLimits
from tests.conftest import ROOT

pytestmark = pytest.mark.slow  # spawns the training worker

DEMOS = ROOT / "skills" / "demos" / "pour"


def _limits_in_worker() -> tuple[int, int]:
    return resource.getrlimit(resource.RLIMIT_AS)[0], os.nice(0)


def test_the_worker_runs_capped_and_below_the_learner():
    limits = TrainingLimits(memory=3 * 1024**3, nice=7)
    with Trainer(limits) as t:
        cap, nice = t._start().submit(_limits_in_worker).result(timeout=60)
    assert cap == 3 * 1024**3 and nice == os.nice(0) + 7


def test_a_training_trains_and_passes_its_stages_back():
    stages: list[str] = []
    with Trainer() as t:
        result = t.train(read_demos(DEMOS), "vf", None, {"object": "mug"}, stages.append)
    assert result.learner.fields_  # it learned its fields
    assert stages == list(STAGES["vf"])  # every stage, as it ended, in order


def test_a_training_past_its_time_limit_is_stopped_and_the_next_one_runs():
    demos = read_demos(DEMOS)
    with Trainer(TrainingLimits(timeout=0.3)) as t:
        with pytest.raises(TrainingError, match=r"longer than 0\.3 s"):
            t.train(demos, "vf", None, {"object": "mug", "n_fields": 10, "em_iterations": 100})
        assert t._pool is None  # the worker was killed
    with Trainer() as t:
        assert t.train(demos, "linear", None, {"object": "mug"}).labels


def test_a_hyperparameter_error_comes_back_as_itself():
    from sctd.learn import HyperparameterError

    with Trainer() as t, pytest.raises(HyperparameterError, match="em_iterations"):
        t.train(read_demos(DEMOS), "vf", None, {"em_iterations": 10**9})


def _init_then_report(init, args, out):
    init(*args)
    out.put("ran")


def test_a_pool_worker_whose_learner_is_already_gone_ends_at_once():
    """Killed while its pools start, a learner sends its workers no death signal (it was
    not set yet): a worker that finds itself an orphan ends in its initializer."""
    import multiprocessing

    from sctd_services.learner import check, training

    ctx = multiprocessing.get_context("spawn")
    out = ctx.SimpleQueue()
    for init, args in ((check._die_with_parent, (os.getpid(),)),
                       (training._worker_init, (os.getpid(), 2 << 30, 0, out))):
        p = ctx.Process(target=_init_then_report, args=(init, args, out))
        p.start()
        p.join(60)
        assert p.exitcode == 0 and out.get() == "ran"  # its parent is alive: it goes on
    for init, args in ((check._die_with_parent, (1,)), (training._worker_init, (1, 2 << 30, 0, out))):
        p = ctx.Process(target=_init_then_report, args=(init, args, out))
        p.start()
        p.join(60)
        assert p.exitcode == 0 and out.empty()  # "parent" 1 is not its parent: it ended


def test_the_workers_start_before_the_first_request():
    """The training worker and the check's trial processes start (and import) when asked
    to be warm, not when the first training or trial arrives."""
    import multiprocessing

    from sctd_services.learner.check import trial_pool

    before = set(multiprocessing.active_children())
    with Trainer() as t:
        t.warm()
        assert len(set(multiprocessing.active_children()) - before) == 1
    pool = trial_pool(2)
    try:
        assert len(set(multiprocessing.active_children()) - before) == 2
    finally:
        pool.shutdown()
