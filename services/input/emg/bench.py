"""The EMG processing latency figure (``sctd bench input``): sample in -> command out.

Synthetic contractions (:mod:`.synthetic`) are written as a BrainFlow playback file and
streamed by BrainFlow's playback board in real time; a calibration is fitted on the same
kind of data; the device is then read at the bridge's rate and each :meth:`read` (fetch
the samples that arrived, band-pass, rectify, envelope, normalise, map) is timed with
``perf_counter``. The envelope's group delay is a property of the filter, not of the
computation, and is reported apart.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from .board import BoardSource, BoardSpec, write_playback
from .calibration import PHASES, fit
from .device import EmgDevice
from .processing import Chain, Filters
from .synthetic import contractions

RATE_HZ = 250.0  # BrainFlow's synthetic board, whose layout the playback file uses
CHANNELS = list(range(1, 9))


def bench_processing(seconds: float = 5.0, rate: float = 100.0, random_state: int = 0) -> dict[str, float]:
    """Time ``seconds`` of reads at ``rate`` Hz.

    Returns
    -------
    dict
        ``reads``, ``samples_per_read`` (mean), ``p50_ms``, ``p99_ms``, ``max_ms`` (per
        read), ``envelope_group_delay_ms``, ``board_rate_hz``, ``read_rate_hz``.
    """
    filters = Filters()
    phase_s = 2.0
    train = contractions([(p.name, phase_s) for p in PHASES], RATE_HZ, len(CHANNELS), random_state)
    env = Chain(filters, RATE_HZ, len(CHANNELS)).envelope(train)
    n = round(phase_s * RATE_HZ)
    cal = fit({p.name: env[i * n:(i + 1) * n] for i, p in enumerate(PHASES)}, board="synthetic",
              channels=CHANNELS, rate_hz=RATE_HZ, filters=filters, settle_s=0.5)
    cycle = [(p.name, 0.5) for p in PHASES]
    timeline = cycle * (int(seconds / (0.5 * len(cycle))) + 2)
    samples = contractions(timeline, RATE_HZ, len(CHANNELS), random_state + 1)
    times: list[float] = []
    counts: list[int] = []
    with tempfile.TemporaryDirectory(prefix="sctd-emg-bench-") as tmp:
        path = str(Path(tmp) / "contractions.csv")
        write_playback(path, samples, CHANNELS, RATE_HZ)
        dev = EmgDevice(BoardSource(BoardSpec(board="playback", file=path)), cal)
        try:
            period, due = 1.0 / rate, time.monotonic()
            end = due + seconds
            while due < end:
                due += period
                time.sleep(max(0.0, due - time.monotonic()))
                seen = dev.process.seen
                t0 = time.perf_counter()
                dev.read()
                times.append(time.perf_counter() - t0)
                counts.append(dev.process.seen - seen)
            delay = dev.process.chain.envelope_delay_s
        finally:
            dev.close()
    ms = np.asarray(times) * 1e3
    busy = [c for c in counts if c]
    return {"reads": float(len(ms)), "samples_per_read": float(np.mean(busy)) if busy else 0.0,
            "p50_ms": float(np.percentile(ms, 50)), "p99_ms": float(np.percentile(ms, 99)),
            "max_ms": float(ms.max()), "envelope_group_delay_ms": delay * 1e3,
            "board_rate_hz": RATE_HZ, "read_rate_hz": rate}


def main() -> None:
    r = bench_processing()
    print(f"emg processing: {int(r['reads'])} reads at {r['read_rate_hz']:g} Hz of a "
          f"{r['board_rate_hz']:g} Hz board ({r['samples_per_read']:.1f} samples each): "
          f"p50 {r['p50_ms']:.3f} ms, p99 {r['p99_ms']:.3f} ms, max {r['max_ms']:.3f} ms (p99 <= 5 ms asked)")
    print(f"emg envelope group delay (not included): {r['envelope_group_delay_ms']:.1f} ms")


if __name__ == "__main__":
    main()
