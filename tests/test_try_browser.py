"""``sctd try`` in a real headless Chromium (:mod:`tests.browser`): the page's safety
rules, and trials driven to success by the simulated user through the page's gamepad
(the Gamepad API stubbed in the page) and its keyboard.

What is asserted is what the programs report: the page's state (the gate's counters, the
daemon's status it relays), the input and target messages on the wire (their senders'
stamps), the trial's JSON and MCAP; never the test's own clock.
"""

from __future__ import annotations

import json
import re
import threading
from pathlib import Path

import numpy as np
import pytest

from sctd.task import find_task
from sctd.wire import Keys, codec
from sctd.wire.session import session
from tests.browser import drive_as_user, keyboard_injector, open_page
from tests.conftest import sctd, wait_for

# realtime, every test: the stops are judged against the 0.1 s input timeout and "nothing
# moves" against the daemon's targets, and with the other worker's tests beside them on two
# cores a zero reached the daemon late (a target 0.04 mm on, after the timeout by the
# gate's stamp) or the page's status lagged; the realtime tier runs them one at a time
pytestmark = [pytest.mark.slow, pytest.mark.realtime, pytest.mark.timeout(600)]

INPUT_TIMEOUT = 0.1  # s: the daemon's default (sctd run --input-timeout)
DEADBAND = 0.12  # the browser pad map's sticks
RB, A, B = 5, 0, 1  # the standard mapping's buttons: deadman, mode, escape
SET_PAD = """([axes, pressed]) => {
  window.__pad = {id: "test pad", connected: true, mapping: "standard", axes,
                  buttons: pressed.map((p) => ({pressed: !!p, value: p ? 1 : 0}))};
  Object.defineProperty(navigator, "getGamepads", {value: () => [window.__pad], configurable: true});
}"""


def buttons(*held: int) -> list[int]:
    return [1 if k in held else 0 for k in range(17)]


@pytest.fixture(scope="module")
def tried(tmp_path_factory):
    """``sctd try --no-view`` and its URL, Zenoh endpoint and output folder."""
    tmp = tmp_path_factory.mktemp("try")
    proc = sctd("try", "--no-view", "--out", str(tmp / "out"), log=tmp / "try.log")
    try:
        line = wait_for(lambda: re.search(r"open (http://\S+) \(Zenoh (\S+)\)", proc.output()), 60.0)
        assert line, proc.output()
        yield line.group(1), line.group(2), tmp / "out", proc
    finally:
        assert proc.stop() == 0, proc.output()


@pytest.fixture(scope="module")
def browser(tried):
    with open_page(tried[0]) as bp:
        yield bp


class Wire:
    """The input the page's gate publishes and the daemon's targets, as they arrive."""

    def __init__(self, s):
        k = Keys()
        self.inputs: list[tuple[float, int, tuple]] = []  # (stamp, enable, u)
        self.targets: list[tuple[float, tuple]] = []  # (stamp, pose)
        self.lock = threading.Lock()
        self.subs = [s.declare_subscriber(k.input("browser"), self._input),
                     s.declare_subscriber(k.target, self._target)]

    def _input(self, sample):
        m = codec.decode_input(sample.payload.to_bytes())
        with self.lock:
            self.inputs.append((m.stamp, m.buttons[1] if m.buttons else 1, m.u))

    def _target(self, sample):
        m = codec.decode_target(sample.payload.to_bytes())
        with self.lock:
            self.targets.append((m["stamp"], tuple(m["pose"])))

    def close(self):
        for sub in self.subs:
            sub.undeclare()


def state(page):
    return page.evaluate("window.sctdState")


def start_trial(page, task, condition):
    page.evaluate("() => window.sctdState && window.sctdState.trial.phase === 'running' && "
                  "window.sctdSocket.send(JSON.stringify({type: 'abort'}))")
    page.wait_for_function("window.sctdState && window.sctdState.trial.phase !== 'running'")
    page.select_option("#task", task)
    page.select_option("#condition", condition)
    page.click("#start")
    page.wait_for_function("window.sctdState.trial.phase === 'running'", timeout=150_000)


def push_until_moving(page):
    """The pad pushed forward with the deadman held, until the daemon reports the
    browser owns the motion and runs."""
    page.evaluate(SET_PAD, [[0.0, -1.0, 0.0, 0.0], buttons(RB)])
    page.wait_for_function("window.sctdState.status.mode === 'running' && "
                           "window.sctdState.status.owner === 'browser'", timeout=30_000)


