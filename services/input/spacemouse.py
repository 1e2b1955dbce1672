"""3Dconnexion SpaceMouse devices over HID (``docs/input-spacemouse.md``).

The device is read through hidapi (the ``hidapi`` wheel bundles its C library, so no
system package or driver is needed); the reports are parsed here, by
:class:`ReportParser`, which imports nothing and is tested on scripted bytes.

Reports (the first byte is the report id, values are int16 little-endian):

- id 1, 7 bytes: translation x, y, z (SpaceNavigator, SpaceMouse Pro, Compact and the
  other cabled devices, which send the rotation apart in report 2);
- id 1, 13 bytes: translation and rotation together (SpaceMouse Wireless, Pro Wireless,
  Enterprise and the Universal Receiver);
- id 2, 7 bytes: rotation rx, ry, rz;
- id 3: buttons, one bit each, bit 0 of the first byte is button 0.

Anything else (another id, a short report) is ignored and counted.

Axes published (each in [-1, 1], raw / the model's range, clipped), right-handed with
the user in front of the device: x to the right, y away from the user, z up; rx, ry, rz
about those axes by the right-hand rule. The HID reports have y toward the user and z
down (pushing the cap gives +z raw), so y, z, ry and rz change sign here: pushing the
cap forward gives +y, lifting it +z, tilting its front down (pitch forward) -rx,
twisting it counter-clockwise seen from above +rz.
"""

from __future__ import annotations

import argparse
import struct
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

from .device import Backend, DeviceInfo, InputDevice, InputError, Reading, pick

VENDOR_LOGITECH = 0x046D  # 3Dconnexion was a Logitech company until 2011
VENDOR_3DCONNEXION = 0x256F
RANGE_TYPICAL = 350  # the raw value at full deflection on the devices in MODELS

REPORT_TRANSLATION, REPORT_ROTATION, REPORT_BUTTONS = 1, 2, 3
SIGNS = (1, -1, -1, 1, -1, -1)  # HID frame (y toward the user, z down) -> ours
MAX_REPORT = 64  # bytes asked per hid read; SpaceMouse reports are at most 13
MAX_DRAIN = 256  # reports taken per read(): a device sends ~60-120 a second
RETRY_S = 1.0  # seconds between attempts to reopen an unplugged device


@dataclass(frozen=True)
class Model:
    """One SpaceMouse model: its name, its buttons and the raw value at full deflection."""

    name: str
    buttons: int
    range: int = RANGE_TYPICAL


# (vendor id, product id) -> model. Ids as the Linux kernel's hid-ids.h, spacenavd and
# pyspacemouse list them; button counts as the devices' HID descriptors report them.
MODELS: dict[tuple[int, int], Model] = {
    (VENDOR_LOGITECH, 0xC603): Model("SpaceMouse Plus XT USB", 11),
    (VENDOR_LOGITECH, 0xC605): Model("CADman", 4),
    (VENDOR_LOGITECH, 0xC606): Model("SpaceMouse Classic USB", 8),
    (VENDOR_LOGITECH, 0xC621): Model("SpaceBall 5000 USB", 12),
    (VENDOR_LOGITECH, 0xC623): Model("SpaceTraveler", 8),
    (VENDOR_LOGITECH, 0xC625): Model("SpacePilot", 21),
    (VENDOR_LOGITECH, 0xC626): Model("SpaceNavigator", 2),
    (VENDOR_LOGITECH, 0xC627): Model("SpaceExplorer", 15),
    (VENDOR_LOGITECH, 0xC628): Model("SpaceNavigator for Notebooks", 2),
    (VENDOR_LOGITECH, 0xC629): Model("SpacePilot Pro", 31),
    (VENDOR_LOGITECH, 0xC62B): Model("SpaceMouse Pro", 15),
    (VENDOR_3DCONNEXION, 0xC62E): Model("SpaceMouse Wireless (cabled)", 2),
    (VENDOR_3DCONNEXION, 0xC62F): Model("SpaceMouse Wireless (receiver)", 2),
    (VENDOR_3DCONNEXION, 0xC631): Model("SpaceMouse Pro Wireless (cabled)", 15),
    (VENDOR_3DCONNEXION, 0xC632): Model("SpaceMouse Pro Wireless (receiver)", 15),
    (VENDOR_3DCONNEXION, 0xC633): Model("SpaceMouse Enterprise", 31),
    (VENDOR_3DCONNEXION, 0xC635): Model("SpaceMouse Compact", 2),
    (VENDOR_3DCONNEXION, 0xC652): Model("3Dconnexion Universal Receiver", 2),
}
GENERIC = Model("SpaceMouse", 2)  # used by the fake HID and --fake-hid


