"""The gamepad backend through SDL2 itself: SDL's virtual game controller read through
the game-controller API, hot-plug, selectors, the virtual script, ``--list``, and end
to end: the bridge process with a scripted pad -> Zenoh -> ``sctd run`` -> targets."""

from __future__ import annotations

import argparse
import ctypes
import itertools
import os
import re
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import zenoh

from sctd.wire import Keys, codec
from sctd.wire.session import close_session, open_session
from sctd_services.input.bridge import Bridge
from sctd_services.input.device import InputError
from sctd_services.input.gamepad import Gamepad, sdl_acquire, sdl_release
from sctd_services.input.mapping import shipped_mapping
from sctd_services.input.virtual_pad import NAME, Script, VirtualPad, load_script, parse_script
from tests.conftest import ROOT, free_port, sctd, wait_for

NO_FLAGS = argparse.Namespace(gamepad_mappings=None, virtual_script=None)


@pytest.fixture
def pad():
    with VirtualPad() as p:
        yield p


@pytest.mark.slow
def test_virtual_pad_reads_normalised_through_the_controller_api(pad):
    with Gamepad().open(None, NO_FLAGS) as dev:
        assert dev.name == NAME and dev.axes == 6 and dev.buttons >= 15
        rest = dev.read()
        assert rest is not None and rest.axes == (0.0,) * 6 and not any(rest.buttons)
        pad.set_axis(0, 0.5)
        pad.set_axis(1, -1.0)  # left stick pushed forward: SDL's y is down +
        pad.set_axis(3, 1.0)
        pad.set_axis(4, 0.25)  # triggers 0..1
        pad.set_axis(5, 1.0)
        pad.set_button(10, True)
        pad.set_button(0, True)
        before = time.time()
        r = dev.read()
        assert r is not None and r.stamp >= before
        assert r.axes == pytest.approx((0.5, -1.0, 0.0, 1.0, 0.25, 1.0), abs=1e-4)
        assert all(-1.0 <= a <= 1.0 for a in r.axes)
        assert [k for k, b in enumerate(r.buttons) if b] == [0, 10]
        pad.set_button(0, False)
        pad.set_axis(5, 0.0)
        r = dev.read()
        assert r is not None and r.axes[5] == 0.0 and [k for k, b in enumerate(r.buttons) if b] == [10]


@pytest.mark.slow
def test_xbox_map_numbering_is_sdls():
    """The shipped map's sources and buttons are SDL's game-controller enums."""
    import sdl2

    m = shipped_mapping("xbox")
    assert [(a.source, a.minus, a.invert) for a in m.axes[:5]] == [
        (sdl2.SDL_CONTROLLER_AXIS_LEFTX, None, False),
        (sdl2.SDL_CONTROLLER_AXIS_LEFTY, None, True),
        (sdl2.SDL_CONTROLLER_AXIS_RIGHTY, None, True),
        (sdl2.SDL_CONTROLLER_AXIS_RIGHTX, None, False),
        (sdl2.SDL_CONTROLLER_AXIS_TRIGGERRIGHT, sdl2.SDL_CONTROLLER_AXIS_TRIGGERLEFT, False)]
    assert m.buttons == {"mode": sdl2.SDL_CONTROLLER_BUTTON_A,
                         "enable": sdl2.SDL_CONTROLLER_BUTTON_RIGHTSHOULDER,
                         "escape": sdl2.SDL_CONTROLLER_BUTTON_B, "choose": sdl2.SDL_CONTROLLER_BUTTON_X,
                         "grasp": sdl2.SDL_CONTROLLER_BUTTON_LEFTSHOULDER,
                         "stop": sdl2.SDL_CONTROLLER_BUTTON_Y}
    # the range a mapping file is checked against is SDL's numbering
    assert (Gamepad.device_axes, Gamepad.device_buttons) == (sdl2.SDL_CONTROLLER_AXIS_MAX,
                                                             sdl2.SDL_CONTROLLER_BUTTON_MAX)


@pytest.mark.slow
def test_bridge_with_the_xbox_map_publishes_the_stick_and_deadman(pad):
    sent: list[bytes] = []
    with Gamepad().open(None, NO_FLAGS) as dev:
        bridge = Bridge(dev, shipped_mapping("xbox"), 3, sent.append, log=lambda s: None)
        pad.set_axis(1, -1.0)
        bridge.step()
        pad.set_button(10, True)
        bridge.step()
    released, held = (codec.decode_input(m) for m in sent)
    assert list(released.u) == pytest.approx([0.0, 1.0, 0.0]) and released.buttons == (0, 0, 0, 0, 0)
    assert list(held.u) == pytest.approx([0.0, 1.0, 0.0]) and held.buttons == (0, 1, 0, 0, 0)


