"""What both ends of the joint bus share: the bus, the codecs, the counters, sending."""

from __future__ import annotations

import can

from .codec import JointBusCodecs
from .link import LinkStats
from .virtual import send_batch


class BusEndpoint:
    """One node's end of the joint bus (the controller's :class:`~.master.BusMaster`,
    the drives' :class:`~.drives.JointDrives`).

    Parameters
    ----------
    bus : can.BusABC
    codecs : JointBusCodecs

    Attributes
    ----------
    n : int
        Number of joints.
    stats : LinkStats
        Receive-side counters; ``tx_errors`` counts refused sends (bus-off).
    """

    def __init__(self, bus: can.BusABC, codecs: JointBusCodecs) -> None:
        self.bus = bus
        self.codecs = codecs
        self.n = codecs.n_joints
        self.stats = LinkStats()

    def send(self, frames: list[can.Message]) -> bool:
        """Send a cycle's frames in one batch; False (counted in ``stats.tx_errors``) if
        the bus refused."""
        try:
            send_batch(self.bus, frames)
        except can.CanError:
            self.stats.tx_errors += 1
            return False
        return True