class ReportParser:
    """The device's state built up from its HID reports (pure: bytes in, numbers out).

    Parameters
    ----------
    model : Model
        Its range (raw value at full deflection) and how many buttons a reading carries.

    Attributes
    ----------
    raw : list of int, shape (6,)
        The newest raw values, HID frame: tx, ty, tz, rx, ry, rz.
    mask : int
        The newest button bits (bit k = button k).
    parsed, ignored : int
        Reports used and reports ignored (unknown id, too short).
    """

    def __init__(self, model: Model = GENERIC):
        self.model = model
        self.raw = [0] * 6
        self.mask = 0
        self.parsed = 0
        self.ignored = 0

    def feed(self, report: bytes) -> bool:
        """Take one report (report id first); False when it was ignored."""
        rid = report[0] if report else -1
        if rid == REPORT_TRANSLATION and len(report) >= 13:
            self.raw[:] = struct.unpack_from("<6h", report, 1)
        elif rid == REPORT_TRANSLATION and len(report) >= 7:
            self.raw[0:3] = struct.unpack_from("<3h", report, 1)
        elif rid == REPORT_ROTATION and len(report) >= 7:
            self.raw[3:6] = struct.unpack_from("<3h", report, 1)
        elif rid == REPORT_BUTTONS and len(report) >= 2:
            self.mask = int.from_bytes(report[1:5], "little")
        else:
            self.ignored += 1
            return False
        self.parsed += 1
        return True

    def axes(self) -> tuple[float, ...]:
        """x, y, z, rx, ry, rz in [-1, 1], our frame (module docstring)."""
        r = float(self.model.range)
        return tuple(max(-1.0, min(1.0, s * v / r)) for s, v in zip(SIGNS, self.raw, strict=True))

    def buttons(self) -> tuple[int, ...]:
        """Button k is bit k of the buttons report (as many as the model has)."""
        return tuple((self.mask >> k) & 1 for k in range(self.model.buttons))

    def reading(self, stamp: float) -> Reading:
        return Reading(self.axes(), self.buttons(), stamp)


class HidHandle(Protocol):
    """What the device uses of an open ``hid.device``."""

    def read(self, max_length: int) -> list[int]: ...

    def close(self) -> None: ...


class SpaceMouseDevice(InputDevice):
    """An open SpaceMouse: drains the pending reports on each :meth:`read`, reopens
    itself after an unplug.

    Parameters
    ----------
    opener : callable
        Opens the device (non-blocking) and returns its handle; raises OSError when it
        is not there. Called again, every ``retry_s``, after a read error.
    name : str
    model : Model
    retry_s : float
        Seconds between reopen attempts.
    clock : callable
        Monotonic seconds (injected by the tests).
    """

    axes = 6

    def __init__(self, opener: Callable[[], HidHandle], name: str, model: Model,
                 retry_s: float = RETRY_S, clock: Callable[[], float] = time.monotonic):
        self.name = name
        self.buttons = model.buttons
        self.parser = ReportParser(model)
        self._opener = opener
        self._retry_s = retry_s
        self._clock = clock
        self._hid: HidHandle | None = opener()
        self._next_try = 0.0
        self.reopens = 0

    def read(self) -> Reading | None:
        if self._hid is None and not self._reopen():
            return None
        assert self._hid is not None
        try:
            for _ in range(MAX_DRAIN):
                report = self._hid.read(MAX_REPORT)
                if not report:
                    break
                self.parser.feed(bytes(report))
        except (OSError, ValueError):  # hidapi raises OSError (ValueError when closed)
            self._drop()
            return None
        return self.parser.reading(time.time())

    def _reopen(self) -> bool:
        now = self._clock()
        if now < self._next_try:
            return False
        try:
            self._hid = self._opener()
        except OSError:
            self._next_try = now + self._retry_s
            return False
        self.reopens += 1
        self.parser = ReportParser(self.parser.model)  # the old state is stale
        return True

    def _drop(self) -> None:
        hid, self._hid = self._hid, None
        self._next_try = self._clock() + self._retry_s
        if hid is not None:
            try:
                hid.close()
            except (OSError, ValueError):
                pass

    def close(self) -> None:
        hid, self._hid = self._hid, None
        self._next_try = float("inf")  # closed for good
        if hid is not None:
            hid.close()


class HidScript:
    """Scripted reports for ``--fake-hid FILE`` (and the tests): one line per report,
    ``SECONDS HEX`` (delivered once that long has passed since the first open), or
    ``SECONDS error`` (that read fails, as an unplug does); ``#`` starts a comment.

    ::

        0.0  01 5e01 0000 0000     # translation x = +350
        0.5  error                 # unplugged; the device reopens after RETRY_S
    """

    def __init__(self, entries: list[tuple[float, bytes | None]],
                 clock: Callable[[], float] = time.monotonic):
        self.entries = entries
        self.pos = 0
        self.clock = clock
        self.t0: float | None = None

    @classmethod
    def parse(cls, text: str, origin: str, clock: Callable[[], float] = time.monotonic) -> HidScript:
        entries: list[tuple[float, bytes | None]] = []
        for n, line in enumerate(text.splitlines(), 1):
            line = line.split("#", 1)[0].strip()
            if not line:
                continue
            t, _, rest = line.partition(" ")
            try:
                at = float(t)
                data = None if rest.strip() == "error" else bytes.fromhex(rest)
            except ValueError as e:
                raise InputError(f"{origin}:{n}: expected 'SECONDS HEX' or 'SECONDS error': {e}") from e
            entries.append((at, data))
        return cls(entries, clock)

    def open(self) -> ScriptedHid:
        if self.t0 is None:
            self.t0 = self.clock()
        return ScriptedHid(self)


