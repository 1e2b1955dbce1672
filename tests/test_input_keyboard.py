"""The keyboard backend: the key decoder and the hold logic on scripted bytes and a
scripted clock, its flags, and ``sctd input keyboard`` on a pseudo-terminal: held while
the key repeats, zero once the repeats stop, the terminal's settings restored on SIGTERM."""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import termios
import threading
import time

import pytest

from sctd.wire import DEFAULT_ROBOT, Keys, codec
from sctd.wire.session import close_session, open_session
from sctd_services.input.device import InputError
from sctd_services.input.keyboard import (
    HELP,
    HoldTracker,
    Keyboard,
    KeyDecoder,
    reading_from_keys,
)
from sctd_services.input.mapping import shipped_mapping

from .conftest import ROOT, free_port, wait_for

RIGHT, UP, DOWN = b"\x1b[C", b"\x1b[A", b"\x1b[B"


# --- the decoder ----------------------------------------------------------------------

def test_decoder_arrows_page_keys_letters_and_space():
    d = KeyDecoder()
    assert d.feed(UP + DOWN + RIGHT + b"\x1b[D") == ["up", "down", "right", "left"]
    assert d.feed(b"\x1bOA\x1bOD") == ["up", "left"]  # application cursor mode
    assert d.feed(b"\x1b[5~\x1b[6~") == ["pageup", "pagedown"]
    assert d.feed(b"wS m\x05e") == ["w", "s", " ", "m", "\x05", "e"]
    assert d.unknown == 0


def test_decoder_completes_a_sequence_split_over_reads():
    d = KeyDecoder()
    assert d.feed(b"w\x1b") == ["w"]
    assert d.feed(b"[") == []
    assert d.feed(b"5") == []
    assert d.feed(b"~\x1b[") == ["pageup"]
    assert d.feed(b"A") == ["up"]


def test_decoder_drops_unknown_sequences_and_a_lone_escape():
    d = KeyDecoder()
    assert d.feed(b"\x1b[1;5C" + b"w") == ["w"]  # Ctrl-Right: not a key of ours
    assert d.feed(b"\x1b[15~" + UP) == ["up"]  # F5
    assert d.feed(b"\x1bx") == ["x"]  # ESC then x: the ESC alone is dropped
    assert d.unknown == 3


# --- the hold logic -------------------------------------------------------------------

def test_a_single_press_holds_for_the_first_hold_time():
    h = HoldTracker(first_hold=0.6, repeat_hold=0.1)
    h.press("up", 10.0)
    assert h.held(10.0) == {"up"}
    assert h.held(10.59) == {"up"}
    assert h.held(10.61) == set()


def test_repeats_keep_a_key_held_and_it_falls_the_repeat_hold_after_the_last():
    h = HoldTracker(first_hold=0.6, repeat_hold=0.1)
    h.press("right", 0.0)
    t = 0.5  # the terminal's repeat delay, then a repeat every 33 ms
    while t < 2.0:
        assert h.held(t) == {"right"}
        h.press("right", t)
        t += 0.033
    last = t - 0.033
    assert h.held(last + 0.099) == {"right"}
    assert h.held(last + 0.101) == set()
    h.press("right", last + 1.0)  # pressed again later: a first press, the long hold
    assert h.held(last + 1.5) == {"right"}


def test_each_key_has_its_own_hold():
    h = HoldTracker(first_hold=0.6, repeat_hold=0.1)
    h.press("up", 0.0)
    h.press("up", 0.5)  # repeat: up now holds until 0.6
    h.press("w", 0.55)  # a new key: its first press, until 1.15
    assert h.held(0.58) == {"up", "w"}
    assert h.held(0.7) == {"w"}


def test_hold_times_must_be_ordered():
    with pytest.raises(ValueError, match="hold times"):
        HoldTracker(first_hold=0.1, repeat_hold=0.5)
    with pytest.raises(ValueError):
        HoldTracker(first_hold=0.6, repeat_hold=0.0)


def test_reading_from_keys_signs_speed_buttons_and_opposites():
    r = reading_from_keys({"right", "up", "pageup"}, 1.0, 5.0)
    assert r.axes == (1.0, 1.0, 1.0) and r.buttons == (0, 0, 0, 0, 0) and r.stamp == 5.0
    assert reading_from_keys({"left", "down", "s"}, 0.5, 0.0).axes == (-0.5, -0.5, -0.5)
    assert reading_from_keys({"up", "down", "w", "pagedown"}, 1.0, 0.0).axes == (0.0, 0.0, 0.0)
    assert reading_from_keys({"w", "pageup"}, 1.0, 0.0).axes == (0.0, 0.0, 1.0)  # clipped
    assert reading_from_keys({" "}, 1.0, 0.0).buttons == (1, 0, 0, 0, 0)
    assert reading_from_keys({"m", "e", "q"}, 1.0, 0.0).buttons == (1, 0, 1, 0, 0)
    keyboard = shipped_mapping("keyboard")
    u, b = keyboard.apply(reading_from_keys({"e", "left"}, 1.0, 0.0), 6)
    assert u == [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0] and b == [0, 1, 1, 0]  # enable held: no deadman
    assert keyboard.apply(reading_from_keys({"c"}, 1.0, 0.0), 3)[1] == [0, 1, 0, 1]  # c: choose
    assert keyboard.stop(reading_from_keys({"x"}, 1.0, 0.0))  # x: the message's stop field
    assert not keyboard.stop(reading_from_keys({"e"}, 1.0, 0.0))