@pytest.mark.slow
def test_unplugged_pad_reads_none_and_is_reopened_by_itself(pad):
    with Gamepad().open(NAME, NO_FLAGS) as dev:
        pad.set_axis(0, 1.0)
        assert dev.read().axes[0] == 1.0
        pad.detach()
        assert dev.read() is None and dev.read() is None
        with VirtualPad("another pad") as other:  # not what --device names: not opened
            other.set_axis(0, -1.0)
            assert dev.read() is None
            pad.attach()
            r = dev.read()
            assert r is not None and r.axes[0] == 0.0  # plugged in again at rest
            assert dev.reopened == 1
            pad.set_axis(2, -0.5)
            assert dev.read().axes[2] == pytest.approx(-0.5, abs=1e-4)


@pytest.mark.slow
def test_selector_errors_name_the_devices(pad):
    g = Gamepad()
    with pytest.raises(InputError, match=f"--device 'nosuch' matches none of the devices \\(0: {NAME}\\)"):
        g.open("nosuch", NO_FLAGS)
    with pytest.raises(InputError, match="matches none"):
        g.open("7", NO_FLAGS)
    with g.open("0", NO_FLAGS) as dev:
        assert dev.name == NAME


@pytest.mark.slow
def test_no_pad_is_an_error_and_a_joystick_without_mapping_is_listed_but_refused():
    g = Gamepad()
    with pytest.raises(InputError, match="gamepad: no device found"):
        g.open(None, NO_FLAGS)
    sdl = sdl_acquire()
    try:
        index = sdl.SDL_JoystickAttachVirtual(sdl.SDL_JOYSTICK_TYPE_UNKNOWN, 2, 2, 0)
        assert index >= 0
        try:
            [info] = g.devices()
            assert "not a game controller: no mapping" in info.detail
            with pytest.raises(InputError, match=r"no game controller among the joysticks.*no mapping"):
                g.open(None, NO_FLAGS)
            with pytest.raises(InputError, match="not a game controller"):
                g.open(info.name, NO_FLAGS)
        finally:
            sdl.SDL_JoystickDetachVirtual(index)
    finally:
        sdl_release()


@pytest.mark.slow
def test_mappings_file_makes_a_joystick_a_controller(tmp_path):
    sdl = sdl_acquire()
    try:
        index = sdl.SDL_JoystickAttachVirtual(sdl.SDL_JOYSTICK_TYPE_UNKNOWN, 2, 4, 0)
        try:
            buf = ctypes.create_string_buffer(33)
            sdl.SDL_JoystickGetGUIDString(sdl.SDL_JoystickGetDeviceGUID(index), buf, 33)
            db = tmp_path / "gamecontrollerdb.txt"
            db.write_text(f"{buf.value.decode()},Test stick,a:b0,b:b1,rightshoulder:b3,"
                          "leftx:a0,lefty:a1,platform:Linux,\n")
            args = argparse.Namespace(gamepad_mappings=str(db), virtual_script=None)
            with Gamepad().open(None, args) as dev:
                assert dev.name == "Test stick"
                joystick = sdl.SDL_JoystickOpen(index)
                sdl.SDL_JoystickSetVirtualButton(joystick, 3, 1)
                r = dev.read()
                sdl.SDL_JoystickClose(joystick)
                assert [k for k, b in enumerate(r.buttons) if b] == [10]  # rightshoulder
        finally:
            sdl.SDL_JoystickDetachVirtual(index)
    finally:
        sdl_release()
    with pytest.raises(InputError, match=r"--gamepad-mappings .*nope\.txt: no such file"):
        Gamepad().open(None, argparse.Namespace(gamepad_mappings=str(tmp_path / "nope.txt")))


