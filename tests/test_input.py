"""`sctd input`'s framework: the mapping file, the backend registry (built-ins and the
``sctd.input`` entry points) and the bridge's safety rules (finite, bounded, zero with
the deadman released while the device is gone and on exit)."""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
import threading

import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd.wire import codec
from sctd_services.input.bridge import Bridge
from sctd_services.input.bridge import run as run_bridge
from sctd_services.input.device import DeviceInfo, InputDevice, InputError, Reading, pick
from sctd_services.input.mapping import (
    AxisMap,
    Mapping,
    check_range,
    identity,
    load_mapping,
    parse_mapping,
    shipped_mapping,
)
from sctd_services.input.registry import BUILTIN, get_backend
from tests.conftest import ROOT


def _doc(**over):
    doc = {"version": 1, "axes": [{"source": 0}, {"source": 1, "invert": True, "deadband": 0.2},
                                  {"source": [3, 2], "scale": 0.5}],
           "buttons": {"mode": 4, "enable": 5, "escape": None}}
    doc.update(over)
    return doc


def test_mapping_known_answers():
    m = parse_mapping(_doc(), "t.yaml")
    u, b = m.apply(Reading((0.5, 0.6, 0.2, 1.0), (0, 0, 0, 0, 1, 1)), 3)
    assert u[0] == 0.5
    assert u[1] == pytest.approx(-(0.6 - 0.2) / 0.8)  # inverted, rescaled from the band's edge
    assert u[2] == pytest.approx(0.5 * (1.0 - 0.2))  # axis 3 minus axis 2, scaled
    assert b == [1, 1, 0]  # mode (device 4), enable (device 5), escape unmapped
    u, b = m.apply(Reading((0.0, 0.19, 0.0, 0.0), (0, 0, 0, 0, 0, 0)), 6)
    assert u == [0.0] * 6 and b == [0, 0, 0]  # within the dead band; deadman released
    # no enable button mapped: enable is held (the device has no deadman)
    assert identity().apply(Reading((0.1, 0.2, 0.3)), 3) == ([0.1, 0.2, 0.3], [0, 1, 0])


@given(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=0, max_size=8),
       st.floats(0.0, 0.99), st.floats(-10, 10).filter(lambda s: abs(s) > 1e-3), st.booleans())
def test_mapped_axes_are_finite_bounded_and_zero_in_the_band(axes, db, scale, invert):
    m = AxisMap(0, 1, scale, invert, db)
    x = m(tuple(axes))
    assert math.isfinite(x) and -1.0 <= x <= 1.0
    a0 = axes[0] if axes and math.isfinite(axes[0]) else 0.0
    a1 = axes[1] if len(axes) > 1 and math.isfinite(axes[1]) else 0.0
    if abs(max(-1.0, min(1.0, a0 - a1))) <= db:
        assert x == 0.0


@pytest.mark.parametrize(("over", "where"), [
    ({"version": 2}, "version"),
    ({"axes": []}, "axes"),
    ({"axes": [{"source": -1}]}, "axes[0].source"),
    ({"axes": [{"source": 0, "deadband": 1.0}]}, "axes[0].deadband"),
    ({"axes": [{"source": 0, "scale": 0}]}, "axes[0].scale"),
    ({"axes": [{"source": 0, "invert": "yes"}]}, "axes[0].invert"),
    ({"axes": [{"source": 0, "gain": 2}]}, "axes[0].gain"),
    ({"buttons": {"deadman": 3}}, "buttons.deadman"),
    ({"buttons": {"enable": "A"}}, "buttons.enable"),
    ({"colour": "red"}, "colour"),
])
def test_bad_mapping_files_name_the_field(over, where):
    with pytest.raises(InputError) as e:
        parse_mapping(_doc(**over), "my.yaml")
    assert str(e.value).startswith(f"my.yaml: {where}: ")


def test_unknown_keys_of_mixed_types_are_named():
    """YAML's ``82:`` is an int key: next to a string one, naming the first unknown key
    must not compare an int with a str (found by ``sctd bench fuzz``)."""
    doc = _doc()
    with pytest.raises(InputError, match=r"^my\.yaml: 82: unknown field"):
        parse_mapping({**doc, 82: None, "colour": "red"}, "my.yaml")
    doc["axes"] = [{"source": 0, "gain": 2, 82: None}]
    with pytest.raises(InputError, match=r"^my\.yaml: axes\[0\]\.82: unknown field"):
        parse_mapping(doc, "my.yaml")


