"""The daemon's tick loop, on the tick thread.

The tick thread wakes once per period, ahead of its deadline: it installs a swapped-in
skill (:class:`~.swap.SkillSwap`) and drains each ring (:class:`~.ingress.Ingress`):
checks each message's size before copying it, decodes and validates it, counts every
malformed one, and keeps the newest valid sample; then it spins to the deadline. At the
deadline the control step runs on them (:class:`~.driver.TickDriver`), and its target
(and a gripper message, when the tick has one) is encoded and put at once, on this
thread; the tick's timing is kept (:class:`~.status.TickStats`) and, when due, a status
map handed to the publisher thread (:class:`~.publisher.Publisher`), which encodes and
puts it. After it, the work the next tick would otherwise do itself.

How far ahead it wakes: ``spin`` (the daemon's ``--spin-us``) plus the drain's usual
time (its :data:`LEAD_QUANTILE` quantile, tracked a step of :data:`LEAD_STEP` a tick, so
that one slow drain moves it by a microsecond; at most :data:`MAX_LEAD`): the drain
ends about ``spin`` before the deadline, and the timer's late wake-ups up to ``spin``
cost no lateness. With ``spin`` 0 it wakes at the
deadline and drains then: the cheapest, with the drain and the timer's delay as
lateness. (Decoding costs far more after a sleep than in a hot loop: about 45 us for a
state on this project's VM.)

A drain that takes :data:`LONG_DRAIN` (or ``spin``, if longer) beyond the tracked quantile is
counted (``status.long_drains``): with ``spin`` it is what makes a tick late from the
inside, the thread having woken in time. Under a flood of input the usual one is a
``try_recv`` that waits for a ring's lock held by one of Zenoh's receiving threads which
the tick thread's own wake-up pushed off the CPU; ``sctd run --io-nice`` runs those
threads first when the tick thread waits for one (docs/benchmarks.md).

One wake-up per tick, and no thread between the step and its target: on a 2-core
machine each wake-up of a thread costs about 25 us of CPU, so a second sleep before the
spin, and a hand-over of every target to another thread, cost the daemon a tenth of a
core (``sctd bench cost``, docs/benchmarks.md).
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

MAX_LEAD = 2.5e-4  # s: the most the tick thread wakes before its spin window to drain
LEAD_QUANTILE = 0.95  # of the drain's time: how far before the spin window the tick wakes
LEAD_STEP = 1e-6  # s a tick moves the tracked quantile (one outlier moves it 1 us)
LONG_DRAIN = 1e-4  # s beyond the tracked quantile (or the spin, if longer): a long drain


def next_lead(lead: float, drained: float) -> float:
    """The tracked quantile of the drain's time after a drain of ``drained`` s: up by
    ``LEAD_STEP * LEAD_QUANTILE`` when it took longer, down by the rest of a step when
    not, so that it settles where that share of drains take longer; within [0,
    MAX_LEAD]."""
    return min(MAX_LEAD, max(0.0, lead + LEAD_STEP * (LEAD_QUANTILE - (drained <= lead))))


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
    gripper : callable, optional
        ``gripper(cmd)``: publishes a gripper message (:class:`~sctd.wire.codec.GripperCmd`)
        on this thread (:class:`~.publisher.GripperOut`); default ``send``.
    """

    def __init__(self, driver: TickDriver, ingress: Ingress, swap: SkillSwap,
                 send: Callable[[Any], None], target: Callable[[tuple], None] | None = None,
                 gripper: Callable[[Any], None] | None = None):
        self.driver, self.ingress, self.swap, self.send = driver, ingress, swap, send
        self.target = target if target is not None else send
        self.gripper = gripper if gripper is not None else send
        self.controller = driver.controller

    def run(self, ticker: Ticker, status: DaemonStatus, stop: threading.Event,
            end: float | None = None) -> None:
        """Tick on ``ticker`` until ``stop`` is set or the monotonic time ``end``: wake
        ahead of each deadline (module doc) and drain, spin to it, step, put the target,
        account after it. The compute time is the step's (the put is ``publish_ms``)."""
        send, tick, publish = self.send, self.driver.tick, self.publish
        stats = status.stats
        spin, lead = ticker.spin, 0.0  # lead: the drain's time, its LEAD_QUANTILE tracked (s)
        allowance = max(spin, LONG_DRAIN)
        while not stop.is_set():
            ahead = ticker.due - (spin + lead if spin > 0.0 else 0.0) - time.monotonic()
            if ahead > 0.0:
                time.sleep(ahead)
            t = time.monotonic()
            self.before_tick(t)
            drained = time.monotonic() - t
            if drained > lead + allowance:
                stats.long_drains += 1
            lead = next_lead(lead, drained)
            now, lateness = ticker.wait(sleep=False)  # spins what the drain left: no second wake-up
            if end is not None and now >= end:
                break
            wall = time.time()
            res = tick(now, wall)
            done = time.monotonic()
            if res.pose is not None:
                publish(res, wall)
            if res.gripper is not None:
                self.gripper(res.gripper)
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
        if res.gripper is not None:
            self.gripper(res.gripper)
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