@pytest.mark.slow
def test_script_plays_on_the_pad_opened_like_a_real_one(tmp_path):
    script = tmp_path / "s.yaml"
    script.write_text("- {at: 0.0, button: 10, pressed: 1}\n- {at: 0.5, axis: 1, value: -1.0}\n"
                      "- {at: 1.0, detach: true}\n- {at: 1.5, attach: true}\n"
                      "- {at: 1.6, axis: 4, value: 0.5}\n")
    now = [100.0]
    steps = load_script(script)
    with VirtualPad() as p, Gamepad().open("virtual", NO_FLAGS) as dev:
        s = Script(p, steps, clock=lambda: now[0])

        def at(t: float):
            now[0] = 100.0 + t
            s.advance()
            return dev.read()

        assert at(0.0).buttons[10] == 1 and at(0.4).axes[1] == 0.0
        assert at(0.5).axes[1] == -1.0
        assert at(1.0) is None and at(1.4) is None
        r = at(1.5)
        assert r is not None and r.axes == (0.0,) * 6 and not any(r.buttons)
        assert at(2.0).axes[4] == pytest.approx(0.5, abs=1e-4)


@pytest.mark.slow
def test_a_late_reader_still_sees_the_pad_unplugged_and_plugged_in_again(tmp_path):
    """A reader that falls 2 s behind the script (a loaded machine) reads the unplugging
    and the plugging in as two reads, in order, and the steps after them on a third."""
    steps = parse_script([{"at": 0.0, "axis": 1, "value": -1.0}, {"at": 1.0, "detach": True},
                          {"at": 1.5, "attach": True}, {"at": 1.6, "axis": 0, "value": 0.5}], "s")
    now = [0.0]
    with VirtualPad() as p, Gamepad().open("virtual", NO_FLAGS) as dev:
        s = Script(p, steps, clock=lambda: now[0])
        s.advance()
        assert dev.read().axes[1] == -1.0
        now[0] = 3.0  # everything is due at once
        reads = []
        for _ in range(3):
            s.advance()
            reads.append(dev.read())
        assert reads[0] is None  # unplugged
        assert reads[1] is not None and reads[1].axes == (0.0,) * 6  # plugged in, at rest
        assert reads[2] is not None and reads[2].axes[0] == pytest.approx(0.5, abs=1e-4)


@pytest.mark.parametrize(("doc", "message"), [
    ([{"at": 0, "axis": 6, "value": 0}], r"\[0\]: axis: expected 0 to 5"),
    ([{"at": 0, "axis": 4, "value": -0.5}], r"\[0\]: value: a trigger axis takes 0 to 1"),
    ([{"at": 0, "axis": 0, "value": 1.5}], r"\[0\]: value: a stick axis takes -1 to 1"),
    ([{"at": 0, "button": 15, "pressed": 1}], r"\[0\]: button: expected 0 to 14"),
    ([{"at": 0, "button": 1, "pressed": 2}], r"\[0\]\.pressed: expected 0 or 1"),
    ([{"at": -1, "detach": True}], r"\[0\]\.at: expected seconds >= 0"),
    ([{"at": 0, "axis": 0, "value": 0, "button": 1}], r"\[0\]: expected exactly one of"),
    ([{"at": 0, "axis": 0, "value": 0, "speed": 1}], r"\[0\]\.speed: unknown field"),
    ([{"at": 0, "axis": 0, "value": 0, "speed": 1, 7: 1}], r"\[0\]\.7: unknown field"),
    ([{"at": 1, "detach": True}, {"at": 2, "axis": 0, "value": 1}], r"\[1\]: the pad is detached at 2 s"),
    ([{"at": 0, "attach": True}], r"\[0\]: the pad is already attached at 0 s"),
    ({"at": 0}, "expected a list of steps"),
])
def test_bad_scripts_are_refused_naming_the_step(doc, message):
    with pytest.raises(InputError, match=f"s.yaml: {message}"):
        parse_script(doc, "s.yaml")


