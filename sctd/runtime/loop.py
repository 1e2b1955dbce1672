"""The daemon's tick loop, on the tick thread.

The tick thread wakes once per period, ``spin`` before its deadline (the daemon's
``--spin-us``): it installs a swapped-in skill (:class:`~.swap.SkillSwap`) and drains each
ring (:class:`~.ingress.Ingress`): checks each message's size before copying it, decodes
and validates it, counts every malformed one, and keeps the newest valid sample; then it
spins to the deadline. At the deadline the control step runs on them
(:class:`~.driver.TickDriver`), and its target is encoded and put at once, on this
thread; the tick's timing is kept (:class:`~.status.TickStats`) and, when due, a status
map handed to the publisher thread (:class:`~.publisher.Publisher`), which encodes and
puts it. After it, the work the next tick would otherwise do itself.

One wake-up per tick, and no thread between the step and its target: on a 2-core
machine each wake-up of a thread costs about 25 us of CPU, so a second sleep before the
drain, and a hand-over of every target to another thread, cost the daemon a tenth of a
core (docs/benchmarks.md, ``sctd bench cost``). The spin window is the drain's: with the
default spin (100 us) the inputs are decoded ahead of the deadline and the step starts on
time; with no spin the drain runs at the deadline and its time shows as lateness.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from ..timing import Ticker
from .controller import TickResult
from .driver import TickDriver
from .ingress import Ingress
from .status import DaemonStatus
from .swap import SkillSwap


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
        ``send(item)``: the publisher thread's queue (a status map, or a list of samples to
        drop).
    target : callable, optional
        ``target(item)``: publishes a target tuple ``(seq, stamp, pose, state, skill id,
        in_seq, in_device, seed)`` on this thread (:class:`~.publisher.TargetOut`);
        default ``send``.
    """

    def __init__(self, driver: TickDriver, ingress: Ingress, swap: SkillSwap,
                 send: Callable[[Any], None], target: Callable[[tuple], None] | None = None):
        self.driver, self.ingress, self.swap, self.send = driver, ingress, swap, send
        self.target = target if target is not None else send
        self.controller = driver.controller

    def run(self, ticker: Ticker, status: DaemonStatus, stop: threading.Event,
            end: float | None = None) -> None:
        """Tick on ``ticker`` until ``stop`` is set or the monotonic time ``end``: wake
        ``ticker.spin`` ahead of each deadline and drain, step at it, put the target,
        account after it. The compute time is the step's (the put is ``publish_ms``)."""
        send, tick, publish = self.send, self.driver.tick, self.publish
        stats = status.stats
        while not stop.is_set():
            ahead = ticker.due - ticker.spin - time.monotonic()
            if ahead > 0.0:
                time.sleep(ahead)
            self.before_tick(time.monotonic())
            now, lateness = ticker.wait()  # spins what the drain left of the window
            if end is not None and now >= end:
                break
            wall = time.time()
            res = tick(now, wall)
            done = time.monotonic()
            if res.pose is not None:
                publish(res, wall)
            stats.account(lateness, done - now, res.state)
            if done >= stats.next_status:
                send(status.close_window(ticker, time.monotonic()))
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
            self.publish(res, wall)
        return res.state

    def publish(self, res: TickResult, wall: float) -> None:
        """The step's target (it has a pose), stamped ``wall``, out."""
        self.target((self.driver.target_seq, wall, res.pose, res.state, self.controller.skill.id,
                     res.in_seq, res.device, res.seed))

    def after_tick(self) -> None:
        """After the target is out: the work the next tick would otherwise do itself
        (vector-field neighbour answers), new devices' rings, freeing big samples (on the
        publisher's thread)."""
        self.driver.after_tick()
        ingress = self.ingress
        ingress.after_tick()
        if ingress.trash:
            self.send(ingress.take_trash())
