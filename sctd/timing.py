"""Fixed-rate scheduling on absolute deadlines, and cheap latency statistics.

The loop sleeps to shortly before each deadline and spins the rest, with the thread's
timer slack set to 1 ns (Linux defaults to 50 us, which alone would miss a 0.2 ms p99).
Deadlines advance by ``due += period`` (as python-can's periodic sender), so timing
error never accumulates; a tick that starts more than half a period late is counted
late, and when the loop falls more than ``max_behind`` periods behind it resynchronises
instead of bursting, counting the skipped ticks.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import signal
import threading
import time
from collections.abc import Iterator

PR_SET_NAME = 15
PR_SET_TIMERSLACK = 29


def set_timer_slack(ns: int = 1) -> bool:
    """Set this thread's timer slack (Linux); returns False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(ns), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def set_thread_name(name: str) -> bool:
    """Name the calling OS thread (Linux, at most 15 bytes shown), so that ``top -H`` and
    ``/proc/<pid>/task/*/comm`` tell a process's threads apart; False where unsupported."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_NAME, ctypes.c_char_p(name.encode()[:15]), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def set_realtime(priority: int) -> bool:
    """Put the calling thread in SCHED_FIFO at ``priority`` (1-99); False when the OS
    refuses (no CAP_SYS_NICE / rtprio limit) or ``priority`` is 0."""
    if priority <= 0:
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
        return True
    except (OSError, AttributeError):
        return False


@contextlib.contextmanager
def threads_niced(nice: int) -> Iterator[int]:
    """The calling thread at ``nice`` for the ``with`` block and back after it, so that
    every thread started meanwhile (and every thread those start) inherits ``nice``:
    Linux keeps a nice value per thread, and a new thread takes its creator's. Yields the
    nice the new threads get: ``nice``, or the calling thread's own when ``nice`` is 0 or
    the OS refuses it (a nice below the current one needs CAP_SYS_NICE or an
    RLIMIT_NICE that allows it)."""
    own = os.getpriority(os.PRIO_PROCESS, 0)  # (Linux: 0 is the calling thread)
    if nice == 0 or nice == own:
        yield own
        return
    try:
        os.setpriority(os.PRIO_PROCESS, 0, nice)
    except OSError:
        yield own
        return
    try:
        yield nice
    finally:
        try:
            os.setpriority(os.PRIO_PROCESS, 0, own)
        except OSError:  # (back up to a higher priority than ``nice`` needs the same privilege)
            pass


class Histogram:
    """Fixed-bin histogram of durations (s) for percentiles without storing samples.

    Bins are 5 us wide up to 50 ms; anything longer lands in the last bin, whose
    percentile is reported as the largest value seen.
    """

    BIN = 5e-6
    N = 10_000

    def __init__(self) -> None:
        self.counts = [0] * self.N
        self.n = 0
        self.max = 0.0

    def add(self, x: float) -> None:
        i = int(x / self.BIN) if x > 0 else 0
        self.counts[i if i < self.N else self.N - 1] += 1
        self.n += 1
        if x > self.max:
            self.max = x

    def merge(self, other: Histogram) -> None:
        """Add ``other``'s samples to this one's."""
        self.counts = [a + b for a, b in zip(self.counts, other.counts, strict=True)]
        self.n += other.n
        self.max = max(self.max, other.max)

    def clear(self) -> None:
        """Forget every sample (zeroing only the bins up to the largest one used)."""
        top = min(int(self.max / self.BIN) + 1, self.N)
        self.counts[:top] = [0] * top
        self.counts[-1] = 0
        self.n = 0
        self.max = 0.0

    def percentile(self, p: float) -> float:
        """Upper edge of the bin holding the p-th percentile (s); 0 when empty."""
        if self.n == 0:
            return 0.0
        rank = math.ceil(p / 100.0 * self.n)
        acc = 0
        for i, c in enumerate(self.counts):
            acc += c
            if acc >= rank:
                return min((i + 1) * self.BIN, self.max) if i < self.N - 1 else self.max
        return self.max

    def summary_ms(self) -> dict[str, float]:
        return {
            "p50": round(self.percentile(50) * 1e3, 4),
            "p99": round(self.percentile(99) * 1e3, 4),
            "p999": round(self.percentile(99.9) * 1e3, 4),
            "max": round(self.max * 1e3, 4),
            "n": self.n,
        }


class Ticker:
    """Absolute-deadline ticker on the monotonic clock.

    Parameters
    ----------
    period : float
        Tick period (s).
    spin : float
        How long before each deadline to stop sleeping and spin (s).
    max_behind : int
        Periods behind schedule after which the ticker resynchronises.
    """

    def __init__(self, period: float, spin: float = 1e-4, max_behind: int = 5):
        self.period = period
        self.spin = spin
        self.max_behind = max_behind
        self.due = time.monotonic() + period
        self.ticks = 0
        self.late = 0
        self.skipped = 0

    def wait(self, sleep: bool = True) -> tuple[float, float]:
        """Block until the next deadline (sleeping to ``spin`` before it, then spinning;
        with ``sleep`` false, spinning only: for a caller that slept itself and did work
        since); return (wake time, lateness) in seconds."""
        due = self.due
        remaining = due - time.monotonic()
        if sleep and remaining > self.spin:
            time.sleep(remaining - self.spin)
        now = time.monotonic()
        while now < due:
            now = time.monotonic()
        lateness = now - due
        self.ticks += 1
        if lateness > 0.5 * self.period:
            self.late += 1
        self.due = due + self.period
        behind = now - self.due
        if behind > self.max_behind * self.period:
            missed = int(behind / self.period)
            self.skipped += missed
            self.due += missed * self.period
        return now, lateness


class RoundTrips:
    """Round-trip times of numbered messages: the send time of message ``seq``, and the
    time to the first answer that names ``seq`` (a pong, or a target whose ``in_seq``
    is the input's ``seq``). Thread-safe: answers arrive on Zenoh's threads.

    Parameters
    ----------
    keep : int
        Send times held at most; the oldest tenth is forgotten past it (messages that
        no answer named, e.g. inputs a newer one overwrote before any tick read them).
    """

    def __init__(self, keep: int = 5000):
        self.histogram = Histogram()
        self.counting = True  # whether answers add to the histogram (off in a warm-up)
        self.answers = 0  # answers seen, counted or not, named a sent message or not
        self._keep = keep
        self._sent: dict[int, float] = {}
        self._lock = threading.Lock()

    def sent(self, seq: int) -> None:
        with self._lock:
            self._sent[seq] = time.monotonic()
            if len(self._sent) > self._keep:
                for k in list(self._sent)[: self._keep // 10]:
                    del self._sent[k]

    def answered(self, seq: int, now: float) -> None:
        """An answer naming ``seq`` arrived at ``now`` (``time.monotonic()``)."""
        with self._lock:
            t = self._sent.pop(seq, None)
            self.answers += 1
        if t is not None and self.counting:
            self.histogram.add(now - t)

    def clear(self) -> None:
        """Forget the send times (between phases: late answers then count nothing)."""
        with self._lock:
            self._sent.clear()


STOP_POLL = 0.1  # s between a waiting main thread's looks for a stop signal


def wait_until(done: threading.Event, seconds: float = 0.0) -> None:
    """Wait in the main thread for ``done``, Ctrl-C or SIGTERM, or ``seconds`` (0: no
    limit); SIGTERM sets ``done``.

    The wait wakes every :data:`STOP_POLL` s: the kernel may hand a signal to any thread
    that does not block it, often one of Zenoh's, and Python runs the handler only when
    the main thread runs, never while it is blocked on an event without a timeout.
    """
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    end = time.monotonic() + seconds if seconds > 0 else math.inf
    try:
        while not done.wait(min(STOP_POLL, max(0.0, end - time.monotonic()))):
            if time.monotonic() >= end:
                break
    except KeyboardInterrupt:
        pass