def assert_stops(wire, what):
    """After the gate's first zero with the deadman released, no target published more
    than the input timeout later differs from the one before it (the daemon's stamps)."""
    wait_for(lambda: len(wire.targets) > 0 and wire.targets[-1][0] > _zero_at(wire) + 3 * INPUT_TIMEOUT, 10.0)
    t0 = _zero_at(wire)
    with wire.lock:
        after = [p for t, p in wire.targets if t > t0 + INPUT_TIMEOUT]
        before = [p for t, p in wire.targets if t <= t0]
    assert after, f"{what}: no target after the stop"
    assert np.ptp(np.array(after)[:, :3], axis=0).max() < 1e-9, f"{what}: the target still moved"
    assert np.abs(np.array(before[-1][:3]) - np.array(before[0][:3])).max() > 1e-3, \
        f"{what}: the arm did not move before the stop"


def _zero_at(wire) -> float:
    with wire.lock:
        moving = max((t for t, enable, u in wire.inputs if enable and any(u)), default=None)
        zeros = [t for t, enable, _ in wire.inputs if not enable and moving is not None and t > moving]
    return zeros[0] if zeros else float("inf")


@pytest.mark.parametrize("how", ["release", "hide", "blur", "close"])
def test_the_arm_stops_within_the_input_timeout(tried, browser, how):
    page = browser.page
    if how == "close":  # a fresh connection: the page that drives is the one reloaded
        page.reload()
    page.wait_for_function("window.sctdState && window.sctdState.role === 'controller'")
    start_trial(page, "drawer", "teleop")
    with session(connect=[tried[1]]) as s:
        wire = Wire(s)
        try:
            push_until_moving(page)
            wait_for(lambda: len(wire.targets) > 200, 10.0)
            before = state(page)["gate"]["counts"]
            if how == "release":
                page.evaluate(SET_PAD, [[0.0, -1.0, 0.0, 0.0], buttons()])
            elif how == "hide":
                page.evaluate("() => { Object.defineProperty(document, 'visibilityState', "
                              "{value: 'hidden', configurable: true}); "
                              "document.dispatchEvent(new Event('visibilitychange')); }")
            elif how == "blur":
                page.evaluate("() => window.dispatchEvent(new Event('blur'))")
            else:
                page.evaluate("() => window.sctdSocket.close()")
            assert_stops(wire, how)
        finally:
            wire.close()
    if how == "close":
        page.reload()
        page.wait_for_function("window.sctdState && window.sctdState.role === 'controller'")
        assert state(page)["gate"]["counts"]["stale:closed"] >= 1
        return
    try:
        # the daemon goes from hold (zero input) to stopped (stale input) once the watchdog
        # trips; the page shows its status as the daemon publishes it: wait for it
        page.wait_for_function("window.sctdState.status.mode === 'stopped'", timeout=30_000)
        after = state(page)
        if how in ("hide", "blur"):
            why = "hidden" if how == "hide" else how
            assert after["gate"]["counts"][f"stale:{why}"] == before.get(f"stale:{why}", 0) + 1
            assert after["gate"]["paused"] == why
    finally:  # the page back as the next test expects it, whatever came of this one
        if how in ("hide", "blur"):
            page.evaluate("() => { delete document.visibilityState; "
                          "window.dispatchEvent(new Event('focus')); }")
            page.wait_for_function("window.sctdState.gate.paused === null")
        page.evaluate(SET_PAD, [[0.0, 0.0, 0.0, 0.0], buttons()])


def test_a_second_page_is_an_observer(tried, browser):
    browser.page.wait_for_function("window.sctdState && window.sctdState.role === 'controller'")
    second = browser.page.context.new_page()
    try:
        second.goto(tried[0])
        second.wait_for_function("window.sctdState && window.sctdState.role === 'observer'")
        assert "observer" in second.inner_text("#role")
        second.wait_for_function("(window.sctdState.gate.counts['refused:observer'] || 0) > 5")
        second.click("#start")
        second.wait_for_function("window.sctdRefused.length > 0")
        assert "observer" in second.evaluate("window.sctdRefused[0]")
    finally:
        second.close()
    assert state(browser.page)["role"] == "controller"


def test_bad_input_is_rejected_counted_and_nothing_moves(tried, browser):
    page = browser.page
    page.wait_for_function("window.sctdState && window.sctdState.role === 'controller'")
    start_trial(page, "drawer", "teleop")
    with session(connect=[tried[1]]) as s:
        wire = Wire(s)
        try:
            page.evaluate("""() => {
              const send = (text) => window.sctdSocket.send(text);
              const big = 1e9;
              send('{"type":"input","seq":1000000,"source":"gamepad","axes":[NaN,-1,0,0],"buttons":[0,0,0,0,0,1]}');
              send(JSON.stringify({type: "input", seq: 1000001, source: "gamepad", axes: [0, -big, 0, 0],
                                   buttons: [0, 0, 0, 0, 0, 1]}));
              send(JSON.stringify({type: "input", seq: "x", source: "gamepad", axes: "up", buttons: [1]}));
              send("not json");
            }""")
            page.wait_for_function("(c => (c['rejected:nonfinite'] || 0) >= 1 && "
                                   "(c['rejected:range'] || 0) >= 1 && "
                                   "(c['rejected:type'] || 0) >= 2)(window.sctdState.gate.counts)")
            wait_for(lambda: len(wire.targets) > 300, 10.0)
            with wire.lock:
                poses = np.array([p for _, p in wire.targets])
                moved = [u for _, enable, u in wire.inputs if enable and any(u)]
            assert not moved and np.ptp(poses[:, :3], axis=0).max() < 1e-4  # (0.1 mm: a push moves cm)
            assert state(page)["status"]["mode"] == "stopped"
        finally:
            wire.close()


