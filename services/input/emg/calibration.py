"""The calibration: what the guided phases recorded -> per-channel normalisation and the
axis map, and the calibration file that holds them (JSON, ``docs/input-emg.md``).

The fit is pure (arrays in, :class:`Calibration` out); :func:`load` and :func:`save` are
the file boundary and validate everything they read.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from sctd.files import MAX_YAML_BYTES, FileError, read_text

from ..device import InputError
from .processing import N_AXES, AxisMap, Filters, Normalisation, envelope_sos, fit_axis_map, group_delay_s

VERSION = 1


@dataclass(frozen=True)
class Phase:
    """One step of the guided calibration: what the user is told and the axes it means."""

    name: str
    target: tuple[float, float, float]
    say: str


PHASES = (
    Phase("rest", (0.0, 0.0, 0.0), "relax every muscle"),
    Phase("+x", (1.0, 0.0, 0.0), "contract for +x and hold"),
    Phase("-x", (-1.0, 0.0, 0.0), "contract for -x and hold"),
    Phase("+y", (0.0, 1.0, 0.0), "contract for +y and hold"),
    Phase("-y", (0.0, -1.0, 0.0), "contract for -y and hold"),
    Phase("+z", (0.0, 0.0, 1.0), "contract for +z and hold"),
    Phase("-z", (0.0, 0.0, -1.0), "contract for -z and hold"),
    Phase("co-contract", (0.0, 0.0, 0.0), "tense every muscle at once (it means stop)"),
)
WEAK_RATIO = 2.0  # an MVC below 2 x rest: the channel never really contracted


@dataclass
class Calibration:
    """A calibration file's content.

    Attributes
    ----------
    board : str
        The board it was recorded on (``synthetic``, a BrainFlow board name).
    channels : list of int
        The board's data rows used, in order (BrainFlow's EMG channel numbers).
    rate_hz : float
        The board's sampling rate.
    filters : Filters
    normalisation : Normalisation
    mapping : AxisMap
    created : str
        ISO time of the calibration.
    notes : list of str
        What the fit noticed (weak channels, no co-contraction rule).
    """

    board: str
    channels: list[int]
    rate_hz: float
    filters: Filters
    normalisation: Normalisation
    mapping: AxisMap
    created: str = ""
    notes: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        f = self.filters
        low, high = f.band_hz(self.rate_hz)
        delay = group_delay_s(envelope_sos(f, self.rate_hz), self.rate_hz)
        m = self.mapping
        return {
            "version": VERSION,
            "board": self.board,
            "channels": list(self.channels),
            "rate_hz": self.rate_hz,
            "filters": {
                "bandpass": {"low_hz": low, "high_hz": high, "order": f.band_order, "notch_hz": f.notch_hz},
                "envelope": {"cutoff_hz": f.envelope_hz, "order": f.envelope_order,
                             "group_delay_ms": round(delay * 1e3, 3)},
            },
            "normalisation": {"rest": self.normalisation.rest.tolist(),
                              "mvc": self.normalisation.mvc.tolist()},
            "mapping": {"matrix": m.matrix.tolist(), "bias": m.bias.tolist(), "deadzone": m.deadzone,
                        "cocontraction": m.cocontraction, "hold_s": m.hold_s},
            "created": self.created,
            "notes": list(self.notes),
        }


def fit(envelopes: dict[str, np.ndarray], *, board: str, channels: list[int], rate_hz: float,
        filters: Filters, settle_s: float = 1.0, ridge: float = 1e-2,
        phases: tuple[Phase, ...] = PHASES) -> Calibration:
    """The calibration from each phase's envelopes (n_i, n_channels).

    The first ``settle_s`` of each phase is dropped (the user's reaction and the
    envelope's rise). Per channel: ``rest`` is the median at rest and ``mvc`` the
    largest phase median. The map is ridge regression from the activations to each
    phase's target (rest and co-contraction: 0). When co-contraction stands apart from
    every single-axis phase (the smallest activation across channels), a rule zeroes
    it from a third of the way up; the dead zone covers what rest leaves.
    """
    skip = round(settle_s * rate_hz)
    filters = replace(filters, band_high_hz=filters.band_hz(rate_hz)[1])  # the file says which edge
    held = _held(envelopes, phases, skip)
    notes: list[str] = []
    norm, strong = _normalisation(held, phases, channels, notes)
    act = {name: norm(e) for name, e in held.items()}
    mapping = _axis_map(act, phases, strong, ridge, notes)
    notes += _phase_notes(mapping, act, phases)
    return Calibration(board=board, channels=list(channels), rate_hz=rate_hz, filters=filters,
                       normalisation=norm, mapping=mapping,
                       created=time.strftime("%Y-%m-%dT%H:%M:%S%z"), notes=notes)


def _held(envelopes: dict[str, np.ndarray], phases: tuple[Phase, ...], skip: int) -> dict[str, np.ndarray]:
    """Each phase's envelopes without their first ``skip`` samples (the user's reaction
    and the envelope's rise)."""
    held = {}
    for p in phases:
        e = envelopes.get(p.name)
        if e is None or len(e) <= skip + 10:
            raise InputError(f"calibration: phase {p.name!r} recorded {0 if e is None else len(e)} "
                             f"samples, needs more than {skip + 10}")
        held[p.name] = e[skip:]
    return held


def _normalisation(held: dict[str, np.ndarray], phases: tuple[Phase, ...], channels: list[int],
                   notes: list[str]) -> tuple[Normalisation, np.ndarray]:
    """Per channel, ``rest`` the median at rest and ``mvc`` the largest phase median; and
    which channels contracted (an MVC of at least :data:`WEAK_RATIO` x rest). The weak
    ones are named in ``notes``."""
    rest = np.median(held["rest"], axis=0)
    mvc = np.max([np.median(held[p.name], axis=0) for p in phases if p.name != "rest"], axis=0)
    strong = mvc >= WEAK_RATIO * rest
    if not strong.any():
        raise InputError(f"calibration: no channel contracted above {WEAK_RATIO:g} x its rest "
                         f"envelope in any phase: check the electrodes and --channels")
    weak = [channels[i] for i in np.flatnonzero(~strong)]
    if weak:
        notes.append(f"channels {weak}: no contraction above {WEAK_RATIO:g} x rest; not used")
    mvc = np.maximum(mvc, WEAK_RATIO * rest + 1e-9)
    return Normalisation(rest=rest, mvc=mvc), strong


def _axis_map(act: dict[str, np.ndarray], phases: tuple[Phase, ...], strong: np.ndarray,
              ridge: float, notes: list[str]) -> AxisMap:
    """Ridge regression from the activations ``act`` to each phase's target, with the
    co-contraction rule (when co-contraction stands apart; otherwise said in ``notes``)
    and the dead zone over what rest leaves."""
    A = np.vstack([act[p.name] for p in phases])
    Y = np.vstack([np.tile(p.target, (len(act[p.name]), 1)) for p in phases])
    raw = fit_axis_map(A, Y, ridge=ridge, deadzone=0.0, use=strong)

    single = [p.name for p in phases if any(p.target)]
    low_single = max(float(np.percentile(act[n][:, strong].min(axis=1), 90)) for n in single)
    co = float(np.median(act["co-contract"][:, strong].min(axis=1))) if "co-contract" in act else 0.0
    # a third of the way up from the single contractions: a held co-contraction rarely dips below
    cocontraction = low_single + (co - low_single) / 3.0 if co > 1.5 * low_single + 0.05 else None
    if cocontraction is None:
        notes.append("co-contraction does not stand apart from the single contractions: no "
                     "co-contraction rule, the map alone brings it near zero")
    quiet = [act["rest"]] + ([act["co-contract"]] if cocontraction is None and "co-contract" in act else [])
    residual = np.abs(raw(np.vstack(quiet)))
    deadzone = float(np.clip(1.2 * np.percentile(residual.max(axis=1), 95), 0.05, 0.3))
    return AxisMap(matrix=raw.matrix, bias=raw.bias, deadzone=deadzone, cocontraction=cocontraction)


def _phase_notes(mapping: AxisMap, act: dict[str, np.ndarray], phases: tuple[Phase, ...]) -> list[str]:
    """What the fitted map makes of each phase where it falls short: a single-axis phase
    that reaches less than half its axis, a quiet one that moves."""
    notes = []
    for p in phases:
        u = mapping(act[p.name]).mean(axis=0)
        own = int(np.argmax(np.abs(p.target))) if any(p.target) else None
        if own is not None and u[own] * p.target[own] < 0.5:
            notes.append(f"phase {p.name} maps to only {u[own]:+.2f} on its axis: calibrate again "
                         f"with a stronger or more distinct contraction")
        elif own is None and np.max(np.abs(u)) > 0.1:
            notes.append(f"phase {p.name} maps to {np.round(u, 2).tolist()}, not zero")
    return notes


def save(cal: Calibration, path: str | Path) -> None:
    Path(path).write_text(json.dumps(cal.to_json(), indent=2) + "\n")


def load(path: str | Path) -> Calibration:
    """The calibration file at ``path``; InputError naming the file and the field."""
    where = f"calibration {path}"
    try:
        obj = json.loads(read_text(path, MAX_YAML_BYTES, where))
    except FileError as e:
        raise InputError(str(e)) from None
    except (json.JSONDecodeError, RecursionError) as e:
        raise InputError(f"{where}: not JSON: {e}") from None
    if not isinstance(obj, dict) or obj.get("version") != VERSION:
        got = obj.get("version") if isinstance(obj, dict) else obj
        raise InputError(f"{where}: version must be {VERSION}, got {got!r}")
    try:
        channels = [int(c) for c in obj["channels"]]
        n = len(channels)
        rate = _positive(obj["rate_hz"], "rate_hz")
        bp, env = obj["filters"]["bandpass"], obj["filters"]["envelope"]
        filters = Filters(band_low_hz=float(bp["low_hz"]), band_high_hz=float(bp["high_hz"]),
                          band_order=int(bp["order"]), notch_hz=float(bp.get("notch_hz", 0.0)),
                          envelope_hz=float(env["cutoff_hz"]), envelope_order=int(env["order"]))
        filters.band_hz(rate)
        rest = _array(obj["normalisation"]["rest"], (n,), "normalisation.rest")
        mvc = _array(obj["normalisation"]["mvc"], (n,), "normalisation.mvc")
        if np.any(mvc <= rest):
            raise ValueError("normalisation: every mvc must exceed its rest")
        m = obj["mapping"]
        co = m.get("cocontraction")
        deadzone = float(m["deadzone"])
        if not 0.0 <= deadzone < 1.0:
            raise ValueError(f"mapping.deadzone must be in [0, 1), got {deadzone}")
        mapping = AxisMap(matrix=_array(m["matrix"], (n, N_AXES), "mapping.matrix"),
                          bias=_array(m["bias"], (N_AXES,), "mapping.bias"), deadzone=deadzone,
                          cocontraction=None if co is None else float(co),
                          hold_s=float(m.get("hold_s", 0.3)))
    except KeyError as e:
        raise InputError(f"{where}: missing field {e}") from e
    except (TypeError, ValueError) as e:
        raise InputError(f"{where}: {e}") from e
    return Calibration(board=str(obj.get("board", "")), channels=channels, rate_hz=rate, filters=filters,
                       normalisation=Normalisation(rest=rest, mvc=mvc), mapping=mapping,
                       created=str(obj.get("created", "")), notes=list(obj.get("notes", [])))


def _positive(x: Any, name: str) -> float:
    v = float(x)
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{name} must be a positive number, got {x!r}")
    return v


def _array(x: Any, shape: tuple[int, ...], name: str) -> np.ndarray:
    a = np.asarray(x, dtype=float)
    if a.shape != shape:
        raise ValueError(f"{name}: shape {a.shape}, expected {shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name}: not all finite")
    return a
