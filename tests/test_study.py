"""``sctd study``'s pure parts: the balanced Latin square, the plan and its file, the
questionnaires' scoring and checks, and the statistics (known answers)."""

from __future__ import annotations

import itertools

import pytest
from hypothesis import given
from hypothesis import strategies as st

from sctd_services.study import (
    StudyError,
    check_answers,
    check_participant_id,
    describe,
    holm,
    make_plan,
    paired_test,
    plan_from_yaml,
    plan_to_yaml,
    raw_tlx,
    sus_score,
)
from sctd_services.study.latin import carryover_counts, williams_rows
from sctd_services.study.plan import Condition
from sctd_services.study.stats import rank_biserial

# ---------------------------------------------------------------- Latin square


@given(st.integers(1, 12))
def test_every_row_holds_every_condition_once(n):
    rows = williams_rows(n)
    assert len(rows) == (2 * n if n % 2 and n > 1 else n)
    for r in rows:
        assert sorted(r) == list(range(n))


@given(st.integers(1, 12))
def test_every_condition_takes_every_position_equally_often(n):
    rows = williams_rows(n)
    times = len(rows) // n
    for pos in range(n):
        column = [r[pos] for r in rows]
        assert sorted(column) == sorted(list(range(n)) * times)


@given(st.integers(2, 12))
def test_first_order_carryover_is_balanced(n):
    """Even n: each ordered pair adjacent once in one square; odd n: twice in the two."""
    counts = carryover_counts(williams_rows(n))
    want = 1 if n % 2 == 0 else 2
    assert counts == {(a, b): want for a, b in itertools.permutations(range(n), 2)}


def test_the_first_row_is_williams():
    assert williams_rows(4) == [[0, 1, 3, 2], [1, 2, 0, 3], [2, 3, 1, 0], [3, 0, 2, 1]]
    assert williams_rows(3)[:3] == [[0, 1, 2], [1, 2, 0], [2, 0, 1]]
    assert williams_rows(3)[3] == [2, 1, 0]


# ---------------------------------------------------------------- the plan

A, B, C = (Condition("a-vf", "skill", "assisted"), Condition("b-linear", "skill", "assisted"),
           Condition("teleop", "teleop", "baseline"))


def test_a_plan_counterbalances_and_pairs_the_seeds():
    plan = make_plan([A, C], ["t1", "t2"], participants=4, practice=1, trials=2, seed=10)
    assert [s.participant for s in plan.participants] == ["P01", "P02", "P03", "P04"]
    assert [s.order for s in plan.participants] == [("a-vf", "teleop"), ("teleop", "a-vf")] * 2
    assert not plan.warnings
    p1 = plan.participants[0]
    seeds = {(b.condition, b.task): (b.practice_seeds, b.seeds) for b in p1.blocks}
    assert seeds[("a-vf", "t1")] == seeds[("teleop", "t1")] == ((10,), (11, 12))
    assert seeds[("a-vf", "t2")] == ((13,), (14, 15))
    p2 = plan.participants[1]
    assert set(p2.blocks[0].seeds).isdisjoint(s for b in p1.blocks for s in b.seeds)
    steps = p1.steps()
    assert len(steps) == 2 * 2 * 3
    assert [(s.condition, s.task, s.practice, s.seed) for s in steps[:3]] == [
        ("a-vf", "t1", True, 10), ("a-vf", "t1", False, 11), ("a-vf", "t1", False, 12)]
    assert steps[6].order == 2 and steps[6].condition == "teleop"


def test_too_few_participants_for_the_square_is_said_in_the_file():
    plan = make_plan([A, B, C], ["t"], participants=4, practice=0, trials=1)
    assert len(plan.sequences) == 6  # three conditions: two squares
    assert "incomplete" in plan.warnings[0]
    text = plan_to_yaml(plan)
    assert "# WARNING: 4 participants for 6 sequences" in text
    assert "odd): two squares" in text
    assert "not a multiple" in make_plan([A, C], ["t"], participants=3, practice=0, trials=1).warnings[0]


