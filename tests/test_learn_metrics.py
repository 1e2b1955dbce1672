"""Scores against known phases (sctd.learn.metrics): known answers, state numbering that
does not matter, and refusals that name the demonstration."""

from __future__ import annotations

import re

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sctd.learn import field_kinds_by_phase, segmentation_accuracy

TRUTH = {"a": [0, 0, 0, 1, 1], "b": [0, 0, 1, 1, 1]}


def test_a_perfect_segmentation_scores_one_whatever_the_state_numbers():
    learned = {"a": [7, 7, 7, 3, 3], "b": [7, 7, 3, 3, 3]}
    assert segmentation_accuracy(learned, TRUTH) == (1.0, {"a": 1.0, "b": 1.0})


def test_each_state_stands_for_the_phase_most_of_its_displacements_have():
    # State 0 covers four phase-0 displacements and one phase-1: it stands for phase 0,
    # and that phase-1 displacement is the one wrong of ten.
    learned = {"a": [0, 0, 0, 0, 1], "b": [0, 0, 1, 1, 1]}
    acc, per_demo = segmentation_accuracy(learned, TRUTH)
    assert acc == pytest.approx(0.9)
    assert per_demo == {"a": pytest.approx(0.8), "b": 1.0}


def test_a_tie_takes_the_smaller_phase():
    acc, _ = segmentation_accuracy({"a": [5, 5]}, {"a": [1, 0]})
    assert acc == 0.5


def test_one_state_for_everything_scores_the_largest_phase_share():
    learned = {k: [0] * len(v) for k, v in TRUTH.items()}
    acc, per_demo = segmentation_accuracy(learned, TRUTH)
    assert acc == pytest.approx(5 / 10) and per_demo == {"a": pytest.approx(3 / 5),
                                                        "b": pytest.approx(2 / 5)}


def test_only_the_demonstrations_with_true_labels_are_scored():
    learned = {"a": [1, 1, 1, 0, 0], "b": [0, 0, 0, 0, 0], "extra": [4, 4]}
    acc, per_demo = segmentation_accuracy(learned, {"a": TRUTH["a"]})
    assert acc == 1.0 and set(per_demo) == {"a"}


@pytest.mark.parametrize("learned, truth, said", [
    ({"a": [0, 0, 0, 1, 1]}, TRUTH, "no demonstration 'b'"),
    ({"a": [0, 0, 0, 1], "b": [0, 0, 1, 1, 1]}, TRUTH, "labels['a']: shape (4,), its true labels (5,)"),
    ({}, {}, "no demonstrations"),
    ({"a": []}, {"a": []}, "no displacements"),
])
def test_labels_that_do_not_match_the_truth_are_refused(learned, truth, said):
    with pytest.raises(ValueError, match=re.escape(said)):
        segmentation_accuracy(learned, truth)


@given(st.lists(st.integers(0, 3), min_size=1, max_size=40), st.permutations(range(4)),
       st.integers(0, 2**32 - 1))
def test_renumbering_states_keeps_the_score(truth, perm, seed):
    """A one-to-one renumbering of the learned states changes nothing; the score is a
    share, and labels equal to the truth score one."""
    rng = np.random.default_rng(seed)
    learned = rng.integers(0, 4, len(truth))
    acc, _ = segmentation_accuracy({"d": learned}, {"d": truth})
    renumbered = np.asarray(perm)[learned]
    assert segmentation_accuracy({"d": renumbered}, {"d": truth})[0] == acc
    assert 0.0 <= acc <= 1.0
    assert segmentation_accuracy({"d": truth}, {"d": truth})[0] == 1.0


def test_field_kinds_by_phase_votes_and_skips_outliers():
    kinds = ["translation", "sphere", "cylinder"]
    # phase 0: translation 4 votes, sphere 1; phase 1: sphere 3, cylinder 2 (outliers
    # -1 do not vote); phase 2: outliers only.
    fields = {"a": [0, 0, 1, 1, 2, -1, -1], "b": [0, 0, 1, 2, -1, -1]}
    truth = {"a": [0, 0, 0, 1, 1, 1, 2], "b": [0, 0, 1, 1, 1, 2]}
    assert field_kinds_by_phase(fields, kinds, truth) == ("translation", "sphere", None)
    assert field_kinds_by_phase(fields, kinds, truth, n_phases=4) == ("translation", "sphere", None, None)


def test_field_kinds_by_phase_tie_goes_to_the_first_kind_counted():
    kinds = ["sphere", "cylinder"]
    assert field_kinds_by_phase({"a": [1, 0]}, kinds, {"a": [0, 0]}) == ("cylinder",)
    assert field_kinds_by_phase({"a": [0, 1]}, kinds, {"a": [0, 0]}) == ("sphere",)


def test_field_kinds_by_phase_refuses_labels_of_another_length():
    with pytest.raises(ValueError, match="labels\\['a'\\]"):
        field_kinds_by_phase({"a": [0, 0]}, ["translation"], {"a": [0, 0, 0]})
