"""The daemon's publisher thread: targets and status encoded and put off the tick thread."""

from __future__ import annotations

import logging
import queue
import threading
import time
from typing import Any

from ..timing import Histogram, set_realtime, set_timer_slack
from ..wire import codec

log = logging.getLogger("sctd.run")


class Publisher(threading.Thread):
    """Encodes and publishes targets and status off the tick thread: a Zenoh put that
    reaches a remote subscriber writes to the socket (tens of us, with a long tail),
    which would otherwise count against every tick. Runs at one FIFO priority below the
    tick. Queue items: a target's ``(seq, stamp, pose, state, skill id, in_seq, in_device,
    seed)``, a status map (dict), a list of samples to drop (freeing them takes time), or
    None to stop. With ``ros`` (``--ros``), each target is also offered to
    ``ros.target(stamp, pose)`` (CDR, rate-limited) after its own put. A context manager:
    started on entry, stopped and joined on exit."""

    def __init__(self, target: Any, status: Any, rt_priority: int, ros: Any = None):
        super().__init__(name="sctd-publisher", daemon=True)
        self.target = target
        self.status = status
        self.ros = ros
        self.rt_priority = rt_priority
        self.queue: queue.SimpleQueue[tuple | dict | list | None] = queue.SimpleQueue()
        self.put_time = Histogram()  # target puts

    def run(self) -> None:
        set_timer_slack(1)
        set_realtime(max(0, self.rt_priority - 1))
        q = self.queue
        encode = codec.encode_target
        while (item := q.get()) is not None:
            if isinstance(item, dict):
                self.status.put(codec.pack(item))
                continue
            if isinstance(item, list):  # the tick's oversized samples: dropped here
                del item
                continue
            t0 = time.monotonic()
            self.target.put(encode(*item))
            self.put_time.add(time.monotonic() - t0)
            if self.ros is not None:
                try:
                    self.ros.target(item[1], item[2])
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
