"""``sctd input emg --calibrate``: the guided calibration in the terminal.

Each phase says what to do ("rest", "contract for +x", ..., "co-contract"), waits for
Enter when a person is at the terminal, then records ``--phase-seconds`` of samples from
the board through the chain. Without a terminal on stdin (a script, a playback file
whose phases follow the same timeline) the phases follow each other back to back,
counted in samples, so phase k is samples ``[k S fs, (k+1) S fs)`` of the stream.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from ..device import InputError
from .board import BoardSource
from .calibration import PHASES, Phase
from .processing import Chain

NO_DATA_S = 2.0  # the board sent nothing for this long during a phase: give up


def record(source: BoardSource, rows: list[int], chain: Chain, *, seconds: float,
           interactive: bool, say: Callable[[str], None], ask: Callable[[str], str] = input,
           phases: tuple[Phase, ...] = PHASES) -> dict[str, np.ndarray]:
    """Each phase's envelopes (n, len(rows)) recorded from ``source``, in phase order."""
    need = round(seconds * source.rate_hz)
    out: dict[str, np.ndarray] = {}
    carry = np.zeros((0, len(rows)))  # envelopes past the previous phase's end
    for i, p in enumerate(phases, 1):
        say(f"[{i}/{len(phases)}] {p.name}: {p.say} ({seconds:g} s)")
        if interactive:
            ask("    press Enter to start ")
            source.flush()
            chain.reset()  # the pause before Enter is not part of this phase
            carry = carry[:0]
        got, count = [carry], len(carry)
        last, shown = time.monotonic(), 0
        while count < need:
            raw = source.poll(rows)
            if raw.shape[0]:
                got.append(chain.envelope(raw))
                count += raw.shape[0]
                last = time.monotonic()
                if interactive and count >= (shown + 1) * source.rate_hz:
                    shown += 1
                    say(f"    {shown} s")
            elif time.monotonic() - last > NO_DATA_S:
                raise InputError(f"emg --calibrate: board {source.name} stopped delivering data "
                                 f"in phase {p.name!r} ({count} of {need} samples)")
            else:
                time.sleep(0.01)
        env = np.vstack(got)
        out[p.name], carry = env[:need], env[need:]
    return out