class ScriptedHid:
    """A fake ``hid.device`` (its read(size)/close) reading a :class:`HidScript`."""

    def __init__(self, script: HidScript):
        self.script = script
        self.closed = False

    def read(self, max_length: int) -> list[int]:
        if self.closed:
            raise ValueError("read on a closed device")
        s = self.script
        assert s.t0 is not None
        if s.pos >= len(s.entries) or s.entries[s.pos][0] > s.clock() - s.t0:
            return []
        _, data = s.entries[s.pos]
        s.pos += 1
        if data is None:
            raise OSError("read error (scripted unplug)")
        return list(data[:max_length])

    def close(self) -> None:
        self.closed = True


def _is_spacemouse(info: dict[str, Any]) -> bool:
    return (info.get("vendor_id"), info.get("product_id")) in MODELS


def _not_motion(info: dict[str, Any]) -> bool:
    """False for the interface that sends the motion: a device with several HID
    interfaces is listed once per interface, its multi-axis controller (usage page 1,
    usage 8) is the one to open. (A platform that reports no usage gives 0, 0 for all.)"""
    return (info.get("usage_page"), info.get("usage")) not in ((1, 8), (0, 0), (None, None))


class SpaceMouse(Backend):
    """3Dconnexion SpaceMouse devices through hidapi."""

    name = "spacemouse"
    help = "3Dconnexion SpaceMouse over HID (hidapi): 6 axes, its buttons"
    library = "hidapi"
    default_map = "spacemouse"
    device_axes = 6
    device_buttons = max(m.buttons for m in MODELS.values())  # the model is known once opened

    def add_arguments(self, group: argparse._ArgumentGroup) -> None:
        group.add_argument("--fake-hid", metavar="FILE", help=argparse.SUPPRESS)

    def missing(self) -> str | None:
        try:
            import hid  # noqa: F401
        except ImportError:
            return "needs hidapi: pip install 'sctd[inputs]'"
        return None

    def _enumerate(self) -> list[dict[str, Any]]:
        import hid

        found = [d for d in hid.enumerate() if _is_spacemouse(d)]
        seen: dict[tuple[Any, ...], dict[str, Any]] = {}
        for d in sorted(found, key=_not_motion):
            seen.setdefault((d["vendor_id"], d["product_id"], d.get("serial_number")), d)
        return list(seen.values())

    def devices(self) -> list[DeviceInfo]:
        return _infos(self._enumerate())

    def open(self, selector: str | None, args: argparse.Namespace) -> InputDevice:
        fake = getattr(args, "fake_hid", None)
        if fake:
            try:
                text = Path(fake).read_text()
            except OSError as e:
                raise InputError(f"--fake-hid {fake}: {e.strerror or e}") from e
            script = HidScript.parse(text, fake)
            return SpaceMouseDevice(script.open, f"fake HID {Path(fake).name}", GENERIC)
        found = self._enumerate()
        chosen = pick(_infos(found), selector, self.name)
        hid_info = found[chosen.index]
        model = MODELS[(hid_info["vendor_id"], hid_info["product_id"])]
        try:
            return SpaceMouseDevice(_hid_opener(hid_info), chosen.name, model)
        except OSError as e:
            raise InputError(f"spacemouse: cannot open {chosen.name} ({chosen.detail}): {e}; "
                             "on Linux the hidraw node needs read access (a udev rule)") from e


def _infos(found: list[dict[str, Any]]) -> list[DeviceInfo]:
    """What --list prints of hid.enumerate()'s entries."""
    out = []
    for k, d in enumerate(found):
        model = MODELS[(d["vendor_id"], d["product_id"])]
        path = d.get("path", b"")
        path = path.decode(errors="replace") if isinstance(path, bytes) else str(path)
        detail = f"{d['vendor_id']:04x}:{d['product_id']:04x} {path}"
        if d.get("serial_number"):
            detail += f" serial {d['serial_number']}"
        out.append(DeviceInfo(k, d.get("product_string") or model.name, detail))
    return out


def _hid_opener(info: dict[str, Any]) -> Callable[[], HidHandle]:
    """Opens the device ``info`` describes, found again by its serial number (else its
    path) after an unplug: a replugged device may get another path."""
    import hid

    vid, pid, serial, path = (info["vendor_id"], info["product_id"], info.get("serial_number"),
                              info.get("path"))

    def opener() -> HidHandle:
        now = sorted((d for d in hid.enumerate(vid, pid)
                      if (serial and d.get("serial_number") == serial) or d.get("path") == path),
                     key=lambda d: (_not_motion(d), d.get("path") != path))
        if not now:
            raise OSError(f"{vid:04x}:{pid:04x} is not connected")
        h = hid.device()
        h.open_path(now[0]["path"])
        h.set_nonblocking(1)
        return h

    return opener
