"""Where the daemon's tick thread spends its CPU, part by part: ``sctd run`` with its tick
loop's parts timed on the thread's CPU clock (``sctd bench cost --parts``).

``python -m sctd.bench.parts --out FILE run ARGS...`` runs ``sctd run ARGS...`` with each
part of :class:`~sctd.runtime.loop.TickLoop`'s tick wrapped in a timer: the drain
(:meth:`~sctd.runtime.loop.TickLoop.before_tick`), the spin to the deadline (the
ticker's wait), the control step (the driver's tick), the put of the target and any
gripper message, the statistics (:meth:`~sctd.runtime.status.TickStats.account`), the
status map (:meth:`~sctd.runtime.status.DaemonStatus.close_window`, 20 times a second)
and the work after the tick (:meth:`~sctd.runtime.loop.TickLoop.after_tick`). What is
left of the thread's CPU is the rest: the sleep between ticks (the system call and the
wake-up), the loop's own lines, the timers' clock reads. Twice a second a thread writes
the sums so far to ``FILE`` (JSON: ``ticks``, ``thread_s``, and per part ``s`` and
``calls``), replaced whole, so that a reader takes differences over any window.

The wrappers cost the thread two clock reads and a Python call a part (about 1-2 us a
part on this project's VM): the parts' figures have one clock read's cost taken off per
call, and the rest carries the wrappers' own lines. Compare phases measured the same way.
"""

from __future__ import annotations

import json
import os
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

from .tickpath import clock_cost

PARTS = ("drain", "spin", "step", "put", "account", "status", "after")
WRITE_EVERY = 0.5  # s between the sums written out


class PartClock:
    """The sums of the timed parts (seconds and calls), filled on the tick thread."""

    def __init__(self) -> None:
        self.s = dict.fromkeys(PARTS, 0.0)
        self.calls = dict.fromkeys(PARTS, 0)

    def timed(self, part: str, f: Callable[..., Any]) -> Callable[..., Any]:
        """``f``, its CPU time on the calling thread added to ``part``."""
        clock, s, calls = time.thread_time, self.s, self.calls

        def timed_call(*args: Any, **kwargs: Any) -> Any:
            t0 = clock()
            try:
                return f(*args, **kwargs)
            finally:
                s[part] += clock() - t0
                calls[part] += 1
        return timed_call


def instrument(loop: Any, ticker: Any, status: Any, parts: PartClock) -> None:
    """Wrap the parts of ``loop``'s tick (module doc) before it runs."""
    loop.before_tick = parts.timed("drain", loop.before_tick)
    ticker.wait = parts.timed("spin", ticker.wait)
    loop.driver.tick = parts.timed("step", loop.driver.tick)
    loop.publish = parts.timed("put", loop.publish)
    loop.gripper = parts.timed("put", loop.gripper)
    status.stats.account = parts.timed("account", status.stats.account)
    status.close_window = parts.timed("status", status.close_window)
    loop.after_tick = parts.timed("after", loop.after_tick)


def write_parts(out: str, parts: PartClock, ticker: Any, tick_thread: int) -> Callable[[], None]:
    """Start the thread that writes ``parts``' sums, ``ticker``'s ticks and the CPU time of
    thread ``tick_thread`` to ``out`` (module doc); the function returned has it write
    once more and end, and waits for that."""
    done = threading.Event()
    writer = threading.Thread(target=_writer, name="sctd-parts", daemon=True,
                              args=(out, parts, ticker, tick_thread, done, clock_cost()))
    writer.start()

    def stop() -> None:
        done.set()
        writer.join(2.0)
    return stop


def _writer(out: str, parts: PartClock, ticker: Any, tick_thread: int, stop: threading.Event,
            read_cost: float) -> None:
    """Write the sums to ``out`` every :data:`WRITE_EVERY` s, and once more at the end."""
    cpu = time.pthread_getcpuclockid(tick_thread)
    while True:
        done = stop.wait(WRITE_EVERY)
        sums = {"ticks": ticker.ticks, "thread_s": time.clock_gettime(cpu), "clock_read_s": read_cost,
                "parts": {p: {"s": parts.s[p], "calls": parts.calls[p]} for p in PARTS}}
        tmp = f"{out}.tmp"
        with open(tmp, "w") as f:
            json.dump(sums, f)
        os.replace(tmp, out)
        if done:
            return


def run_instrumented(out: str, argv: list[str]) -> int:
    """``sctd run argv`` with its tick loop's parts timed, the sums written to ``out``."""
    from sctd.cli.main import main
    from sctd.runtime.loop import TickLoop

    original = TickLoop.run

    def run(self: TickLoop, ticker: Any, status: Any, stop: threading.Event,
            end: float | None = None) -> None:
        parts = PartClock()
        instrument(self, ticker, status, parts)
        stop_writing = write_parts(out, parts, ticker, threading.get_ident())
        try:
            original(self, ticker, status, stop, end)
        finally:
            stop_writing()

    TickLoop.run = run  # type: ignore[method-assign]
    return main(["run", *argv])


def per_tick(before: dict[str, Any], after: dict[str, Any]) -> dict[str, float] | None:
    """The parts' CPU microseconds a tick between two of the written sums (each call's
    clock read taken off), the thread's whole (``thread``) and what is left (``rest``);
    None without a tick between them."""
    ticks = after["ticks"] - before["ticks"]
    if ticks <= 0:
        return None
    read = after.get("clock_read_s", 0.0)
    out: dict[str, float] = {}
    for p in PARTS:
        a, b = after["parts"][p], before["parts"][p]
        out[p] = round(1e6 * max(0.0, (a["s"] - b["s"]) - read * (a["calls"] - b["calls"])) / ticks, 1)
    out["thread"] = round(1e6 * (after["thread_s"] - before["thread_s"]) / ticks, 1)
    out["rest"] = round(out["thread"] - sum(out[p] for p in PARTS), 1)
    return out


def main(argv: list[str] | None = None) -> int:
    args = list(sys.argv[1:] if argv is None else argv)
    if len(args) < 3 or args[0] != "--out" or args[2] != "run":
        print("usage: python -m sctd.bench.parts --out FILE run [sctd run's arguments]", file=sys.stderr)
        return 2
    return run_instrumented(args[1], args[3:])


if __name__ == "__main__":
    sys.exit(main())
