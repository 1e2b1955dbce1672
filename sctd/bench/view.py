"""``sctd bench view``: the daemon's tick with the live view and a browser attached.

One run: the simulator (``sctd sim --task T``) and the daemon (``sctd run --skill S``)
on a private loopback port, a person's input pushed at 100 Hz (slow sines on three axes,
the deadman held) so that the daemon ticks with input; then phases of ``--phase`` s,
alternately **closed** (nothing else) and **open** (``sctd view`` and a headless
Chromium on its page, both started at the phase's start and given 3 s to connect before
the phase is measured), closed first and last. The daemon's ``status`` says, each
second, the p99 of its tick lateness and compute over that second (``recent_ms``); a
phase's figure is the median of its seconds' p99 (and their maximum). The goal: every
open phase's median within the spread of the closed phases' (at most their largest).
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from ..app.defaults import defaults
from ..app.options import SKILL_HELP
from ..cli.procs import Child, free_port
from ..wire import Keys, codec
from ..wire.session import session
from . import run_and_report
from .latency import wait_for_targets

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                  "--enable-unsafe-swiftshader", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync")
CONNECT = 3.0  # s an open phase gives the view and the browser before it is measured


class _Status:
    """The daemon's per-second p99s, with the time each arrived."""

    def __init__(self) -> None:
        self.rows: list[tuple[float, float, float]] = []  # (t, lateness p99, compute p99)
        self._lock = threading.Lock()

    def __call__(self, sample: zenoh.Sample) -> None:
        try:
            recent = codec.unpack_map(sample.payload.to_bytes()).get("recent_ms") or {}
            row = (time.monotonic(), float(recent["lateness"]["p99"]), float(recent["compute"]["p99"]))
        except (KeyError, TypeError, ValueError):
            return  # the first second has none
        with self._lock:  # one row a second: the status repeats the last second's figures
            if not self.rows or row[0] - self.rows[-1][0] >= 0.95:
                self.rows.append(row)

    def between(self, t0: float, t1: float) -> list[tuple[float, float, float]]:
        with self._lock:
            return [r for r in self.rows if t0 <= r[0] <= t1]


def _push(ep: str, stop: threading.Event) -> None:
    """A person's input at 100 Hz: slow sines, the deadman held."""
    with session(connect=[ep]) as s:
        pub = s.declare_publisher(Keys().input("bench"))
        k = 0
        while not stop.is_set():
            k += 1
            u = [0.4 * math.sin(k * 0.01), 0.4 * math.cos(k * 0.007), 0.2 * math.sin(k * 0.004)]
            pub.put(codec.encode_input(k, time.time(), u, [0, 1, 0]))
            stop.wait(0.01)
        pub.put(codec.encode_input(k + 1, time.time(), [0.0, 0.0, 0.0], [0, 0, 0]))


def _open(ep: str, task: str, logdir: Path, k: int) -> tuple[Child, subprocess.Popen, Path]:
    """The view and a headless Chromium on its page."""
    port = free_port()
    view = Child("sctd.cli.main", "view", "--connect", ep, "--task", task, "--view-port", str(port),
                 log=logdir / f"view-{k}.log")
    profile = Path(tempfile.mkdtemp(prefix="sctd-bench-chromium-"))
    end = time.monotonic() + 30.0
    while "sctd view: robot" not in (logdir / f"view-{k}.log").read_text(errors="replace"):
        if time.monotonic() > end or not view.running():
            view.stop()
            raise RuntimeError(f"sctd view did not start; see {logdir / f'view-{k}.log'}")
        time.sleep(0.1)
    # Its temporary files in its own folder too (TMPDIR): it is killed at the end, and a
    # killed Chromium leaves an org.chromium.Chromium.* folder in the temp folder it used.
    browser = subprocess.Popen([str(CHROMIUM), *CHROMIUM_FLAGS, f"--user-data-dir={profile}",
                                f"http://127.0.0.1:{port}/"], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL, start_new_session=True,
                               env={**os.environ, "TMPDIR": str(profile)})
    return view, browser, profile


