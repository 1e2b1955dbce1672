"""The SpaceMouse backend: its report parser on known reports, the device through a fake
HID reader (draining, unplug, reopen), the bridge through it, ``--list`` and an end-to-end
run of ``sctd input spacemouse --fake-hid`` publishing six axes on loopback."""

from __future__ import annotations

import struct
import subprocess
import sys
import threading
import time

import pytest

from sctd.wire import DEFAULT_ROBOT, Keys, codec
from sctd.wire.session import close_session, open_session
from sctd_services.input.bridge import Bridge
from sctd_services.input.mapping import shipped_mapping
from sctd_services.input.spacemouse import (
    GENERIC,
    MODELS,
    HidScript,
    Model,
    ReportParser,
    SpaceMouse,
    SpaceMouseDevice,
)

from .conftest import ROOT, Proc, free_port, wait_for


def translation(x: int, y: int, z: int) -> bytes:
    return b"\x01" + struct.pack("<3h", x, y, z)


def rotation(rx: int, ry: int, rz: int) -> bytes:
    return b"\x02" + struct.pack("<3h", rx, ry, rz)


def joined(*six: int) -> bytes:
    return b"\x01" + struct.pack("<6h", *six)


def buttons(mask: int, n_bytes: int = 1) -> bytes:
    return b"\x03" + mask.to_bytes(n_bytes, "little")


class Clock:
    """A scripted monotonic clock."""

    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class FakeHid:
    """The read(size)/close of a ``hid.device``: scripted reports, then [] (nothing
    pending); ``fail`` makes the next read raise as an unplugged device's does."""

    def __init__(self, reports: list[bytes]):
        self.reports = list(reports)
        self.fail = False
        self.closed = False
        self.sizes: list[int] = []

    def read(self, size: int) -> list[int]:
        self.sizes.append(size)
        if self.fail:
            raise OSError("read error")
        return list(self.reports.pop(0)) if self.reports else []

    def close(self) -> None:
        self.closed = True


# --- the parser ------------------------------------------------------------------------

def test_separate_translation_and_rotation_reports_with_signs():
    p = ReportParser(Model("t", 2, 350))
    assert p.feed(translation(350, 350, 350))
    assert p.axes() == (1.0, -1.0, -1.0, 0.0, 0.0, 0.0)  # HID y toward user, z down
    assert p.feed(rotation(350, 350, 350))
    assert p.axes() == (1.0, -1.0, -1.0, 1.0, -1.0, -1.0)
    assert p.feed(translation(-175, 0, 70))  # rotation kept from its own report
    assert p.axes() == (-0.5, 0.0, -0.2, 1.0, -1.0, -1.0)
    assert p.raw == [-175, 0, 70, 350, 350, 350]
    assert (p.parsed, p.ignored) == (3, 0)


def test_joined_thirteen_byte_report_carries_all_six_axes():
    p = ReportParser(Model("t", 2, 350))
    assert p.feed(joined(35, -70, 105, -140, 175, -350))
    assert p.axes() == pytest.approx((0.1, 0.2, -0.3, -0.4, -0.5, 1.0))


def test_range_is_per_model_and_values_are_clipped():
    assert ReportParser(Model("t", 2, 500)).axes() == (0.0,) * 6
    p = ReportParser(Model("wide", 2, 500))
    p.feed(joined(250, -500, 700, -32768, 32767, 0))
    assert p.axes() == (0.5, 1.0, -1.0, -1.0, -1.0, 0.0)
    assert all(m.range > 0 for m in MODELS.values())


def test_buttons_by_bit_across_bytes():
    p = ReportParser(Model("two", 2))
    assert p.buttons() == (0, 0)
    p.feed(buttons(0b10))
    assert p.buttons() == (0, 1)
    p.feed(buttons(0b01))
    assert p.buttons() == (1, 0)  # the newest report replaces the state
    pro = ReportParser(MODELS[(0x256F, 0xC631)])  # Pro Wireless: 15 buttons
    pro.feed(buttons((1 << 0) | (1 << 9) | (1 << 14), 4))
    b = pro.buttons()
    assert len(b) == 15 and [k for k, v in enumerate(b) if v] == [0, 9, 14]


