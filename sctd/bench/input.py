"""``sctd bench input``: a device event to the daemon's target, next to a bare Zenoh
echo of the same run; and the EMG chain's processing latency.

Processes, on one free loopback port: ``sctd run`` (pour, 1 kHz), the kinematic
stand-in robot (the skill and task of ``sctd/app/defaults.yaml``) and the echo of
``sctd bench latency``. This process holds SDL's virtual
game controller (it exists only in the process that creates it) and runs the gamepad
bridge on it, in one thread: every 0.1 s, once the previous move was answered (or given
up as lost after 1 s), it moves the stick at a random moment within a bridge period (an
*event*), and at the period's deadline the bridge reads the pad and publishes.
An event's latency is from the moment the stick moved to the arrival of the first
target whose ``in_seq`` is at least the ``seq`` of the first message carrying the
move. The bound is the bridge period + the daemon period + 2 x the echo's p99, measured
in the same run.
"""

from __future__ import annotations

import argparse
import random
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from sctd.app.defaults import defaults
from sctd.bench import run_and_report
from sctd.bench.latency import PING, PONG, wait_for_targets
from sctd.cli.procs import Child, free_port
from sctd.timing import Histogram, RoundTrips, Ticker, set_timer_slack
from sctd.wire import Keys, codec
from sctd.wire.session import MSGPACK, TEXT, session

ANSWER_TIMEOUT = 1.0  # s an event waits for its target before it counts as lost


class _EventTimes:
    """The pending event (its first carrying ``seq`` and the time it happened) and the
    latencies of answered ones. Thread-safe: targets arrive on Zenoh's threads.

    One event at a time: the next waits until the pending one is answered or lost (no
    target within :data:`ANSWER_TIMEOUT`), so that a slow answer on a loaded machine is
    measured as slow rather than counted as lost."""

    def __init__(self) -> None:
        self.histogram = Histogram()
        self.lock = threading.Lock()
        self.pending: tuple[int, float] | None = None
        self.answered = 0
        self.lost = 0

    def wait_for(self, seq: int, t_event: float) -> None:
        with self.lock:
            self.pending = (seq, t_event)

    def lose(self) -> None:
        with self.lock:
            self.lost += 1

    def idle(self, now: float) -> bool:
        """No event pending (one pending past :data:`ANSWER_TIMEOUT` counts as lost)."""
        with self.lock:
            if self.pending is not None and now - self.pending[1] > ANSWER_TIMEOUT:
                self.pending = None
                self.lost += 1
            return self.pending is None

    def on_target(self, sample: zenoh.Sample) -> None:
        now = time.monotonic()
        try:
            in_seq = codec.decode_target(sample.payload.to_bytes())["in_seq"]
        except codec.DecodeError:
            return
        with self.lock:
            if self.pending is not None and in_seq is not None and in_seq >= self.pending[0]:
                self.histogram.add(now - self.pending[1])
                self.pending = None
                self.answered += 1


def _echo_rtt(s: zenoh.Session, seconds: float, rate: float = 200.0) -> dict[str, float]:
    trips = RoundTrips()
    with s.declare_subscriber(PONG, lambda m: trips.answered(int(m.payload.to_bytes()), time.monotonic())), \
            s.declare_publisher(PING, express=True, encoding=TEXT) as pub:
        ticker = Ticker(1.0 / rate, spin=0.0)
        trips.counting = False
        start = time.monotonic()
        k = 0
        while (now := time.monotonic()) < start + seconds + 1.0:
            ticker.wait()
            trips.counting = now - start > 1.0
            trips.sent(k)
            pub.put(str(k).encode())
            k += 1
        time.sleep(0.2)
    return trips.histogram.summary_ms()


def gamepad_events(ep: str, bridge_rate: float, seconds: float, seed: int = 0,
                   min_events: int = 0) -> dict[str, Any]:
    """Stick moves on a virtual pad, through the gamepad bridge to the daemon's targets
    (see the module doc), for ``seconds`` and until ``min_events`` were made (each waits
    for its answer: on a busy machine fewer fit in the time; at most a minute longer);
    the figures."""
    from sctd_services.input.bridge import Bridge
    from sctd_services.input.gamepad import Gamepad
    from sctd_services.input.mapping import shipped_mapping
    from sctd_services.input.virtual_pad import VirtualPad

    rng = random.Random(seed)
    keys = Keys()
    times = _EventTimes()
    mapping = shipped_mapping("xbox")
    enable = mapping.buttons["enable"]
    with session(connect=[ep]) as s:
        echo = _echo_rtt(s, 3.0)
        with VirtualPad(name="sctd bench pad") as pad, s.declare_subscriber(keys.target, times.on_target), \
                s.declare_publisher(keys.input("gamepad"), express=True, encoding=MSGPACK) as pub:
            assert enable is not None
            pad.set_button(enable, True)
            device = Gamepad().open("sctd bench pad",
                                    argparse.Namespace(gamepad_mappings=None, virtual_script=None))
            bridge = Bridge(device, mapping, 3, pub.put, log=lambda m: None)
            period = 1.0 / bridge_rate
            ticker = Ticker(period, spin=1e-4)
            set_timer_slack(1)
            sign, every, k = 1.0, max(2, round(0.1 / period)), 0
            start = time.monotonic()
            moved: float | None = None
            try:
                def more() -> bool:
                    t = time.monotonic()
                    made = times.answered + times.lost
                    return t < start + seconds + 1.0 or (made < min_events and t < start + seconds + 61.0)
                while more():
                    now = time.monotonic()
                    if k % every == 0 and now > start + 1.0 and moved is None and times.idle(now):
                        time.sleep(rng.uniform(0.0, 0.9) * period)
                        sign = -sign
                        pad.set_axis(0, 0.6 * sign)
                        moved = time.monotonic()
                    ticker.wait()
                    u, _ = bridge.step()
                    if moved is not None and u[0] * sign > 0.3:
                        times.wait_for(bridge.seq, moved)
                        moved = None
                    elif moved is not None and time.monotonic() - moved > ANSWER_TIMEOUT:
                        times.lose()  # the bridge never read the move
                        moved = None
                    k += 1
                while not times.idle(time.monotonic()):  # the last event's answer, or its loss
                    time.sleep(0.01)
            finally:
                bridge.zero()
                device.close()
    events = times.answered + times.lost
    return {"bridge_rate_hz": bridge_rate, "events": events, "answered": times.answered,
            "echo_rtt_ms": echo, "event_to_target_ms": times.histogram.summary_ms()}


