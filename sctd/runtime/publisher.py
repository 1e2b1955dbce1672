"""The daemon's outputs: each target and gripper message put on the tick thread
(:class:`TargetOut`, :class:`GripperOut`), the status encoded and put by a thread of its
own (:class:`Publisher`)."""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any

from ..timing import Histogram, set_realtime, set_thread_name, set_timer_slack
from ..wire import codec

log = logging.getLogger("sctd.run")


class TargetOut:
    """Puts each target on the tick thread, right after its step: encoded (msgpack, about
    5 us) and handed to Zenoh (an express put on a ``DROP`` publisher queues it for
    Zenoh's own transmit thread and never blocks), timed into :attr:`put_time`. With
    ``publisher`` (``--ros``), the target's pose is also queued for the ROS copy there."""

    def __init__(self, target: Any, publisher: Publisher | None = None):
        self.put = target.put
        self.publisher = publisher
        self.put_time = Histogram()

    def __call__(self, item: tuple) -> None:
        t0 = time.monotonic()
        self.put(codec.encode_target(*item))
        self.put_time.add(time.monotonic() - t0)
        if self.publisher is not None:
            self.publisher.queue.put((item[1], item[2]))


class GripperOut:
    """Puts each gripper message (a new command or a repeat, about 10 a second) on the
    tick thread, as :class:`TargetOut` does the targets."""

    def __init__(self, gripper: Any):
        self.put = gripper.put

    def __call__(self, c: codec.GripperCmd) -> None:
        self.put(codec.encode_gripper(c))


class Publisher(threading.Thread):
    """Encodes and publishes the status off the tick thread (a map of a few kB, 20 times a
    second), and frees the tick's oversized samples. Runs at one FIFO priority below the
    tick. Queue items: a status map (dict), a list of samples to drop (freeing them takes
    time), a ROS copy ``(stamp, pose)`` of a target, or None to stop. With ``ros``
    (``--ros``), each copy goes to ``ros.target(stamp, pose)`` (CDR, rate-limited). A
    context manager: started on entry, stopped and joined on exit."""

    def __init__(self, status: Any, rt_priority: int, ros: Any = None):
        super().__init__(name="sctd-publisher", daemon=True)
        self.status = status
        self.ros = ros
        self.rt_priority = rt_priority
        self.queue: queue.SimpleQueue[tuple | dict | list | None] = queue.SimpleQueue()

    def run(self) -> None:
        set_thread_name("sctd-publisher")
        set_timer_slack(1)
        set_realtime(max(0, self.rt_priority - 1))
        q = self.queue
        while (item := q.get()) is not None:
            if isinstance(item, dict):
                self.status.put(codec.pack(item))
            elif isinstance(item, list):  # the tick's oversized samples: dropped here
                del item
            elif self.ros is not None:
                try:
                    self.ros.target(*item)
                except Exception:  # the ROS copy must never cost the targets
                    log.exception("publishing the ROS target pose failed; ROS output stopped")
                    self.ros = None

    def close(self) -> None:
        self.queue.put(None)
        self.join(timeout=5.0)

    def __enter__(self) -> Publisher:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