@pytest.mark.parametrize("report", [b"", b"\x01", b"\x01\x00\x00\x00\x00\x00",
                                    b"\x02\x10\x00", b"\x03", b"\x09" + bytes(12)])
def test_malformed_or_unknown_report_is_ignored_and_counted(report):
    p = ReportParser(GENERIC)
    p.feed(translation(100, 0, 0))
    before = (p.axes(), p.buttons())
    assert p.feed(report) is False
    assert (p.axes(), p.buttons()) == before
    assert (p.parsed, p.ignored) == (1, 1)


# --- the device through a fake HID reader ----------------------------------------------

def test_read_drains_pending_reports_and_keeps_the_newest():
    hid = FakeHid([translation(10, 0, 0), rotation(0, 0, 35), translation(20, 0, 0),
                   b"\x07junk", buttons(1), translation(35, 0, 0)])
    dev = SpaceMouseDevice(lambda: hid, "fake", Model("t", 2, 350))
    r = dev.read()
    assert r is not None
    assert r.axes == pytest.approx((0.1, 0.0, 0.0, 0.0, 0.0, -0.1))
    assert r.buttons == (1, 0)
    assert hid.reports == [] and len(hid.sizes) == 7  # six reports, then the empty read
    assert (dev.parser.parsed, dev.parser.ignored) == (5, 1)
    again = dev.read()  # nothing pending: the same state
    assert again is not None and again.axes == r.axes


def test_read_error_gives_none_then_reopens_after_the_retry_time():
    clock = Clock()
    handles = [FakeHid([translation(350, 0, 0)]), FakeHid([translation(0, 175, 0)])]
    opened: list[FakeHid] = []
    unplugged = [False]

    def opener() -> FakeHid:
        if unplugged[0]:
            raise OSError("not connected")
        opened.append(handles[len(opened)])
        return opened[-1]

    dev = SpaceMouseDevice(opener, "fake", Model("t", 2, 350), retry_s=1.0, clock=clock)
    r = dev.read()
    assert r is not None and r.axes[0] == 1.0
    handles[0].fail = True
    unplugged[0] = True
    assert dev.read() is None
    assert handles[0].closed
    clock.t += 1.5
    assert dev.read() is None  # the opener failed: still gone, tried again later
    unplugged[0] = False
    clock.t += 0.5
    assert dev.read() is None and len(opened) == 1  # not before the retry time
    clock.t += 0.6
    r = dev.read()
    assert r is not None and len(opened) == 2 and dev.reopens == 1
    assert r.axes[:2] == (0.0, -0.5)  # the new handle's state, not the stale one
    dev.close()
    assert handles[1].closed
    assert dev.read() is None  # closed for good


def test_bridge_through_the_fake_hid_maps_and_zeroes_on_unplug():
    clock = Clock()
    script = HidScript([(0.0, joined(350, 0, -350, 0, 0, 175)), (0.0, buttons(0b11)),
                        (1.0, None), (2.5, joined(0, 0, 0, 0, 0, 0))], clock)
    dev = SpaceMouseDevice(script.open, "fake", GENERIC, retry_s=1.0, clock=clock)
    sent: list[codec.InputMsg] = []
    bridge = Bridge(dev, shipped_mapping("spacemouse"), 6,
                    lambda b: sent.append(codec.decode_input(b)), log=lambda s: None)
    bridge.step()
    assert sent[-1].u == pytest.approx((1.0, 0.0, 1.0, 0.0, 0.0, -(0.5 - 0.08) / 0.92))
    assert sent[-1].buttons == (1, 1, 1)  # mode (left), enable held (no deadman), escape (right)
    clock.t += 1.0
    bridge.step()  # the scripted unplug
    assert sent[-1].u == (0.0,) * 6 and sent[-1].buttons == (0, 0, 0)
    clock.t += 1.6
    bridge.step()  # reopened
    assert sent[-1].u == (0.0,) * 6 and sent[-1].buttons == (0, 1, 0)
    assert bridge.stats.events == ["fake: connected", "fake: disconnected; publishing zero "
                                   "until it is back", "fake: reconnected"]


