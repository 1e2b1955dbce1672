"""The mapping file: which device axis drives each output axis (scale, inversion, dead
band) and which device buttons are ``mode``, ``enable``, ``escape``, ``choose``,
``grasp`` and ``stop`` (``docs/input.md``).

::

    version: 1
    axes:                 # u[0], u[1], u[2] (and u[3..5] with --axes 6)
      - {source: 0}                            # device axis 0 as it is
      - {source: 1, invert: true, deadband: 0.1}
      - {source: [5, 4], scale: 0.8}           # axis 5 minus axis 4 (two triggers)
    buttons: {mode: 0, enable: null, escape: 1, choose: 2, grasp: 4, stop: 3}

An output axis is ``clip(scale * s * d(x), -1, 1)`` with ``s`` = -1 when inverted and
``d`` the dead band rescaled so the output still starts from zero at its edge:
``d(x) = sign(x) (|x| - b) / (1 - b)`` for ``|x| > b``, else 0. A button names a device
button by its number, or null: ``enable: null`` publishes enable held (the device has
no deadman), ``mode``/``escape``/``choose``/``grasp``/``stop`` null (or absent) never
press them. The published ``buttons`` are by the wire contract's positions: ``[mode,
enable, escape]``, ``choose`` (a skill set's next member) fourth when it is mapped, and
``grasp`` (the gripper: close, or open when held) fifth when it is mapped, after a
``choose`` of 0 when choose is not; ``stop`` is published as the message's ``stop``
field (it halts every device's motion).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from sctd.files import FileError, load_yaml, parse_yaml

from .device import InputError, Reading

VERSION = 1
ROLES = ("mode", "enable", "escape")  # the wire contract's button positions 0, 1, 2
CHOOSE = "choose"  # position 3, published when it or grasp is mapped
GRASP = "grasp"  # position 4, published only when mapped
STOP = "stop"  # the wire contract's stop field
KNOWN = (*ROLES, CHOOSE, GRASP, STOP)
MAX_AXES = 6


@dataclass(frozen=True)
class AxisMap:
    """One output axis: device axis ``source`` (minus ``minus`` when set)."""

    source: int
    minus: int | None = None
    scale: float = 1.0
    invert: bool = False
    deadband: float = 0.0

    def __call__(self, axes: tuple[float, ...]) -> float:
        x = _at(axes, self.source) - (_at(axes, self.minus) if self.minus is not None else 0.0)
        x = max(-1.0, min(1.0, x))
        b = self.deadband
        if abs(x) <= b:
            return 0.0
        x = math.copysign((abs(x) - b) / (1.0 - b), x)
        x *= -self.scale if self.invert else self.scale
        return max(-1.0, min(1.0, x))


def _at(axes: tuple[float, ...], i: int) -> float:
    """Axis ``i``, 0 when the device has fewer or it is not finite."""
    x = axes[i] if i < len(axes) else 0.0
    return x if math.isfinite(x) else 0.0


@dataclass(frozen=True)
class Mapping:
    """Output axes and button roles; :meth:`apply` maps one :class:`Reading`."""

    axes: tuple[AxisMap, ...]
    buttons: dict[str, int | None]
    origin: str = "identity"

    @property
    def published(self) -> tuple[str, ...]:
        """The roles of the published ``buttons``, by position: ``mode, enable, escape``,
        then ``choose`` when choose or grasp is mapped, then ``grasp`` when it is."""
        grasp = self.buttons.get(GRASP) is not None
        if grasp:
            return (*ROLES, CHOOSE, GRASP)
        return (*ROLES, CHOOSE) if self.buttons.get(CHOOSE) is not None else ROLES

    def apply(self, reading: Reading, n_axes: int) -> tuple[list[float], list[int]]:
        """``u`` (``n_axes`` values in [-1, 1]) and the buttons by :attr:`published`
        (``[mode, enable, escape]``, ``choose`` and ``grasp`` where mapped)."""
        u = [m(reading.axes) for m in self.axes[:n_axes]]
        u += [0.0] * (n_axes - len(u))
        return u, [self._button(reading.buttons, r) for r in self.published]

    def released(self) -> list[int]:
        """The buttons of a message with nothing pressed and the deadman released (the
        device gone, the bridge exiting): as many as :meth:`apply` publishes."""
        return [0] * len(self.published)

    def stop(self, reading: Reading) -> bool:
        """Whether the button mapped to ``stop`` is held (never, when none is)."""
        return bool(self._button(reading.buttons, STOP))

    def _button(self, buttons: tuple[int, ...], role: str) -> int:
        i = self.buttons.get(role)
        if i is None:
            return 1 if role == "enable" else 0
        return 1 if i < len(buttons) and buttons[i] else 0


def identity(n_axes: int = MAX_AXES) -> Mapping:
    """Device axis k to output axis k; no buttons mapped (enable held)."""
    return Mapping(tuple(AxisMap(k) for k in range(n_axes)), dict.fromkeys(KNOWN), "identity")


def parse_mapping(doc: Any, origin: str) -> Mapping:
    """A mapping from a parsed YAML document; InputError ``origin: field: problem``."""
    def bad(where: str, what: str) -> InputError:
        return InputError(f"{origin}: {where}: {what}")

    if not isinstance(doc, dict):
        raise bad("(top)", "expected a map with version, axes and buttons")
    unknown = set(doc) - {"version", "device", "axes", "buttons"}
    if unknown:
        raise bad(sorted(map(str, unknown))[0], "unknown field (known: version, device, axes, buttons)")
    if doc.get("version") != VERSION:
        raise bad("version", f"expected {VERSION}, got {doc.get('version')!r}")
    raw_axes = doc.get("axes")
    if not isinstance(raw_axes, list) or not 1 <= len(raw_axes) <= MAX_AXES:
        raise bad("axes", f"expected a list of 1 to {MAX_AXES} axis maps")
    axes = tuple(_axis(a, f"axes[{k}]", bad) for k, a in enumerate(raw_axes))
    raw_buttons = doc.get("buttons", {}) or {}
    if not isinstance(raw_buttons, dict):
        raise bad("buttons", "expected a map of mode, enable, escape, choose, grasp, stop to button numbers "
                             "or null")
    for k in raw_buttons:
        if k not in KNOWN:
            raise bad(f"buttons.{k}", f"unknown role (known: {', '.join(KNOWN)})")
    buttons: dict[str, int | None] = {}
    for role in KNOWN:
        v = raw_buttons.get(role)
        if v is not None and (type(v) is not int or v < 0):
            raise bad(f"buttons.{role}", f"expected a button number >= 0 or null, got {v!r}")
        buttons[role] = v
    return Mapping(axes, buttons, origin)


def _axis(a: Any, where: str, bad) -> AxisMap:
    if not isinstance(a, dict):
        raise bad(where, "expected a map with source and optional scale, invert, deadband")
    unknown = set(a) - {"source", "scale", "invert", "deadband"}
    if unknown:
        raise bad(f"{where}.{sorted(map(str, unknown))[0]}",
                  "unknown field (known: source, scale, invert, deadband)")
    src = a.get("source")
    if type(src) is int and src >= 0:
        source, minus = src, None
    elif (isinstance(src, list) and len(src) == 2 and all(type(s) is int and s >= 0 for s in src)):
        source, minus = src
    else:
        raise bad(f"{where}.source", f"expected a device axis number or [plus, minus], got {src!r}")
    scale = a.get("scale", 1.0)
    if isinstance(scale, bool) or not isinstance(scale, int | float) or not math.isfinite(scale) \
            or not 0.0 < abs(scale) <= 10.0:
        raise bad(f"{where}.scale", f"expected a number with 0 < |scale| <= 10, got {scale!r}")
    invert = a.get("invert", False)
    if not isinstance(invert, bool):
        raise bad(f"{where}.invert", f"expected true or false, got {invert!r}")
    db = a.get("deadband", 0.0)
    if isinstance(db, bool) or not isinstance(db, int | float) or not 0.0 <= db < 1.0:
        raise bad(f"{where}.deadband", f"expected a number in [0, 1), got {db!r}")
    return AxisMap(source, minus, float(scale), invert, float(db))


def check_range(mapping: Mapping, device: str, axes: int | None, buttons: int | None) -> None:
    """Refuse a device axis or button that ``device`` (a backend's name) does not have:
    it numbers ``axes`` axes and ``buttons`` buttons from 0 (None: not known, not
    checked). InputError ``origin: field: problem``, the field as the file names it."""
    def bad(where: str, what: str, v: int, n: int) -> InputError:
        many = "axes" if what == "axis" else "buttons"
        have = f"{many} 0 to {n - 1}" if n > 0 else f"no {many}"
        return InputError(f"{mapping.origin}: {where}: {what} {v} is out of range: {device} devices "
                          f"have {have}")

    if axes is not None:
        for k, a in enumerate(mapping.axes):
            if a.minus is None and a.source >= axes:
                raise bad(f"axes[{k}].source", "axis", a.source, axes)
            if a.minus is not None:
                for j, v in enumerate((a.source, a.minus)):
                    if v >= axes:
                        raise bad(f"axes[{k}].source[{j}]", "axis", v, axes)
    if buttons is not None:
        for role in KNOWN:
            b = mapping.buttons.get(role)
            if b is not None and b >= buttons:
                raise bad(f"buttons.{role}", "button", b, buttons)


def load_mapping(path: str | Path) -> Mapping:
    """The mapping file ``path`` (a regular file of at most 1 MiB, strict YAML: a duplicate
    key, such as two ``enable``, is refused); InputError naming the file and the field."""
    p = Path(path)
    try:
        doc = load_yaml(p)
    except FileError as e:
        raise InputError(str(e)) from None
    return parse_mapping(doc, str(p))


def shipped_mapping(name: str) -> Mapping:
    """A mapping shipped in ``sctd_services/input/maps`` (``xbox``, ``spacemouse``)."""
    f = resources.files("sctd_services.input").joinpath("maps", f"{name}.yaml")
    return parse_mapping(parse_yaml(f.read_text(), f"maps/{name}.yaml"), f"maps/{name}.yaml")


# What a sensor_msgs/Joy carries at most: Linux's joystick interface (joydev), which the
# joy package's drivers read or mirror, numbers at most ABS_CNT axes and (KEY_MAX -
# BTN_MISC + 1) buttons. A Joy shorter than a map reads its missing buttons released
# and its missing axes at rest (Mapping.apply): nothing moves.
JOY_AXES = 64
JOY_BUTTONS = 512


def joy_function(path: str | Path | None = None):
    """``(axes, buttons) -> (u [6], [mode, enable, escape, ...], stop)`` through the
    mapping file ``path`` (the buttons by :attr:`Mapping.published`; default: the
    shipped xbox map, which numbers a ROS Joy from the joy package's
    ``game_controller_node`` as SDL does): how a ROS ``Joy`` becomes sctd input
    (``sctd run --ros``, ``sctd ros``). InputError when the file is bad or names an
    axis or button no Joy has (:data:`JOY_AXES`, :data:`JOY_BUTTONS`), before anything
    starts."""
    from .device import Reading

    mapping = load_mapping(path) if path else shipped_mapping("xbox")
    check_range(mapping, "ROS Joy", JOY_AXES, JOY_BUTTONS)

    def apply(axes: tuple[float, ...], buttons: tuple[int, ...]) -> tuple[list[float], list[int], bool]:
        reading = Reading(axes, buttons)
        return (*mapping.apply(reading, 6), mapping.stop(reading))
    return apply