def _pad_axis(u: float) -> float:
    """The stick deflection that the pad map's dead band turns into ``u``."""
    return 0.0 if u == 0 else float(np.sign(u) * (abs(u) * (1 - DEADBAND) + DEADBAND))


def _drive(tried, page, task_name, condition, inject) -> dict:
    """A trial of ``condition`` on ``task_name`` driven by the simulated user through
    ``inject`` (:func:`tests.browser.drive_as_user`); the page's result."""
    start_trial(page, task_name, condition)
    drive_as_user(tried[1], find_task(task_name), state(page)["trial"]["seed"], inject,
                  lambda: state(page)["result"] is not None)
    return state(page)["result"]


def _failed(result) -> str:
    """What a trial that did not succeed reports, with the share of real time its
    simulator kept: below about 0.9 the machine could not run the simulator, the daemon,
    the browser and the person at full rate (docs/evaluation.md), which shows here as a
    person who steers late."""
    entry = json.loads((Path(result["folder"]) / "trial.json").read_text())
    keep = ("outcome", "reason", "duration_s", "sim_rtf", "phase_s", "mode_switches", "readings")
    return json.dumps({k: entry.get(k) for k in keep})


def _assert_recorded(result, task_name):
    folder = Path(result["folder"])
    entry = json.loads((folder / "trial.json").read_text())
    assert entry["outcome"] == "success" and entry["task"] == task_name and entry["device"] == "browser"
    for field in ("seed", "reason", "time_s", "duration_s", "readings", "progress", "mode_switches",
                  "effort"):
        assert field in entry
    assert (folder / "trial.mcap").stat().st_size > 1000


# The pour with its hand-written skill: driven through the page's gamepad in real time
# beside a busy loop (the simulator at 0.5-0.7 of real time) it succeeded in 16 of 16 runs
# since the simulated person stopped unlearning the tilt against the pour state's tilt
# limit (docs/try.md; before, 4 of 30 emptied the bottle). The learned vector-field pour
# is left out: two of its 20 lockstep trials flip with the CPU's kernels
# (docs/evaluation.md).
@pytest.mark.parametrize(("task_name", "condition"), [("drawer", "drawer-vf"), ("pour", "pour")])
def test_a_gamepad_drives_a_trial_to_success(tried, browser, task_name, condition):
    page = browser.page

    last: list = []

    def inject(u, held):
        axes = [_pad_axis(u[0]), -_pad_axis(u[1]), 0.0, -_pad_axis(u[2])]
        pressed = [k for k, b in ((A, held[0]), (RB, held[1]), (B, held[2] if len(held) > 2 else 0)) if b]
        if [axes, pressed] != last:  # the pad keeps its reading: a round trip only for a change
            page.evaluate(SET_PAD, [axes, buttons(*pressed)])
            last[:] = [axes, pressed]

    result = _drive(tried, page, task_name, condition, inject)
    assert result["outcome"] == "success", _failed(result)
    assert "success" in page.inner_text("#result")
    _assert_recorded(result, task_name)


# The keyboard drives the drawer. Its pour is left out: the simulated person steers by
# proportional wishes, and the keys make full presses of them (past 0.3) that it does not
# know of, so what it learns of the tilt is off; it poured 5 of 5 quietly, but beside a
# busy loop emptied the bottle in 1 of 8 (docs/try.md): a defect of the simulated person
# at a keyboard, not of the page, whose pour the gamepad covers.
@pytest.mark.parametrize(("task_name", "condition"), [("drawer", "drawer-vf")])
def test_the_keyboard_drives_a_trial_to_success(tried, browser, task_name, condition):
    page = browser.page
    page.evaluate("() => Object.defineProperty(navigator, 'getGamepads', "
                  "{value: () => [], configurable: true})")
    result = _drive(tried, page, task_name, condition, keyboard_injector(page))
    assert result["outcome"] == "success", _failed(result)
    _assert_recorded(result, task_name)
