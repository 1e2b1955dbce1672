"""The daemon's tick loop, on the tick thread.

``DRAIN_LEAD`` before each deadline the tick thread wakes, installs a swapped-in skill
(:class:`~.swap.SkillSwap`), and drains each ring (:class:`~.ingress.Ingress`): checks
each message's size before copying it, decodes and validates it, counts every malformed
one, and keeps the newest valid sample. At the deadline the control step runs on them
(:class:`~.driver.TickDriver`) and its target is queued for the publisher thread
(:class:`~.publisher.Publisher`); the tick's timing is kept (:class:`~.status.TickStats`)
and, when due, a status map queued. After it, the work the next tick would otherwise do
itself. (Decoding costs far more after a 1 ms sleep than in a hot loop; done ahead of
the deadline it delays no tick, and one that overruns the lead shows as lateness.)
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from ..timing import Ticker
from .driver import TickDriver
from .ingress import Ingress
from .status import DaemonStatus
from .swap import SkillSwap

DRAIN_LEAD = 2.5e-4  # s before each deadline the inputs are drained and decoded


class TickLoop:
    """The tick loop of one run (module doc).

    Parameters
    ----------
    driver : TickDriver
    ingress : Ingress
        The rings drained into ``driver``.
    swap : SkillSwap
        Its mailbox is read ahead of every tick.
    send : callable
        ``send(item)``: the publisher's queue (a target tuple, a status map, or a list of
        samples to drop).
    """

    def __init__(self, driver: TickDriver, ingress: Ingress, swap: SkillSwap,
                 send: Callable[[Any], None]):
        self.driver, self.ingress, self.swap, self.send = driver, ingress, swap, send
        self.controller = driver.controller

    def run(self, ticker: Ticker, status: DaemonStatus, stop: threading.Event,
            end: float | None = None) -> None:
        """Tick on ``ticker`` until ``stop`` is set or the monotonic time ``end``: drain
        ahead of each deadline, step at it, account after it."""
        send = self.send
        stats = status.stats
        while not stop.is_set():
            ahead = ticker.due - DRAIN_LEAD - time.monotonic()
            if ahead > 0.0:
                time.sleep(ahead)
            self.before_tick(time.monotonic())
            now, lateness = ticker.wait()
            if end is not None and now >= end:
                break
            state = self.step(now, time.time())
            done = time.monotonic()
            stats.account(lateness, done - now, state)
            if done >= stats.next_status:
                send(status.close_window(ticker, done))
            self.after_tick()

    def before_tick(self, now: float) -> None:
        """Ahead of a deadline (``now``: monotonic): install a swapped-in skill, then
        drain the inputs."""
        if self.swap.pending is not None:
            self.swap.install(now)
        self.ingress.drain(now)

    def step(self, now: float, wall: float) -> str:
        """The control step at the deadline ``now`` (monotonic; ``wall``: Unix time);
        queues the target, returns the state."""
        res = self.driver.tick(now, wall)
        if res.pose is not None:
            self.send((self.driver.target_seq, wall, res.pose, res.state, self.controller.skill.id,
                       res.in_seq, res.device, res.seed))
        return res.state

    def after_tick(self) -> None:
        """After the target is out: the work the next tick would otherwise do itself
        (vector-field neighbour answers), new devices' rings, freeing big samples (on the
        publisher's thread)."""
        self.driver.after_tick()
        ingress = self.ingress
        ingress.after_tick()
        if ingress.trash:
            self.send(ingress.take_trash())