# Each built-in backend's numbering: (axes, buttons) its devices have at most.
RANGES = {"keyboard": (3, 5), "gamepad": (6, 21), "spacemouse": (6, 31), "emg": (3, 0)}
HUGE = 10**30  # a YAML integer Python takes whole


def test_every_builtin_backend_says_its_range():
    from sctd_services.input.emg.processing import N_AXES
    from sctd_services.input.spacemouse import MODELS

    assert set(RANGES) == set(BUILTIN)
    assert RANGES["emg"][0] == N_AXES  # its calibrated axes
    assert RANGES["spacemouse"][1] == max(m.buttons for m in MODELS.values())  # the most of any model
    for name, (axes, buttons) in RANGES.items():
        b = get_backend(name)
        assert (b.device_axes, b.device_buttons) == (axes, buttons), name


@pytest.mark.parametrize("backend", sorted(RANGES))
@pytest.mark.parametrize(("over", "where", "what"), [
    ({"buttons": {"enable": HUGE}}, "buttons.enable", f"button {HUGE}"),
    ({"buttons": {"mode": "B"}}, "buttons.mode", "button B"),  # B: the backend's button count
    ({"buttons": {"stop": "B"}}, "buttons.stop", "button B"),
    ({"buttons": {"grasp": "B"}}, "buttons.grasp", "button B"),
    ({"axes": [{"source": 0}, {"source": "A"}]}, "axes[1].source", "axis A"),  # A: its axis count
    ({"axes": [{"source": [0, HUGE]}]}, "axes[0].source[1]", f"axis {HUGE}"),
    ({"axes": [{"source": ["A", 0]}]}, "axes[0].source[0]", "axis A"),
])
def test_a_mapping_naming_a_button_or_axis_the_backend_lacks_is_refused(backend, over, where, what):
    """Each field against each backend's numbering, just past its end (and far past it):
    the error names the file, the field, the value and the range."""
    axes, buttons = RANGES[backend]

    def fill(v):
        return {"A": axes, "B": buttons}.get(v, v) if isinstance(v, str) else v
    doc = {"version": 1, "axes": [{"source": 0}], "buttons": {"enable": None}}
    for k, v in over.items():
        if k == "buttons":
            doc[k] = {**doc[k], **{r: fill(b) for r, b in v.items()}}
        else:
            doc[k] = [{"source": [fill(x) for x in a["source"]] if isinstance(a["source"], list)
                       else fill(a["source"])} for a in v]
    mapping = parse_mapping(doc, "my.yaml")
    what = what.replace(" A", f" {axes}").replace(" B", f" {buttons}")
    with pytest.raises(InputError) as e:
        check_range(mapping, backend, axes, buttons)
    kind = what.split()[0]
    n = axes if kind == "axis" else buttons
    many = {"axis": "axes", "button": "buttons"}[kind]
    have = f"{many} 0 to {n - 1}" if n else f"no {many}"
    assert str(e.value) == f"my.yaml: {where}: {what} is out of range: {backend} devices have {have}"


@pytest.mark.parametrize("backend", sorted(RANGES))
def test_a_mapping_within_the_backend_s_range_passes_and_so_do_the_shipped_ones(backend):
    axes, buttons = RANGES[backend]
    last = {"version": 1, "axes": [{"source": axes - 1}, {"source": [0, axes - 1]}],
            "buttons": {"enable": buttons - 1 if buttons else None}}
    check_range(parse_mapping(last, "my.yaml"), backend, axes, buttons)
    b = get_backend(backend)
    if b.default_map:
        check_range(shipped_mapping(b.default_map), backend, axes, buttons)
    check_range(parse_mapping(last, "my.yaml"), backend, None, None)  # a range not known: not checked


@pytest.mark.parametrize(("field", "value", "message"), [
    ("enable", HUGE, f"buttons.enable: button {HUGE} is out of range: ROS Joy devices have buttons 0 to 511"),
    ("enable", 512, "buttons.enable: button 512 is out of range: ROS Joy devices have buttons 0 to 511"),
    ("source", 64, "axes[0].source: axis 64 is out of range: ROS Joy devices have axes 0 to 63"),
])
def test_a_joy_map_naming_what_no_joy_has_is_refused_before_anything_starts(tmp_path, field, value, message):
    """A ROS Joy map (sctd ros --joy-map, sctd run --ros-joy-map) is checked against what
    a Joy can carry, as each device backend's map is against its devices."""
    from sctd_services.input.mapping import JOY_AXES, JOY_BUTTONS, joy_function

    doc = {"version": 1, "axes": [{"source": value if field == "source" else 0}],
           "buttons": {"enable": value if field == "enable" else 0}}
    path = tmp_path / "joy.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(InputError) as e:
        joy_function(path)
    assert str(e.value) == f"{path}: {message}"
    # the last of each passes; a Joy shorter than the map reads it released and at rest
    path.write_text(yaml.safe_dump({"version": 1, "axes": [{"source": JOY_AXES - 1}],
                                    "buttons": {"enable": JOY_BUTTONS - 1}}))
    apply = joy_function(path)
    u, buttons, stop = apply((1.0,) * JOY_AXES, (1,) * JOY_BUTTONS)
    assert u[0] == 1.0 and buttons[1] == 1 and not stop
    u, buttons, stop = apply((1.0,) * 8, (1,) * 11)
    assert u == [0.0] * 6 and buttons[1] == 0
    assert joy_function(None)((0.0,) * 8, (0,) * 11)[1][1] == 0  # the shipped xbox map passes


