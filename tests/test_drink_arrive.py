"""The learned drink from starts twice as wide as its task's ``vary``: the cup comes to
the lips upright and tilts about its rim there (``arrive`` on its mapping,
docs/skill-format.md). Known answer: wide seeds 3 and 4 spilled with the skill as
learned without it (docs/evaluation.md, "Starts the demonstrations did not cover");
with it they are drunk, under either CPU's kernels."""

from __future__ import annotations

from dataclasses import replace

import pytest

from sctd.skill import load_skill
from sctd.skill.catalog import shipped_folder
from sctd.task import find_task
from sctd_services.eval.lockstep import run_trial
from sctd_services.eval.starts import starts_task
from sctd_services.eval.trial import TaskSpec
from tests.tiers import needs

SEEDS = (3, 4)


def drink_trial(skill, seed: int):
    """One lockstep trial of ``skill`` on the drink from wide start ``seed`` (the plain
    user, the task's time limit)."""
    task, _ = starts_task(find_task("drink"), "wide", seed)
    spec = TaskSpec.of(task, "drink", starts="wide")
    return run_trial(skill, spec, seed, task=task)


@pytest.fixture(scope="module")
def skills():
    needs("pinocchio")
    shipped = load_skill(shipped_folder() / "drink-vf.yaml")
    (state,) = shipped.states
    (mapping,) = state.input_mappings
    assert mapping.arrive == 0.01
    without = replace(shipped, states=(replace(state, input_mappings=(replace(mapping, arrive=0.0),)),))
    return shipped, without


@pytest.mark.slow
def test_the_drink_from_wide_starts_is_drunk_with_arrive_and_not_without(skills):
    shipped, without = skills
    for seed in SEEDS:
        r = drink_trial(shipped, seed)
        assert (r.outcome, r.reason) == ("success", "drunk"), (seed, r.outcome, r.reason)
        assert r.readings["cup.spilled"] == 0.0 and r.readings["face.max_force"] < 5.0
    failed = [(s, r.reason) for s in SEEDS if (r := drink_trial(without, s)).outcome != "success"]
    assert failed == [(s, "spilled") for s in SEEDS], failed  # the cup tilted before the rim was there
