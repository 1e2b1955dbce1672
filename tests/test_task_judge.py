"""The readings a task's predicates compare (sctd.task.judge.readings_of)."""

from __future__ import annotations

from sctd.task.judge import readings_of
from sctd.task.model import AllOf, AnyOf, Compare, Near, Not


def test_readings_of_lists_each_compared_reading_once_in_order():
    either = AnyOf((Not(Compare("b.on", is_=True)), Compare("a.x", above=1.0)))
    p = AllOf((Compare("a.x", at_least=0.5), either, Near("hand", "a", 0.1), True))
    assert readings_of(p) == ["a.x", "b.on"]
    assert readings_of(Near("hand", "a", 0.1)) == [] and readings_of(False) == []