# --- the backend ----------------------------------------------------------------------

def args(**kw) -> argparse.Namespace:
    return argparse.Namespace(**{"key_hold": 0.6, "key_repeat_hold": 0.1, "key_speed": 1.0, **kw})


def test_backend_refuses_bad_flags_and_a_stdin_that_is_not_a_terminal():
    b = Keyboard()
    assert b.missing() is None and b.default_map == "keyboard"
    assert b.devices() == []  # pytest's stdin is not a terminal
    with pytest.raises(InputError, match="key-speed"):
        b.open(None, args(key_speed=0.0))
    with pytest.raises(InputError, match="key-hold"):
        b.open(None, args(key_hold=0.05))
    with pytest.raises(InputError, match="the only device is 0: terminal"):
        b.open("pad", args())
    with pytest.raises(InputError, match="stdin is not a terminal"):
        b.open(None, args())


@pytest.mark.slow
def test_list_shows_the_terminal_when_stdin_is_one():
    master, slave = os.openpty()
    try:
        out = subprocess.run([sys.executable, "-m", "sctd_services.input", "--list"], cwd=ROOT,
                             stdin=slave, capture_output=True, text=True, timeout=60)
    finally:
        os.close(slave)
        os.close(master)
    lines = out.stdout.splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("keyboard "))
    assert lines[k + 1].strip().startswith("0: terminal (/dev/pts/"), out.stdout


# --- on a pseudo-terminal -------------------------------------------------------------

@pytest.mark.slow
def test_keyboard_on_a_pty_holds_while_repeating_then_zero_and_restores_the_terminal(tmp_path):
    master, slave = os.openpty()
    before = termios.tcgetattr(slave)
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    seen: list[codec.InputMsg] = []
    lock = threading.Lock()

    def on_sample(sample) -> None:
        with lock:
            seen.append(codec.decode_input(sample.payload.to_bytes()))

    def u0() -> list[float]:
        with lock:
            return [m.u[0] for m in seen]

    s = open_session(listen=[ep])
    log = tmp_path / "keyboard.log"
    child = None
    try:
        sub = s.declare_subscriber(Keys(DEFAULT_ROBOT).input("keyboard"), on_sample)
        with open(log, "wb") as out:
            # Hold times far longer than the writes' spacing, so a loaded machine's
            # delays do not drop the key between repeats.
            child = subprocess.Popen(
                [sys.executable, "-m", "sctd_services.input", "keyboard", "--connect", ep,
                 "--key-hold", "1.5", "--key-repeat-hold", "0.5", "--key-speed", "0.8"],
                cwd=ROOT, stdin=slave, stdout=out, stderr=subprocess.STDOUT,
                start_new_session=True)
        assert wait_for(lambda: len(u0()) > 5, 30), log.read_text()
        changed = termios.tcgetattr(slave)
        assert not changed[3] & termios.ECHO and not changed[3] & termios.ICANON  # cbreak
        assert u0()[-1] == 0.0
        os.write(master, RIGHT)  # the press, then the terminal's repeats
        time.sleep(0.5)
        for _ in range(20):
            os.write(master, RIGHT)
            time.sleep(0.05)
        assert wait_for(lambda: u0()[-1] == 0.0 and u0().count(0.8) > 0, 10), u0()
        os.write(master, b" ")  # mode
        assert wait_for(lambda: any(m.buttons[0] for m in list(seen)), 10)
        assert wait_for(lambda: seen[-1].buttons == (0, 1, 0, 0), 10)
        child.send_signal(signal.SIGTERM)
        rc = child.wait(10)
        time.sleep(0.3)
        sub.undeclare()
    finally:
        if child is not None and child.poll() is None:
            os.killpg(child.pid, signal.SIGKILL)
            child.wait()
        close_session(s)
        after = termios.tcgetattr(slave)
        os.close(slave)
        os.close(master)
    text = log.read_text()
    assert rc == 0, text
    assert after == before, "the terminal's settings were not restored"
    assert HELP in text
    # Collapsed, x reads: zero, held at the key speed through the repeats, zero again.
    runs = [x for k, x in enumerate(u0()) if k == 0 or u0()[k - 1] != x]
    assert runs == [0.0, 0.8, 0.0], runs
    assert all(m.u[1:] == (0.0, 0.0) for m in seen)
    assert seen[-1].u == (0.0, 0.0, 0.0) and seen[-1].buttons == (0, 0, 0, 0)  # zero on exit
    assert all(m.buttons[1] == 1 for m in seen[:-3])  # enable held while running