def test_duplicate_conditions_and_bad_counts_are_refused():
    with pytest.raises(StudyError, match="--condition: a-vf is given twice"):
        make_plan([A, A], ["t"], 2, 1, 1)
    with pytest.raises(StudyError, match="--task: t is given twice"):
        make_plan([A, C], ["t", "t"], 2, 1, 1)
    with pytest.raises(StudyError, match="--trials: 0 is below 1"):
        make_plan([A, C], ["t"], 2, 1, 0)


def test_the_plan_file_reads_back_as_written():
    plan = make_plan([A, B, C], ["t1", "t2"], participants=7, practice=2, trials=3, seed=5, title="pilot")
    text = plan_to_yaml(plan)
    assert text.startswith("# sctd study plan: pilot\n")
    assert "Hart & Staveland 1988" in text and "Brooke 1996" in text and "Williams 1949" in text
    assert plan_from_yaml(text, "plan.yaml") == plan


def test_a_plan_file_with_a_name_for_an_id_is_refused():
    text = plan_to_yaml(make_plan([A, C], ["t"], 2, 1, 1)).replace("id: P02", "id: Jane Doe")
    with pytest.raises(StudyError, match=r"plan.yaml: participants\[1\].id: .*looks like a person's name"):
        plan_from_yaml(text, "plan.yaml")
    bad = plan_to_yaml(make_plan([A, C], ["t"], 2, 1, 1)).replace("task: t\n", "task: nope\n", 1)
    with pytest.raises(StudyError, match=r"blocks\[0\].task: 'nope' is not one of the plan's tasks"):
        plan_from_yaml(bad, "plan.yaml")


# ---------------------------------------------------------------- questionnaires

WHO = "participant P01, condition a-vf, task t"
TLX = {"mental": 20, "physical": 10, "temporal": 35, "performance": 15, "effort": 40, "frustration": 0}


def test_raw_tlx_is_the_mean_of_the_six():
    assert raw_tlx(TLX) == pytest.approx(120 / 6)
    assert raw_tlx(dict.fromkeys(TLX, 100)) == 100.0


@pytest.mark.parametrize("ratings, score", [
    ([5, 1, 5, 1, 5, 1, 5, 1, 5, 1], 100.0),  # the best answer to every item
    ([1, 5, 1, 5, 1, 5, 1, 5, 1, 5], 0.0),
    ([3] * 10, 50.0),
    # contributions 3+3+2+2+2+2+2+2+2+2 = 22, times 2.5 = 55: the total of Brooke's (1996)
    # scoring example (22 -> 55); these item ratings are ours
    ([4, 2, 3, 3, 3, 3, 3, 3, 3, 3], 55.0),
    ([4, 2, 4, 1, 3, 2, 4, 2, 3, 2], 72.5),
])
def test_sus_scores_as_brooke_scores(ratings, score):
    assert sus_score(ratings) == score
    assert sus_score({str(i + 1): r for i, r in enumerate(ratings)}) == score


@pytest.mark.parametrize("answers, message", [
    ({"nasa_tlx": {**TLX, "effort": 105}, "sus": [3] * 10}, "nasa_tlx.effort: 105 is out of range (0-100)"),
    ({"nasa_tlx": {**TLX, "mental": 52}, "sus": [3] * 10},
     "nasa_tlx.mental: 52 is not on the scale's steps of 5"),
    ({"nasa_tlx": {k: v for k, v in TLX.items() if k != "temporal"}, "sus": [3] * 10},
     "nasa_tlx.temporal: missing"),
    ({"nasa_tlx": {**TLX, "fun": 5}, "sus": [3] * 10}, "nasa_tlx.fun: no such subscale"),
    ({"nasa_tlx": TLX, "sus": [3, 3, 6, 3, 3, 3, 3, 3, 3, 3]}, "sus.3: 6 is out of range (1-5)"),
    ({"nasa_tlx": TLX, "sus": [3] * 9}, "sus.10: missing"),
    ({"nasa_tlx": TLX, "sus": [3] * 4 + [True] + [3] * 5}, "sus.5: True is not a whole number"),
    ({"nasa_tlx": TLX}, "sus: missing"),
])
def test_a_bad_answer_names_participant_condition_item_and_value(answers, message):
    with pytest.raises(StudyError) as e:
        check_answers(answers, WHO)
    assert str(e.value).startswith(WHO + ": ")
    assert message in str(e.value)