@pytest.mark.slow
def test_bad_script_file_exits_2_naming_it(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("- {at: 0, axis: 9, value: 0}\n")
    p = sctd("input", "gamepad", "--virtual-script", str(bad), "--connect",
             f"tcp/127.0.0.1:{free_port()}", log=tmp_path / "b.log")
    assert p.p.wait(60) == 2, p.output()
    p.stop()
    assert f"--virtual-script {bad}: [0]: axis: expected 0 to 5, got 9" in p.output()


def test_script_steps_are_played_in_time_order():
    steps = parse_script([{"at": 2, "attach": True}, {"at": 1, "detach": True}], "s")
    assert [s.kind for s in steps] == ["detach", "attach"]


@pytest.mark.slow
def test_list_names_the_gamepad_backend_and_sees_no_pad(tmp_path):
    env = {**os.environ, "SDL_VIDEODRIVER": "dummy"}
    out = subprocess.run([sys.executable, "-m", "sctd_services.input", "--list"], cwd=ROOT, env=env,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    at = next(k for k, line in enumerate(lines) if line.startswith("gamepad "))
    assert "SDL2" in lines[at] and lines[at + 1].strip() == "no device found", out.stdout


# --- end to end -------------------------------------------------------------------------

KEYS = Keys("edan")
T_WORLD_MUG = [0.6, 0.0, 0.78, 0, 0, 0, 1]
START = [0.35, 0.25, 0.90, 0, 0, 0, 1]
WATCHDOG = 0.1  # sctd run's default input timeout, s
# The pad's timeline (s from the bridge's first read): deadman (right shoulder) and the
# left stick forward; unplugged; plugged in again, deadman and the left stick right.
SCRIPT = """\
- {at: 0.0, button: 10, pressed: 1}
- {at: 0.2, axis: 1, value: -1.0}
- {at: 2.2, detach: true}
- {at: 3.0, attach: true}
- {at: 3.2, button: 10, pressed: 1}
- {at: 3.2, axis: 0, value: 1.0}
"""


class Rig:
    """A robot that follows each target exactly (state and the mug), and a record of the
    targets and of the gamepad bridge's messages."""

    def __init__(self, port: int):
        self.session = open_session(connect=[f"tcp/127.0.0.1:{port}"])
        self.lock = threading.Lock()
        self.targets: list[dict] = []
        self.inputs: list[codec.InputMsg] = []
        self.pose = list(START)
        self.stop = threading.Event()
        s = self.session
        self.subs = [s.declare_subscriber(KEYS.target, self._on_target),
                     s.declare_subscriber(KEYS.input("gamepad"), self._on_input)]
        self.pubs = [s.declare_publisher(KEYS.state), s.declare_publisher(KEYS.objects("mug"))]
        self.thread = threading.Thread(target=self._robot, daemon=True)
        self.thread.start()

    def _on_target(self, sample: zenoh.Sample) -> None:
        msg = codec.decode_target(sample.payload.to_bytes())
        with self.lock:
            self.targets.append(msg)
            self.pose = msg["pose"]

    def _on_input(self, sample: zenoh.Sample) -> None:
        msg = codec.decode_input(sample.payload.to_bytes())
        with self.lock:
            self.inputs.append(msg)

    def _robot(self) -> None:
        state, mug = self.pubs
        for k in itertools.count():
            if self.stop.is_set():
                return
            with self.lock:
                pose = list(self.pose)
            state.put(codec.encode_state(k, time.time(), pose))
            if k % 10 == 0:
                mug.put(codec.encode_object(k, time.time(), T_WORLD_MUG))
            time.sleep(0.002)

    def inputs_where(self, pred) -> list[codec.InputMsg]:
        with self.lock:
            return [m for m in self.inputs if pred(m)]

    def close(self) -> None:
        self.stop.set()
        self.thread.join()
        for d in (*self.subs, *self.pubs):
            d.undeclare()
        close_session(self.session)


def pushed(axis: int):
    """Enabled messages with ``u[axis]`` near +1 and the other axes zero."""
    return lambda m: (m.buttons == (0, 1, 0, 0, 0) and m.u[axis] > 0.9
                      and all(abs(x) < 1e-9 for k, x in enumerate(m.u) if k != axis))


def released(m: codec.InputMsg) -> bool:
    return m.buttons == (0, 0, 0, 0, 0) and all(x == 0.0 for x in m.u)


def moved(targets: list[dict]) -> np.ndarray:
    return np.subtract(targets[-1]["pose"][:3], targets[0]["pose"][:3])


def dominant(v: np.ndarray) -> tuple[int, float]:
    k = int(np.argmax(np.abs(v)))
    return k, float(np.sign(v[k]))


def assert_stops_within_watchdog(targets: list[dict], last_moving_input: codec.InputMsg) -> None:
    """The targets that follow ``last_moving_input`` stop moving within the watchdog, by
    the daemon's and the bridge's own stamps; none after it moves at all."""
    after = [t for t in targets if t["in_seq"] >= last_moving_input.seq]
    steps = [(a, b) for a, b in itertools.pairwise(after)
             if np.linalg.norm(np.subtract(b["pose"][:3], a["pose"][:3])) > 1e-9]
    assert all(a["in_seq"] == last_moving_input.seq for a, _ in steps), \
        "the target moved on an input with the deadman released"
    if steps:
        assert steps[-1][1]["stamp"] - last_moving_input.stamp <= WATCHDOG + 0.002, (
            f"moved {steps[-1][1]['stamp'] - last_moving_input.stamp:.3f} s after the last input")


@pytest.mark.slow
def test_scripted_pad_drives_the_daemon_and_unplugging_stops_it(tmp_path):
    port = free_port()
    script = tmp_path / "pad.yaml"
    script.write_text(SCRIPT)
    daemon = sctd("run", "--skill", str(ROOT / "skills" / "pour.yaml"), "--listen",
                  f"tcp/127.0.0.1:{port}", "--rate", "1000", log=tmp_path / "daemon.log")
    rig = Rig(port)
    bridge = None
    try:
        assert wait_for(lambda: len(rig.targets) > 50, 20), f"no targets; daemon log: {daemon.output()}"
        bridge = sctd("input", "gamepad", "--virtual-script", str(script), "--connect",
                      f"tcp/127.0.0.1:{port}", log=tmp_path / "bridge.log")
        # until the re-plugged pad has pushed right for 0.5 s (50 messages at 100 Hz)
        assert wait_for(lambda: len(rig.inputs_where(pushed(0))) >= 50, 40), bridge.output()
        rc = bridge.stop()
        assert rc == 0, bridge.output()

        def past_the_last_input(ticks: int) -> bool:
            """The daemon published ``ticks`` targets that follow the bridge's last input
            (past the 0.1 s watchdog at 1 kHz)."""
            with rig.lock:
                last = rig.inputs[-1].seq
                return sum(t["in_seq"] == last for t in rig.targets) >= ticks

        assert wait_for(lambda: past_the_last_input(150), 20)
    finally:
        if bridge is not None:
            bridge.stop()
        rig.close()
        daemon.stop()
    log = bridge.output()
    assert "sctd virtual pad: disconnected" in log and "sctd virtual pad: reconnected" in log, log
    with rig.lock:
        inputs, targets = list(rig.inputs), sorted(rig.targets, key=lambda t: t["seq"])
    forward = [m for m in inputs if pushed(1)(m)]
    right = [m for m in inputs if pushed(0)(m)]
    # spans in the bridge's own stamps, not counts: a loaded machine reads less often
    assert len(forward) > 10 and forward[-1].stamp - forward[0].stamp > 1.0, \
        "2 s of the left stick forward (less what a late reader missed)"
    # unplugged: zero with the deadman released between the two pushes
    gap = [m for m in inputs if forward[-1].seq < m.seq < right[0].seq]
    assert gap and all(released(m) for m in gap), gap[:3]
    assert re.search(r"stopped after \d+ messages \(([1-9]\d*) zero while disconnected", log), log
    assert all(released(m) for m in inputs[-3:]), "the bridge's last messages are zero"

    # Left stick forward: the pour skill's carry translates the tip in the mug's axes
    # (the mug is not rotated), u[1] along +y.
    during = [t for t in targets if forward[0].seq <= t["in_seq"] <= forward[-1].seq]
    d = moved(during)
    assert dominant(d) == (1, 1.0) and d[1] > 0.05, d
    assert_stops_within_watchdog([t for t in targets if t["in_seq"] < right[0].seq], forward[-1])
    # The same pad pushed right after it was plugged in again: +x.
    during = [t for t in targets if right[0].seq <= t["in_seq"] <= right[-1].seq]
    d = moved(during)
    assert dominant(d) == (0, 1.0) and d[0] > 0.02, d
    assert_stops_within_watchdog(targets, right[-1])
    # SIGTERM: the bridge's zeros (spaced past the daemon's ingress limit) reach the
    # daemon, which holds on them at once rather than after its watchdog
    zeros = {m.seq for m in inputs[-3:]}
    on_zero = [t for t in targets if t["in_seq"] in zeros]
    assert on_zero, "the daemon used none of the bridge's zeros on exit"
    held = [t["pose"] for t in targets if t["seq"] >= on_zero[0]["seq"]]
    assert all(np.allclose(p, held[0], atol=1e-12) for p in held), "moved after a zero"