def test_mapping_files_load_and_the_shipped_ones_parse(tmp_path):
    for name in ("xbox", "spacemouse", "keyboard"):
        m = shipped_mapping(name)
        assert m.buttons.keys() == {"mode", "enable", "escape", "choose", "grasp", "stop"}
    # (choose is published only where a mapping maps it: the pad's X, the keyboard's c;
    # the space mouse has two buttons)
    assert shipped_mapping("spacemouse").buttons["choose"] is None
    assert shipped_mapping("xbox").buttons["enable"] is not None  # a pad has a deadman
    # the pad's Y (SDL button 3) is stop: the message's stop field, not a button position
    xbox = shipped_mapping("xbox")
    held = Reading((0.0,) * 6, (0, 0, 0, 1) + (0,) * 7)
    assert xbox.stop(held) and not xbox.stop(Reading((0.0,) * 6, (0,) * 11))
    assert xbox.apply(held, 3)[1] == [0, 0, 0, 0, 0] and not shipped_mapping("spacemouse").stop(held)
    x_button = Reading((0.0,) * 6, (0, 0, 1) + (0,) * 8)  # the pad's X: choose, fourth
    assert xbox.apply(x_button, 3)[1] == [0, 0, 0, 1, 0]
    shoulder = Reading((0.0,) * 6, (0,) * 9 + (1, 0))  # the pad's left shoulder: grasp, fifth
    assert xbox.apply(shoulder, 3)[1] == [0, 0, 0, 0, 1]
    # choose (a skill set's next task) is the fourth position, where a file maps it
    f = tmp_path / "m.yaml"
    f.write_text("version: 1\naxes: [{source: 0}]\nbuttons: {enable: null, escape: 1, choose: 2}\n")
    assert load_mapping(f).apply(Reading((0.0,), (0, 0, 1)), 3)[1] == [0, 1, 0, 1]
    assert load_mapping(f).apply(Reading((0.0,), (0, 1, 0)), 3)[1] == [0, 1, 1, 0]
    f.write_text("version: 1\naxes: [{source: 2}]\n")
    assert load_mapping(f).apply(Reading((0.0, 0.0, -0.4)), 3)[0] == [-0.4, 0.0, 0.0]
    f.write_text("version: 1\naxes: [{source: 2}\n")
    with pytest.raises(InputError, match=r"m\.yaml: line 3: invalid YAML"):
        load_mapping(f)
    with pytest.raises(InputError, match=r"nothere\.yaml"):
        load_mapping(tmp_path / "nothere.yaml")


def test_pick_by_index_or_name():
    devs = [DeviceInfo(0, "Xbox Wireless Controller"), DeviceInfo(3, "PS5 DualSense")]
    assert pick(devs, None, "gamepad").index == 0
    assert pick(devs, "3", "gamepad").name == "PS5 DualSense"
    assert pick(devs, "dualsense", "gamepad").index == 3
    with pytest.raises(InputError, match=r"--device 'f310' matches none.*0: Xbox"):
        pick(devs, "f310", "gamepad")
    with pytest.raises(InputError, match="no device found"):
        pick([], None, "gamepad")


class _Scripted(InputDevice):
    """A device that returns the readings it is given (None: unplugged; an exception:
    raised by read)."""

    name = "scripted"

    def __init__(self, readings):
        self.readings = list(readings)
        self.closed = False

    def read(self):
        r = self.readings.pop(0) if self.readings else None
        if isinstance(r, Exception):
            raise r
        return r

    def close(self):
        self.closed = True


