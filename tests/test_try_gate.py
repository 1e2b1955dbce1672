"""The browser page as an input device (:mod:`sctd_services.input.page`), in-process:
what the gate publishes for each reading, and what it refuses, rejects and counts. The
page itself, its socket and ``sctd try`` are tested in ``tests/test_try_browser.py``."""

from __future__ import annotations

import math

import pytest

from sctd.wire import codec
from sctd_services.input.page import PageGate, check_reading

RB = [0] * 5 + [1]  # the standard pad's right shoulder held: the deadman
FORWARD = [0.0, -1.0, 0.0, 0.0]  # the left stick pushed forward (its y is down +)


@pytest.fixture
def gate():
    out: list[codec.InputMsg] = []
    g = PageGate(lambda payload: out.append(codec.decode_input(payload)))
    g.out = out
    assert g.connect(1) == "controller"
    g.set_open(True)
    return g


def pad(seq, axes=FORWARD, buttons=RB):
    return {"type": "input", "seq": seq, "source": "gamepad", "axes": axes, "buttons": buttons}


def test_a_pad_reading_is_mapped_and_published_once(gate):
    assert gate.reading(1, pad(1)) is None
    (msg,) = gate.out
    assert msg.u == (0.0, 1.0, 0.0) and msg.buttons == (0, 1, 0, 0, 0) and not msg.stop
    assert gate.reading(1, pad(2, buttons=[])) is None  # the deadman released: zero, whatever the stick
    assert gate.out[-1].u == (0.0, 0.0, 0.0) and gate.out[-1].buttons[1] == 0
    assert [m.seq for m in gate.out] == [1, 2]  # nothing published on its own, nothing repeated


@pytest.mark.parametrize(("axes", "why"), [
    ([math.nan, 0.0, 0.0], "nonfinite"), ([math.inf, 0.0, 0.0], "nonfinite"), ([0.0, 1e9, 0.0], "range"),
    ([0.0, -1.01, 0.0], "range"), ("up", "type"), ([True, 0.0, 0.0], "type"), ([], "type"),
    ([None, 0.0, 0.0], "type"), ([0.0] * 9, "type")])
def test_bad_values_are_rejected_counted_and_stop_the_arm(gate, axes, why):
    gate.reading(1, pad(1))
    assert gate.reading(1, pad(2, axes=axes)) == f"rejected:{why}"
    assert gate.counts[f"rejected:{why}"] == 1
    assert gate.out[-1].u == (0.0, 0.0, 0.0) and gate.out[-1].buttons[1] == 0


def test_wrong_types_and_old_samples(gate):
    assert check_reading([1, 2], -1) == "type"
    assert check_reading({**pad(1), "seq": "1"}, -1) == "type"
    assert check_reading({**pad(1), "source": "joystick"}, -1) == "type"
    assert check_reading({**pad(1), "buttons": [2]}, -1) == "type"
    gate.reading(1, pad(5))
    assert gate.reading(1, pad(5)) == "rejected:old" and gate.reading(1, pad(4)) == "rejected:old"
    gate.garbage(1)
    assert gate.counts["rejected:type"] == 1


def test_a_value_that_rounds_past_one_is_clipped(gate):
    assert gate.reading(1, pad(1, axes=[0.0, -1.0000000001, 0.0, 0.0])) is None
    assert gate.out[-1].u[1] == 1.0


def test_a_second_page_is_an_observer(gate):
    assert gate.connect(2) == "observer"
    assert gate.reading(2, pad(1)) == "refused:observer"
    assert gate.counts["refused:observer"] == 1 and not gate.out


@pytest.mark.parametrize("why", ["hidden", "blur"])
def test_a_hidden_or_unfocused_page_stops_until_it_is_back(gate, why):
    gate.reading(1, pad(1))
    gate.pause(1, why)
    assert gate.out[-1].u == (0.0, 0.0, 0.0) and gate.out[-1].buttons[1] == 0
    assert gate.counts[f"stale:{why}"] == 1
    assert gate.reading(1, pad(2)) == "refused:paused"
    gate.resume(1)
    assert gate.reading(1, pad(3)) is None and gate.out[-1].u[1] == 1.0


def test_a_closed_socket_stops_the_arm_and_frees_the_controller(gate):
    gate.reading(1, pad(1))
    gate.disconnect(1)
    assert gate.out[-1].u == (0.0, 0.0, 0.0) and gate.counts["stale:closed"] == 1
    assert gate.connect(3) == "controller"
    assert gate.reading(3, pad(1)) is None  # a new page counts its own seq


def test_no_trial_no_input(gate):
    gate.set_open(False)
    assert gate.out[-1].buttons[1] == 0 and gate.counts["stale:trial over"] == 1
    assert gate.reading(1, pad(1)) == "refused:closed"


def test_the_keyboard_and_the_stick_have_their_deadman():
    out: list[bytes] = []
    g = PageGate(out.append)
    g.connect(1)
    g.set_open(True)
    g.reading(1, {"seq": 1, "source": "keyboard", "axes": [1, 0, -1], "buttons": [0, 1]})
    assert codec.decode_input(out[-1]).u == (1.0, 0.0, -1.0)
    g.reading(1, {"seq": 2, "source": "touch", "axes": [0.5, 0.5, 0], "buttons": [1, 0, 0, 0, 0, 0]})
    assert codec.decode_input(out[-1]).u == (0.0, 0.0, 0.0) and codec.decode_input(out[-1]).buttons[0] == 1