def _close(view: Child, browser: subprocess.Popen, profile: Path) -> None:
    import shutil
    import signal

    try:
        os.killpg(browser.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    browser.wait()
    view.stop()
    shutil.rmtree(profile, ignore_errors=True)


def run_view_bench(skill: str, task: str, phases: int, phase_s: float, logdir: Path) -> dict:
    """Run the phases described in the module doc; return every phase's figures."""
    if not CHROMIUM.exists():
        raise RuntimeError(f"needs Chromium at {CHROMIUM} (apt-get install chromium)")
    ep = f"tcp/127.0.0.1:{free_port()}"
    status, stop = _Status(), threading.Event()
    out: list[dict[str, Any]] = []
    with Child("sctd.cli.main", "sim", "--task", task, "--listen", ep, log=logdir / "sim.log"), \
         Child("sctd.cli.main", "run", "--skill", skill, "--connect", ep,
               log=logdir / "daemon.log") as daemon, session(connect=[ep]) as s:
        wait_for_targets(ep, daemon, logdir, timeout=60.0)
        sub = s.declare_subscriber(Keys().status, status)
        pusher = threading.Thread(target=_push, args=(ep, stop), daemon=True)
        pusher.start()
        try:
            for k in range(2 * phases + 1):
                opened = None
                if k % 2:
                    opened = _open(ep, task, logdir, k)
                    time.sleep(CONNECT)
                t0 = time.monotonic()
                time.sleep(phase_s)
                out.append(_phase("open" if opened else "closed", status.between(t0, time.monotonic())))
                if opened is not None:
                    _close(*opened)
        finally:
            stop.set()
            pusher.join(5)
            sub.undeclare()
    return _verdict(skill, task, phase_s, out)


def _phase(kind: str, rows: list[tuple[float, float, float]]) -> dict[str, Any]:
    late, comp = [r[1] for r in rows], [r[2] for r in rows]
    return {"phase": kind, "seconds": len(rows), "lateness_p99_ms": _summary(late),
            "compute_p99_ms": _summary(comp)}


def _summary(values: list[float]) -> dict[str, float | None]:
    return {"median": statistics.median(values) if values else None, "max": max(values, default=None)}


def _verdict(skill: str, task: str, phase_s: float, phases: list[dict]) -> dict:
    def spread(kind: str, what: str) -> tuple[float, float]:
        vals = [p[what]["median"] for p in phases if p["phase"] == kind and p[what]["median"] is not None]
        return (min(vals), max(vals)) if vals else (math.nan, math.nan)

    criteria: dict[str, Any] = {}
    for what in ("lateness_p99_ms", "compute_p99_ms"):
        lo, hi = spread("closed", what)
        worst = spread("open", what)[1]
        criteria[f"open_{what}_within_closed_spread"] = bool(worst <= hi)
        criteria[f"closed_{what}_spread"] = [lo, hi]
    return {"skill": skill, "task": task, "phase_s": phase_s, "phases": phases, "criteria": criteria}


def print_report(r: dict) -> None:
    print(f"sctd bench view: {r['skill']} on {r['task']}, phases of {r['phase_s']:.0f} s, the view and a "
          "headless Chromium attached in the open ones; per phase the median (max) of the daemon's "
          "per-second p99, ms")
    print(f"  {'phase':8s} {'seconds':>7s}   {'lateness p99':>20s}   {'compute p99':>20s}")
    for p in r["phases"]:
        lat, com = p["lateness_p99_ms"], p["compute_p99_ms"]
        print(f"  {p['phase']:8s} {p['seconds']:7d}   {_fmt(lat):>20s}   {_fmt(com):>20s}")
    c = r["criteria"]
    mark = {True: "met", False: "NOT met"}
    for what in ("lateness_p99_ms", "compute_p99_ms"):
        lo, hi = c[f"closed_{what}_spread"]
        print(f"  {what}: closed phases {lo:.3f}-{hi:.3f}; open phases within it: "
              f"{mark[c[f'open_{what}_within_closed_spread']]}")


def _fmt(h: dict) -> str:
    return "-" if h["median"] is None else f"{h['median']:.3f} ({h['max']:.3f})"


def add_view_bench_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--skill", default=defaults().skill, help=f"{SKILL_HELP} (default %(default)s)")
    p.add_argument("--task", default=defaults().task,
                   help="the task the simulator runs (default %(default)s)")
    p.add_argument("--phases", type=int, default=3, help="open phases (each between two closed ones)")
    p.add_argument("--phase", type=float, default=10.0, help="s measured per phase")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def main_view_bench(args: argparse.Namespace) -> int:
    return run_and_report("view", args, lambda logdir: run_view_bench(
        args.skill, args.task, args.phases, args.phase, logdir), print_report)