def run_input_bench(bridge_rate: float, seconds: float, rate: float, emg_seconds: float,
                    logdir: Path, min_events: int = 0) -> dict[str, Any]:
    """The processes of the module doc, the gamepad figures, then the EMG chain's."""
    from sctd_services.input.emg.bench import bench_processing

    ep = f"tcp/127.0.0.1:{free_port()}"
    d = defaults()
    with Child("sctd.cli.main", "run", "--skill", d.skill, "--listen", ep, "--rate", str(rate),
               log=logdir / "daemon.log") as daemon, \
         Child("sctd_sim.kinematic", "--task", d.task, "--connect", ep, log=logdir / "robot.log"), \
         Child("sctd.bench.latency", "echo", "--connect", ep, log=logdir / "echo.log"):
        wait_for_targets(ep, daemon, logdir)
        pad = gamepad_events(ep, bridge_rate, seconds, min_events=min_events)
    bound = 1e3 / bridge_rate + 1e3 / rate + 2 * pad["echo_rtt_ms"]["p99"]
    emg = bench_processing(seconds=emg_seconds)
    emg_p99 = emg["p99_ms"]
    return {"gamepad": pad, "daemon_rate_hz": rate, "emg": emg,
            "criteria": {"event_to_target_p99_ms": pad["event_to_target_ms"]["p99"],
                         "bound_ms": round(bound, 3),
                         "event_to_target_met": pad["event_to_target_ms"]["p99"] <= bound,
                         "emg_p99_ms": emg_p99, "emg_met": emg_p99 <= 5.0}}


def print_report(r: dict[str, Any]) -> None:
    def row(name: str, h: dict) -> str:
        return (f"  {name:34s} p50 {h['p50']:8.3f}   p99 {h['p99']:8.3f}   max {h['max']:8.3f}"
                f"   (n={h['n']})")

    g, c, e = r["gamepad"], r["criteria"], r["emg"]
    mark = {True: "met", False: "NOT met"}
    print(f"sctd bench input: virtual SDL pad -> gamepad bridge at {g['bridge_rate_hz']:g} Hz -> "
          f"sctd run at {r['daemon_rate_hz']:g} Hz; {g['answered']} of {g['events']} events answered")
    print("  all figures in ms")
    print(row("stick moved -> target", g["event_to_target_ms"]))
    print(row("bare Zenoh echo RTT", g["echo_rtt_ms"]))
    print(f"  p99 <= bridge period + daemon period + 2 x echo p99 = {c['bound_ms']:.3f} ms: "
          f"{mark[c['event_to_target_met']]}")
    print(f"EMG chain (BrainFlow playback board at {e['board_rate_hz']:g} Hz, read at "
          f"{e['read_rate_hz']:g} Hz, {e['samples_per_read']:.1f} samples per read, {e['reads']:.0f} reads):")
    print(f"  {'sample in -> command out':34s} p50 {e['p50_ms']:8.3f}   p99 {e['p99_ms']:8.3f}   "
          f"max {e['max_ms']:8.3f}")
    print(f"  envelope filter group delay (not included): {e['envelope_group_delay_ms']:.1f} ms")
    print(f"  p99 <= 5 ms: {mark[c['emg_met']]}")


def add_bench_input_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--bridge-rate", type=float, default=100.0, help="the gamepad bridge's rate, Hz")
    p.add_argument("--rate", type=float, default=1000.0, help="the daemon's tick rate, Hz")
    p.add_argument("--seconds", type=float, default=20.0, help="seconds of stick events")
    p.add_argument("--events", type=int, default=0,
                   help="at least this many stick events, however long they take (default %(default)s)")
    p.add_argument("--emg-seconds", type=float, default=10.0, help="seconds of EMG signal processed")
    p.add_argument("--json", action="store_true")
    p.add_argument("--logs", help="keep the processes' logs here")


def main_bench_input(args: argparse.Namespace) -> int:
    return run_and_report("input", args, lambda logdir: run_input_bench(
        args.bridge_rate, args.seconds, args.rate, args.emg_seconds, logdir, args.events), print_report)
