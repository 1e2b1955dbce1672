"""``sctd bench flood``: the tick under a valid-input flood, the daemon's Zenoh threads at
``--io-nice`` and at a baseline nice, interleaved in one run.

Each round starts the processes as ``sctd demo`` wires them: ``sctd sim`` on the default
task (``sctd/app/defaults.yaml``) listening on a free loopback port, and ``sctd run`` on
the default skill and this bench's session connected to it; once the daemon publishes
targets, the fastest valid-input flood one process sends (``python -m
sctd.bench.robustness flood valid``; ``--flooders`` such processes at once), on one
device name or ``--devices`` names in turn, for ``--seconds``. What the round reports
comes from the daemon's status over the flood: its ticks, late ticks, the drains that
ran past their allowance (``status.long_drains``, :mod:`sctd.runtime.loop`), and the
lateness p99 of its one-second windows (worst and median). Rounds alternate between the
two nice values, so that the machine's slow spells fall on both.

Why the nice: under such a flood the daemon's receiving thread holds a ring's lock a
good share of its time; the tick thread (SCHED_FIFO) that wakes on its core pushes it off
the CPU there, lock held, and its next ``try_recv`` then waits until the fair scheduler
runs that thread again, after whatever else is runnable on the core (the simulator, the
flooder). At a lower nice it runs first (docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import json
import statistics
import threading
import time
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import zenoh

from sctd.app.defaults import defaults
from sctd.app.errors import fail
from sctd.bench import run_and_report
from sctd.cli.procs import Child, free_port
from sctd.wire import Keys, codec
from sctd.wire.session import session

KEYS = Keys()
GOAL_P99_MS = 0.2  # lateness p99 of a one-second window under the flood


class _Status:
    """The daemon's newest status, and the one-second windows' lateness since a mark."""

    def __init__(self, s: zenoh.Session):
        self.lock = threading.Lock()
        self.last: dict[str, Any] | None = None
        self.windows: list[tuple[float, dict]] = []  # (arrival, recent_ms)
        self.sub = s.declare_subscriber(KEYS.status, self._on_status)

    def _on_status(self, sample: zenoh.Sample) -> None:
        m = codec.unpack_map(sample.payload.to_bytes())
        with self.lock:
            recent = m.get("recent_ms")
            if recent is not None and (not self.windows or self.windows[-1][1] != recent):
                self.windows.append((time.monotonic(), recent))
            self.last = m

    def newest(self) -> dict[str, Any]:
        with self.lock:
            return dict(self.last or {})

    def p99s_between(self, t0: float, t1: float) -> list[float]:
        with self.lock:
            return sorted(r["lateness"]["p99"] for t, r in self.windows if t0 < t <= t1)


def run_round(io_nice: int, seconds: float, devices: int, flooders: int, logdir: Path,
              tag: str) -> dict[str, Any]:
    """One round at ``io_nice``: the figures of the daemon's status over the flood of
    ``flooders`` processes (their messages counted together)."""
    hub = f"tcp/127.0.0.1:{free_port()}"
    with Child("sctd.cli.main", "sim", "--task", defaults().task, "--listen", hub,
               log=logdir / f"sim-{tag}.log") as sim:
        end = time.monotonic() + 60
        with session(connect=[hub]) as s:
            st = _Status(s)
            with Child("sctd.cli.main", "run", "--skill", defaults().skill, "--connect", hub,
                       "--io-nice", str(io_nice), log=logdir / f"daemon-{tag}.log") as daemon:
                while st.newest().get("targets", 0) < 2000:  # running, past its start
                    if time.monotonic() > end or not (sim.running() and daemon.running()):
                        raise RuntimeError(f"the daemon published no targets; see {logdir}")
                    time.sleep(0.1)
                s0, t0 = st.newest(), time.monotonic()
                with ExitStack() as stack:
                    floods = [stack.enter_context(Child(
                        "sctd.bench.robustness", "flood", "valid", "--seconds", str(seconds), "--devices",
                        str(devices), "--connect", hub, log=logdir / f"flood-{tag}-{k}.log"))
                        for k in range(flooders)]
                    for f in floods:
                        f.p.wait(seconds + 30)
                time.sleep(1.2)  # the last window reaches a status message
                s1, t1 = st.newest(), time.monotonic()
                p99s = st.p99s_between(t0 + 2.0, t1)  # (the flooder sends a second after it starts)
                st.sub.undeclare()
    each = [_sent(f) for f in floods]
    sent = {"sent": sum(e["sent"] for e in each), "seconds": max(e["seconds"] for e in each)}
    ticks = s1["ticks"] - s0["ticks"]
    return {
        "io_nice": s1.get("io_nice"), "asked_io_nice": io_nice, "sent": sent["sent"],
        "sent_per_s": round(sent["sent"] / sent["seconds"]) if sent["seconds"] else None,
        "ticks": ticks, "late_ticks": s1["late_ticks"] - s0["late_ticks"],
        "skipped_ticks": s1["skipped_ticks"] - s0["skipped_ticks"],
        "long_drains": s1["long_drains"] - s0["long_drains"],
        "long_drains_per_1000_ticks": round(1000 * (s1["long_drains"] - s0["long_drains"]) / ticks, 2)
        if ticks else None,
        "lateness_p99_ms_worst_window": p99s[-1] if p99s else None,
        "lateness_p99_ms_median_window": p99s[len(p99s) // 2] if p99s else None,
    }


def _sent(flooder: Child) -> dict[str, Any]:
    lines = [ln for ln in flooder.output().splitlines() if ln.startswith("{")]
    if not lines:
        raise RuntimeError(f"the flooder printed nothing; see {flooder.log_path}")
    return json.loads(lines[-1])


def run_flood_bench(io_nice: int, baseline: int, rounds: int, seconds: float, devices: int,
                    flooders: int, logdir: Path) -> dict[str, Any]:
    """``rounds`` of each nice, interleaved (the baseline first in even rounds)."""
    out: list[dict[str, Any]] = []
    for k in range(rounds):
        order = (baseline, io_nice) if k % 2 == 0 else (io_nice, baseline)
        for nice in order:
            r = run_round(nice, seconds, devices, flooders, logdir, f"{k}-{nice}")
            r["round"] = k
            out.append(r)
    summary = {str(n): _summary([r for r in out if r["asked_io_nice"] == n]) for n in (io_nice, baseline)}
    return {"skill": defaults().skill, "task": defaults().task, "io_nice": io_nice,
            "baseline_io_nice": baseline, "seconds": seconds, "devices": devices, "flooders": flooders,
            "rounds": out, "summary": summary}


def _summary(rs: list[dict[str, Any]]) -> dict[str, Any]:
    def med(key: str) -> float | None:
        vals = [r[key] for r in rs if r[key] is not None]
        return round(statistics.median(vals), 3) if vals else None

    worst = [r["lateness_p99_ms_worst_window"] for r in rs if r["lateness_p99_ms_worst_window"] is not None]
    return {"rounds": len(rs), "long_drains_per_1000_ticks_median": med("long_drains_per_1000_ticks"),
            "lateness_p99_ms_worst_window_median": med("lateness_p99_ms_worst_window"),
            "rounds_within_goal": sum(p <= GOAL_P99_MS for p in worst),
            "sent_per_s_median": med("sent_per_s")}


def print_report(r: dict[str, Any]) -> None:
    print(f"sctd bench flood: {r['skill']} on {r['task']}, the daemon connected to the simulator; "
          f"the fastest valid-input flood {r['flooders']} process(es) send on {r['devices']} device "
          f"name(s), {r['seconds']:g} s a round; the daemon's Zenoh threads at nice {r['io_nice']} and "
          f"(baseline) {r['baseline_io_nice']}, interleaved")
    cols = ("round", "io_nice", "sent_per_s", "ticks", "late_ticks", "skipped_ticks", "long_drains",
            "long_drains_per_1000_ticks", "lateness_p99_ms_worst_window", "lateness_p99_ms_median_window")
    heads = (c.replace("lateness_p99_ms_", "p99 ").replace("_per_1000_ticks", "/1k")[:14] for c in cols)
    print("  " + "  ".join(f"{h:>14s}" for h in heads))
    for row in r["rounds"]:
        print("  " + "  ".join(f"{'-' if row.get(c) is None else row[c]!s:>14s}" for c in cols))
    for nice, s in r["summary"].items():
        print(f"  nice {nice}: long drains per 1000 ticks (median of {s['rounds']}) "
              f"{s['long_drains_per_1000_ticks_median']}; lateness p99 of the worst window (median) "
              f"{s['lateness_p99_ms_worst_window_median']} ms; within {GOAL_P99_MS} ms in "
              f"{s['rounds_within_goal']} of {s['rounds']} rounds")


def add_flood_bench_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--io-nice", type=int, default=-10,
                   help="the daemon's --io-nice measured (default %(default)s)")
    p.add_argument("--baseline-io-nice", type=int, default=0,
                   help="the nice it is compared with, in the same run (default %(default)s: the "
                        "daemon's default, its own nice)")
    p.add_argument("--rounds", type=int, default=3, help="rounds of each (default %(default)s)")
    p.add_argument("--seconds", type=float, default=5.0,
                   help="seconds of flood a round (default %(default)s)")
    p.add_argument("--devices", type=int, default=1,
                   help="device names the flood goes round (default %(default)s)")
    p.add_argument("--flooders", type=int, default=1,
                   help="flooding processes, their messages counted together (default %(default)s; "
                        "where one process sends fewer messages than a flood to be measured)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def main_flood_bench(args: argparse.Namespace) -> int:
    for flag, v in (("--io-nice", args.io_nice), ("--baseline-io-nice", args.baseline_io_nice)):
        if not -20 <= v <= 19:
            return fail("bench flood", f"{flag}: {v}: a nice value is -20 to 19")
    if args.rounds < 1:
        return fail("bench flood", f"--rounds: {args.rounds}: at least 1")
    if not args.seconds > 0:
        return fail("bench flood", f"--seconds: {args.seconds}: more than 0")
    for flag, n in (("--devices", args.devices), ("--flooders", args.flooders)):
        if n < 1:
            return fail("bench flood", f"{flag}: {n}: at least 1")
    return run_and_report("flood", args, lambda logdir: run_flood_bench(
        args.io_nice, args.baseline_io_nice, args.rounds, args.seconds, args.devices, args.flooders,
        logdir), print_report)
