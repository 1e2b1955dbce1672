"""One trial of ``sctd bench link``, judged on the observer host of the namespaced cluster:
``python -m sctd.bench.linktrial --config FILE --task T --seed N [--time-limit S]``.

It watches what ``sctd eval``'s real-time trials watch (:class:`~sctd_services.eval.
watcher.TrialWatcher`), judges the trial with the same
:class:`~sctd_services.eval.trial.TrialRecorder`, and measures the hand's unintended
motion (:class:`Wander`). It prints ``{"ready": true}`` once its subscriptions are
declared, ``{"acting": true}`` when the user first pushes (its own subscriptions are in
place: it has seen the arm and the objects), then the trial's result as one JSON line:
the recorder's result, ``wander_m`` and the daemon's last ``counters`` and ``input``
(its status).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from typing import Any

from sctd.task import find_task
from sctd.wire import Keys
from sctd.wire.session import session
from sctd_services.eval.trial import TrialRecorder
from sctd_services.eval.watcher import WATCH_INGRESS, WATCH_RATE, TrialWatcher
from sctd_services.user import PROFILES

STARTUP_S = 90.0  # s for the first observation and the user's first input
STUCK_AFTER = 10.0  # s without progress that end a trial as stuck (sctd eval's)


class Wander:
    """The hand's worst unintended motion: over every span in which no input device
    drives the arm (the daemon's status says ``input.owner`` is null: every device's
    input at rest, stale or disarmed), the largest distance (m) the hand got from where
    it was when the span began; the worst over the trial. The span begins at the first
    sample whose newest status says so, a status period (50 ms) and a link's delay after
    the fact, so the hand settling onto the last target after a release (a few mm)
    counts too."""

    def __init__(self) -> None:
        self.worst = 0.0
        self._anchor: tuple[float, float, float] | None = None

    def add(self, p_hand: Any, driven: bool) -> None:
        """One sample: the hand's position (3,) and whether a device drives the arm."""
        if driven:
            self._anchor = None
            return
        p = (float(p_hand[0]), float(p_hand[1]), float(p_hand[2]))
        if self._anchor is None:
            self._anchor = p
            return
        self.worst = max(self.worst, math.dist(p, self._anchor))


def driven(status: dict[str, Any]) -> bool:
    """Whether the status says an input device owns the motion (no status yet: not
    known, counted as driven: nothing unintended is claimed before the daemon speaks)."""
    inp = status.get("input")
    return not isinstance(inp, dict) or inp.get("owner") is not None


def watch(config: str, task_name: str, seed: int, time_limit: float | None, profile: str) -> dict[str, Any]:
    """Judge one trial (module doc); its result."""
    task = find_task(task_name)
    rec = TrialRecorder(task, seed, PROFILES[profile].switch_time, time_limit, STUCK_AFTER)
    keys = Keys()
    wander = Wander()
    limits = [(keys.state, WATCH_INGRESS), (keys.target, WATCH_INGRESS)]
    with session(config_file=config, rate_limits=limits) as s:
        w = TrialWatcher(s, task)
        print(json.dumps({"ready": True}), flush=True)
        deadline = time.monotonic() + STARTUP_S + 3 * rec.time_limit
        first: tuple[float, float] | None = None  # (wall, simulated) at the trial's start, as sctd eval
        last = first
        acting = False
        try:
            while True:
                time.sleep(1.0 / WATCH_RATE)
                if time.monotonic() > deadline:
                    rec.end("no end within the bench's deadline")
                    break
                obs = w.observation()
                if obs is None or w.inputs == 0:  # the trial starts with the user
                    continue
                last = (time.monotonic(), obs.t)
                first = first or last
                if not acting and any(w.u):
                    print(json.dumps({"acting": True}), flush=True)  # the user pushes: it sees all
                    acting = True
                wander.add(obs.T_world_ee[:3, 3], driven(w.status))
                if rec.add(obs, w.u, w.buttons, w.status.get("vf_scale")) is not None:
                    break
        finally:
            w.close()
    res = rec.result()
    if first is not None and last is not None and last[0] - first[0] > 1.0:
        res.sim_rtf = round((last[1] - first[1]) / (last[0] - first[0]), 3)  # how well the sim kept time
    return {**res.as_dict(), "wander_m": round(wander.worst, 5),
            "counters": w.status.get("counters", {}), "input": w.status.get("input", {})}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sctd.bench.linktrial", description=__doc__.split("\n\n")[0])
    p.add_argument("--config", required=True, help="the observer's Zenoh config file")
    p.add_argument("--task", required=True)
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--time-limit", type=float, default=None, help="s (default: the task file's)")
    p.add_argument("--profile", default="steady", choices=sorted(PROFILES))
    args = p.parse_args(argv)
    print(json.dumps(watch(args.config, args.task, args.seed, args.time_limit, args.profile)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