def test_bridge_publishes_zero_released_while_the_device_is_gone_and_on_exit():
    sent: list[codec.InputMsg] = []
    said: list[str] = []
    dev = _Scripted([Reading((0.5, -0.5, 0.0), (0, 1)), None, RuntimeError("USB error"),
                     Reading((float("nan"), 2.0, -3.0), (1, 1))])
    m = parse_mapping({"version": 1, "axes": [{"source": 0}, {"source": 1}, {"source": 2}],
                       "buttons": {"mode": 0, "enable": 1}}, "t")
    br = Bridge(dev, m, 3, lambda p: sent.append(codec.decode_input(p)), log=said.append)
    for _ in range(4):
        br.step()
    br.zero()
    assert [s.seq for s in sent] == list(range(1, 8))
    assert sent[0].u == (0.5, -0.5, 0.0) and sent[0].buttons == (0, 1, 0)
    for s in (sent[1], sent[2], *sent[4:]):  # gone, failed, and the zeros on exit
        assert s.u == (0.0, 0.0, 0.0) and list(s.buttons) == [0, 0, 0]
    assert sent[3].u == (0.0, 1.0, -1.0) and sent[3].buttons == (1, 1, 0)  # finite, clipped
    assert br.stats.errors == 1 and br.stats.disconnected == 2 and br.stats.connects == 2
    assert said[0] == "scripted: connected" and "disconnected" in said[1]
    assert "read failed: USB error" in said[2] and said[3] == "scripted: reconnected"


def test_bridge_run_keeps_its_rate_bounds_and_ends_with_zero():
    sent: list[codec.InputMsg] = []
    stop = threading.Event()
    dev = _Scripted([Reading((1.0, 0.0, 0.0))] * 1000)
    br = Bridge(dev, identity(), 3, lambda p: sent.append(codec.decode_input(p)), log=lambda s: None)
    with pytest.raises(ValueError, match="--rate"):
        run_bridge(br, 10.0, stop)

    def stop_after(b):
        if b.seq >= 5:
            stop.set()
    run_bridge(br, 200.0, stop, stop_after)
    assert [s.u[0] for s in sent[:5]] == [1.0] * 5
    assert [s.u for s in sent[-3:]] == [(0.0, 0.0, 0.0)] * 3 and sent[-1].buttons == (0, 0, 0)


@pytest.mark.slow
def test_every_builtin_backend_loads_and_plug_ins_register_by_entry_point(tmp_path):
    for name in BUILTIN:
        b = get_backend(name)
        assert b.name == name and b.help
        assert b.missing() is None, (name, b.missing())  # make setup installs sctd[inputs]
    with pytest.raises(InputError, match=r"unknown backend 'joy'.*gamepad, spacemouse"):
        get_backend("joy")
    # a plug-in: a distribution with an sctd.input entry point, on sys.path
    pkg = tmp_path / "sctd_fakedev.py"
    pkg.write_text(textwrap.dedent("""
        from sctd_services.input.device import Backend, DeviceInfo, InputDevice, Reading

        class Dev(InputDevice):
            name = "fake one"
            def read(self):
                return Reading((0.25, 0.0, 0.0))

        class Fake(Backend):
            name, help = "fakedev", "a registered test backend"
            def missing(self):
                return None
            def devices(self):
                return [DeviceInfo(0, "fake one")]
            def open(self, selector, args):
                return Dev()
    """))
    dist = tmp_path / "sctd_fakedev-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: sctd-fakedev\nVersion: 1.0\n")
    (dist / "entry_points.txt").write_text("[sctd.input]\nfakedev = sctd_fakedev:Fake\n")
    code = ("import sys; sys.path.insert(0, sys.argv[1]);"
            "from sctd_services.input import registry, list_backends;"
            "print(registry.backend_names()); print(registry.get_backend('fakedev').help);"
            "list_backends()")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path)], capture_output=True,
                         text=True, cwd=ROOT, timeout=120, check=True).stdout
    assert "'fakedev']" in out and "a registered test backend" in out
    assert "fakedev" in out and "0: fake one" in out


def _cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sctd.cli.main", "input", *args], capture_output=True,
                          text=True, cwd=ROOT, timeout=120, env={**__import__("os").environ,
                                                                 "SDL_VIDEODRIVER": "dummy"})


@pytest.mark.slow
def test_cli_refuses_bad_flags_and_files_with_exit_2(tmp_path):
    r = _cli("joy")
    assert r.returncode == 2 and "unknown backend 'joy'" in r.stderr and "gamepad" in r.stderr
    r = _cli()
    assert r.returncode == 2 and "give a BACKEND or --list" in r.stderr
    r = _cli("gamepad", "--rate", "5")
    assert r.returncode == 2 and "--rate: between 20 and 1000 Hz, got 5" in r.stderr
    bad = tmp_path / "bad.yaml"
    bad.write_text("version: 1\naxes: [{source: 0, deadband: 1.5}]\n")
    r = _cli("gamepad", "--map", str(bad))
    assert r.returncode == 2 and f"{bad}: axes[0].deadband: expected a number in [0, 1)" in r.stderr
    r = _cli("--list")
    assert r.returncode == 0, r.stderr
    names = [ln.split()[0] for ln in r.stdout.splitlines() if ln and not ln[0].isspace()]
    assert names[:4] == ["gamepad", "spacemouse", "emg", "keyboard"], r.stdout