def test_check_answers_scores():
    out = check_answers({"nasa_tlx": TLX, "sus": [4, 2, 4, 1, 3, 2, 4, 2, 3, 2]}, WHO)
    assert out["raw_tlx"] == pytest.approx(20.0) and out["sus_score"] == 72.5


@pytest.mark.parametrize("pid, why", [
    ("jane.doe@example.org", "e-mail"), ("+49 151 23456789", "phone"), ("0151-2345678", "phone"),
    ("Jane Doe", "name"), ("jane_doe", "name"), ("P-01!", "not a pseudonym"), ("", "not a pseudonym"),
])
def test_ids_that_look_like_a_person_are_refused(pid, why):
    with pytest.raises(StudyError, match=why):
        check_participant_id(pid)


def test_pseudonyms_pass():
    for pid in ("P01", "P001", "S12", "PT003"):
        assert check_participant_id(pid) == pid


# ---------------------------------------------------------------- statistics


def test_holm_known_answer():
    """m = 4: sorted 0.005, 0.01, 0.03, 0.04 times 4, 3, 2, 1 = 0.02, 0.03, 0.06, 0.04;
    the running maximum makes the last 0.06."""
    assert holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    adjusted = holm([0.2, None, 0.01])  # None is not in the family: m = 2
    assert adjusted[1] is None and adjusted == [pytest.approx(0.2), None, pytest.approx(0.02)]
    assert holm([0.6, 0.7]) == pytest.approx([1.0, 1.0])  # capped at 1, non-decreasing
    assert holm([]) == []


def test_rank_biserial_known_answer():
    """Ranks of |d| = 1, 2, 3, 4; T+ = 1 + 3 + 4 = 8, T- = 2: r = 6 / 10."""
    assert rank_biserial([1.0, -2.0, 3.0, 4.0]) == pytest.approx(0.6)
    assert rank_biserial([0.0, 0.0]) is None


def test_wilcoxon_on_eight_pairs_all_one_way():
    """Eight distinct positive differences: the exact two-sided p is 2 / 2**8."""
    b = [10.0, 12.0, 9.0, 14.0, 11.0, 13.0, 10.5, 12.5]
    a = [x + d for x, d in zip(b, [0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0], strict=True)]
    r = paired_test(a, b)
    assert r["n"] == 8 and r["n_differing"] == 8
    assert r["p"] == pytest.approx(2 / 2**8)
    assert r["statistic"] == 0.0 and r["r_rank_biserial"] == 1.0 and r["note"] == ""
    assert paired_test(b, a)["r_rank_biserial"] == -1.0


def test_too_few_pairs_say_so_instead_of_failing():
    assert paired_test([1.0], [2.0])["note"].startswith("not possible: 1 participant")
    assert paired_test([1.0, None, 3.0], [2.0, 5.0, None])["note"].startswith("not possible")
    same = paired_test([1.0, 2.0, 3.0], [1.0, 2.0, 3.0])
    assert same["p"] is None and "no participant differs" in same["note"]
    small = paired_test([1.0, 2.0, 3.0], [2.0, 4.0, 6.0])
    assert small["p"] == pytest.approx(0.25)
    assert small["note"].startswith("underpowered: with 3 differing pairs the smallest possible p is 0.25")


def test_describe():
    d = describe([1.0, 2.0, 3.0, 4.0, None])
    assert d["n"] == 4 and d["median"] == 2.5 and d["q1"] == 1.75 and d["q3"] == 3.25
    assert describe([None])["median"] is None and describe([2.0])["sd"] is None
