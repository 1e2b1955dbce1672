"""A log (``sctd log --mcap``) as a timeline of snapshots, for the view to scrub.

The messages of a log (``(key, log time ns, value)``, values the contract's maps as the
log stores them) are sorted by key; :meth:`Timeline.at` is what the live view would
have shown at a time: the newest message of each key logged at or before it. The time
axis is the log's own (``log_time``: when each message arrived), from 0 at its first
message.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Any

from .live import Snapshot

KINDS = ("state", "target", "status", "scene", "objects", "input")


@dataclass
class _Track:
    times: list[float] = field(default_factory=list)
    values: list[dict[str, Any]] = field(default_factory=list)

    def at(self, t: float) -> dict[str, Any] | None:
        i = bisect.bisect_right(self.times, t) - 1
        return self.values[i] if i >= 0 else None


class Timeline:
    """The messages of one robot's keys in a log.

    Parameters
    ----------
    messages : iterable of (str, int, dict)
        ``(key, log time in ns, value)`` (:func:`sctd.cli.log.read_log`), any order.
    prefix : str
        The robot's prefix (``sctd/edan``); keys under another are left out.
    """

    def __init__(self, messages, prefix: str):
        self.tracks: dict[tuple[str, str], _Track] = {}
        rows = sorted((t, key, value) for key, t, value in messages if key.startswith(prefix + "/"))
        self.t0 = rows[0][0] * 1e-9 if rows else 0.0
        for t_ns, key, value in rows:
            rest = key[len(prefix) + 1:]
            kind, _, name = rest.partition("/")
            if kind not in KINDS:
                continue
            track = self.tracks.setdefault((kind, name), _Track())
            track.times.append(t_ns * 1e-9 - self.t0)
            track.values.append(value)
        self.duration = max((tr.times[-1] for tr in self.tracks.values()), default=0.0)

    def keys(self, kind: str) -> list[str]:
        """The names logged under ``kind`` (objects, input devices)."""
        return sorted(name for k, name in self.tracks if k == kind)

    def _at(self, kind: str, t: float, name: str = "") -> dict[str, Any] | None:
        track = self.tracks.get((kind, name))
        return track.at(t) if track is not None else None

    def at(self, t: float) -> Snapshot:
        """What the keys said last at ``t`` (s from the log's start)."""
        state = self._at("state", t)
        snap = Snapshot(t=t, target=self._at("target", t), status=self._at("status", t),
                        scene=self._at("scene", t))
        if state is not None:
            snap.pose, snap.q = state.get("pose"), state.get("q")
        for name in self.keys("objects"):
            msg = self._at("objects", t, name)
            if msg is not None and msg.get("pose") is not None:
                snap.objects[name] = msg["pose"]
        for name in self.keys("input"):
            msg = self._at("input", t, name)
            if msg is not None and msg.get("u") is not None:
                snap.inputs[name] = (msg["u"], msg.get("stamp", 0.0))
        return snap

    def skill_ids(self) -> list[str]:
        """The skill ids the status named, in the order they first ran."""
        seen: list[str] = []
        for msg in self.tracks.get(("status", ""), _Track()).values:
            sid = msg.get("skill")
            if sid and sid not in seen:
                seen.append(sid)
        return seen


def run_replay(view, timeline: Timeline, stop, rate: float = 30.0) -> None:
    """Show ``timeline`` on ``view`` (a :class:`~.live.LiveView`) with a timeline to
    scrub: a time slider, play/pause and a speed, until ``stop`` (a threading.Event)."""
    import time

    gui = view.server.gui
    with gui.add_folder("Log", order=-1):
        slider = gui.add_slider("time [s]", min=0.0, max=max(timeline.duration, 0.01), step=0.01,
                                initial_value=0.0)
        play = gui.add_button("play / pause")
        speed = gui.add_dropdown("speed", ("0.25", "0.5", "1", "2", "4"), initial_value="1")
    playing = {"on": False}

    @play.on_click
    def _(_event) -> None:
        playing["on"] = not playing["on"]

    shown, due, period = -1.0, time.monotonic(), 1.0 / rate
    view.replay_slider = slider
    while not stop.is_set():
        if playing["on"]:
            t = slider.value + period * float(speed.value)
            if t >= timeline.duration:
                t, playing["on"] = timeline.duration, False
            slider.value = t
        if slider.value != shown:
            shown = slider.value
            view.draw(timeline.at(shown))
            view.drawn_at = shown
        due += period
        stop.wait(max(0.0, due - time.monotonic()))