def test_hid_script_parse_names_the_bad_line(tmp_path):
    s = HidScript.parse("# comment\n0.0 01 5e01 0000 0000\n\n0.5 error\n", "s.txt")
    assert s.entries == [(0.0, translation(350, 0, 0)), (0.5, None)]
    with pytest.raises(Exception, match=r"s\.txt:2: expected"):
        HidScript.parse("0 01\nlater zz\n", "s.txt")


# --- the backend and the command --------------------------------------------------------

def test_backend_needs_hidapi_and_lists_none_here():
    b = SpaceMouse()
    assert b.missing() is None  # the inputs extra is installed
    assert b.devices() == []  # no 3Dconnexion device (and no /dev/hidraw) on this machine


@pytest.mark.slow
def test_list_names_spacemouse_with_no_device_and_keyboard():
    out = subprocess.run([sys.executable, "-m", "sctd_services.input", "--list"], cwd=ROOT,
                         capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    k = next(i for i, line in enumerate(lines) if line.startswith("spacemouse "))
    assert lines[k + 1].strip() == "no device found"
    assert any(line.startswith("keyboard ") for line in lines)


@pytest.mark.slow
def test_fake_hid_end_to_end_publishes_six_axes_following_the_script(tmp_path):
    a = (175, -175, 350, -350, 0, 35)  # -> 0.5, 0.5, -1, -1, 0, -0.1 (y, z, ry, rz flip)
    b = (0, 350, 0, 0, 350, 0)
    script = tmp_path / "reports.txt"
    script.write_text(f"0.0 {joined(*a).hex()}\n"
                      f"3.0 {joined(*b).hex()}\n3.0 {buttons(0b01).hex()}\n"
                      "5.0 error\n"
                      f"6.5 {joined(0, 0, 0, 0, 0, 0).hex()}\n6.5 {buttons(0).hex()}\n")
    port = free_port()
    ep = f"tcp/127.0.0.1:{port}"
    seen: list[codec.InputMsg] = []
    lock = threading.Lock()

    def on_sample(sample) -> None:
        with lock:
            seen.append(codec.decode_input(sample.payload.to_bytes()))

    def d(x: float) -> float:  # the shipped map's dead band, 0.08, rescaled
        return (abs(x) - 0.08) / 0.92 * (1 if x > 0 else -1)

    ua = pytest.approx((d(0.5), d(0.5), -1.0, -1.0, 0.0, d(-0.1)))
    ub = pytest.approx((0.0, -1.0, 0.0, 0.0, -1.0, 0.0))
    zero = (0.0,) * 6

    def kinds() -> list[str]:
        out: list[str] = []
        with lock:
            msgs = list(seen)
        for m in msgs:
            kind = ("a" if m.u == ua and m.buttons == (0, 1, 0) else
                    "b" if m.u == ub and m.buttons == (1, 1, 0) else
                    "gone" if m.u == zero and m.buttons == (0, 0, 0) else
                    "back" if m.u == zero and m.buttons == (0, 1, 0) else f"? {m}")
            if not out or out[-1] != kind:
                out.append(kind)
        return out

    s = open_session(listen=[ep])
    try:
        sub = s.declare_subscriber(Keys(DEFAULT_ROBOT).input("spacemouse"), on_sample)
        with Proc("sctd_services.input", "spacemouse", "--fake-hid", str(script), "--axes", "6",
                  "--connect", ep, log=tmp_path / "input.log") as child:
            wait_for(lambda: "back" in kinds(), 40)
            rc = child.stop()
            log = child.output()
        time.sleep(0.3)
        sub.undeclare()
    finally:
        close_session(s)
    assert rc == 0, log
    assert all(len(m.u) == 6 for m in seen)
    assert kinds() == ["a", "b", "gone", "back", "gone"], (kinds(), log)  # last: zero on exit
    assert [m.seq for m in seen] == sorted(m.seq for m in seen)
    assert "reconnected" in log


class FakeHidModule:
    """Stands in for the ``hid`` module: enumerate() and device() over a list of
    attached devices (dicts as hidapi gives them), each with its pending reports."""

    def __init__(self) -> None:
        self.attached: list[dict] = []
        self.reports: dict[bytes, list[bytes]] = {}
        self.opened: list[FakeHidModule.Device] = []
        mod = self

        class Device:
            def __init__(self) -> None:
                self.path: bytes | None = None
                self.nonblocking = 0
                mod.opened.append(self)

            def open_path(self, path: bytes) -> None:
                if not any(d["path"] == path for d in mod.attached):
                    raise OSError("open failed")
                self.path = path

            def set_nonblocking(self, v: int) -> None:
                self.nonblocking = v

            def read(self, size: int) -> list[int]:
                if not any(d["path"] == self.path for d in mod.attached):
                    raise OSError("read error")
                pending = mod.reports.setdefault(self.path, [])
                return list(pending.pop(0)) if pending else []

            def close(self) -> None:
                self.path = None

        self.Device = Device

    def enumerate(self, vid: int = 0, pid: int = 0) -> list[dict]:
        return [d for d in self.attached if vid in (0, d["vendor_id"]) and pid in (0, d["product_id"])]

    def device(self):
        return self.Device()


def hid_info(path: bytes, pid: int = 0xC635, serial: str = "S1", usage: tuple = (1, 8)) -> dict:
    return {"path": path, "vendor_id": 0x256F, "product_id": pid, "serial_number": serial,
            "product_string": "", "usage_page": usage[0], "usage": usage[1]}


def test_devices_and_open_through_hidapi_reopen_by_serial_on_a_new_path(monkeypatch):
    fake = FakeHidModule()
    monkeypatch.setitem(sys.modules, "hid", fake)
    fake.attached = [
        {**hid_info(b"/dev/hidraw9"), "vendor_id": 0x046D, "product_id": 0xC52B},  # a receiver
        hid_info(b"/dev/hidraw3", usage=(12, 1)),  # the Compact's consumer-control interface
        hid_info(b"/dev/hidraw2"),
    ]
    b = SpaceMouse()
    listed = b.devices()
    assert [(d.index, d.name) for d in listed] == [(0, "SpaceMouse Compact")]
    assert listed[0].detail == "256f:c635 /dev/hidraw2 serial S1"
    dev = b.open("compact", argparse_ns())
    assert fake.opened[-1].path == b"/dev/hidraw2" and fake.opened[-1].nonblocking == 1
    fake.reports[b"/dev/hidraw2"] = [translation(0, 0, 350), buttons(0b10)]
    r = dev.read()
    assert r is not None and r.axes[2] == -1.0 and r.buttons == (0, 1)
    fake.attached = []  # unplugged
    assert dev.read() is None
    fake.attached = [hid_info(b"/dev/hidraw5")]  # plugged back: another node, same serial
    fake.reports[b"/dev/hidraw5"] = [rotation(0, 0, 350)]
    assert wait_for(lambda: dev.read() is not None, 5)
    r = dev.read()
    assert fake.opened[-1].path == b"/dev/hidraw5"
    assert r is not None and r.axes == (0.0, 0.0, 0.0, 0.0, 0.0, -1.0)
    dev.close()
    with pytest.raises(Exception, match=r"--device 'pro' matches none"):
        b.open("pro", argparse_ns())


def argparse_ns(**kw):
    import argparse

    return argparse.Namespace(fake_hid=None, **kw)