@pytest.mark.slow
@pytest.mark.parametrize(("backend", "field", "have"), [
    ("keyboard", "buttons.enable", "buttons 0 to 4"),
    ("gamepad", "buttons.enable", "buttons 0 to 20"),
    ("spacemouse", "axes[0].source", "axes 0 to 5"),
])
def test_cli_refuses_a_button_or_axis_the_backend_lacks_before_it_starts(tmp_path, backend, field, have):
    """The keyboard took ``enable: 10**30`` and failed only later on its terminal; now
    every backend checks the file against its numbering before it opens anything."""
    bad = tmp_path / "huge.yaml"
    source = HUGE if field.startswith("axes") else 0
    enable = HUGE if field == "buttons.enable" else "null"
    bad.write_text(f"version: 1\naxes: [{{source: {source}}}]\nbuttons: {{enable: {enable}}}\n")
    r = _cli(backend, "--map", str(bad))
    assert r.returncode == 2, (r.returncode, r.stderr)
    kind = "axis" if field.startswith("axes") else "button"
    said = f"{bad}: {field}: {kind} {HUGE} is out of range: {backend} devices have {have}"
    assert said in r.stderr, r.stderr
    assert "terminal" not in r.stderr and "no game controller" not in r.stderr, r.stderr


@pytest.mark.parametrize(("buttons", "published"), [
    ("{enable: null, escape: 1}", ("mode", "enable", "escape")),
    ("{enable: null, choose: 2}", ("mode", "enable", "escape", "choose")),
    ("{enable: null, grasp: 3}", ("mode", "enable", "escape", "choose", "grasp")),
    ("{enable: 0, choose: 2, grasp: 3}", ("mode", "enable", "escape", "choose", "grasp")),
])
def test_grasp_is_the_fifth_position_after_a_choose_of_zero(tmp_path, buttons, published):
    """The wire contract's positions: grasp is buttons[4] where a file maps it, with
    choose (buttons[3]) 0 when choose is not mapped; the released message is as long."""
    f = tmp_path / "m.yaml"
    f.write_text(f"version: 1\naxes: [{{source: 0}}]\nbuttons: {buttons}\n")
    m = load_mapping(f)
    assert m.published == published and len(m.released()) == len(published)
    assert set(m.released()) == {0}
    out = m.apply(Reading((0.0,), (0, 0, 1, 1)), 3)[1]
    assert len(out) == len(published)
    assert out[:2] == [0, 1 if m.buttons["enable"] is None else 0]
    if "grasp" in published:
        assert out[4] == 1 and out[3] == (1 if m.buttons["choose"] == 2 else 0)


@settings(max_examples=100)
@given(pressed=st.lists(st.integers(0, 1), min_size=0, max_size=8), choose=st.none() | st.integers(0, 7),
       grasp=st.none() | st.integers(0, 7))
def test_every_role_lands_at_its_wire_position(pressed, choose, grasp):
    """For any device buttons and any choose/grasp numbers, each published position is
    its role's device button (enable held without one), and the positions are the wire
    contract's (codec.BUTTON_*)."""
    from sctd.wire.codec import BUTTON_CHOOSE, BUTTON_ENABLE, BUTTON_ESCAPE, BUTTON_GRASP, BUTTON_MODE

    roles = {"mode": 0, "enable": None, "escape": 1, "choose": choose, "grasp": grasp, "stop": None}
    m = Mapping((AxisMap(0),), roles)
    out = m.apply(Reading((0.0,), tuple(pressed)), 3)[1]

    def device(i):
        return 1 if i is not None and i < len(pressed) and pressed[i] else 0

    assert out[BUTTON_MODE] == device(0) and out[BUTTON_ENABLE] == 1 and out[BUTTON_ESCAPE] == device(1)
    assert len(out) == 3 + (choose is not None or grasp is not None) + (grasp is not None)
    if len(out) > BUTTON_CHOOSE:
        assert out[BUTTON_CHOOSE] == device(choose)
    if grasp is not None:
        assert out[BUTTON_GRASP] == device(grasp)
    assert len(m.released()) == len(out)
