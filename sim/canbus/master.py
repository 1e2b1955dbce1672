"""The controller's end of the joint bus: SYNC and commands out, joint states in."""

from __future__ import annotations

import can
import numpy as np

from .codec import MODE_ENABLE, JointBusCodecs
from .frames import new_message
from .link import LinkStats
from .virtual import drain, send_batch


class BusMaster:
    """Controller-side bus endpoint.

    Parameters
    ----------
    bus : can.BusABC
    codecs : JointBusCodecs
    period : float
        Nominal cycle period, s (sent in the SYNC frame).

    Attributes
    ----------
    cycle : int
        Number of the current cycle (its low 4 bits are the frames' counter).
    q, dq, tau : ndarray, shape (n,)
        Last accepted joint position (rad), velocity (rad/s), applied torque (N m).
    status : ndarray of int, shape (n,)
        Last accepted drive status bits (:mod:`.codec` ``STATUS_*``).
    fresh : ndarray of bool, shape (n,)
        Whether joint i delivered an accepted state frame in the current cycle.
    age : ndarray of int, shape (n,)
        Cycles since joint i's last accepted state frame.
    stats : LinkStats
        Receive-side counters over the state frames; ``tx_errors`` counts refused
        cycles (bus-off).
    """

    def __init__(self, bus: can.BusABC, codecs: JointBusCodecs, period: float) -> None:
        self.bus = bus
        self.codecs = codecs
        n = codecs.n_joints
        self.n = n
        self.period = float(period)
        self.cycle = -1
        self.q = np.zeros(n)
        self.dq = np.zeros(n)
        self.tau = np.zeros(n)
        self.status = np.zeros(n, dtype=int)
        self.fresh = np.zeros(n, dtype=bool)
        self.age = np.full(n, 1 << 30)
        self.stats = LinkStats()
        self._last_counter: list[int | None] = [None] * n
        self._state_index = {c.frame_id: i for i, c in enumerate(codecs.state)}
        self._cmd_ids = frozenset(c.frame_id for c in codecs.cmd) | {codecs.sync.frame_id}

    def command_frames(self, tau: np.ndarray, q: np.ndarray, dq: np.ndarray,
                       enable: bool = True, stamp: float = 0.0) -> list[can.Message]:
        """Start a new cycle and build its frames: SYNC, then one command per joint.

        Parameters
        ----------
        tau : array_like, shape (n,)
            Commanded torque, N m.
        q, dq : array_like, shape (n,)
            Positions and velocities the command was computed from (for logging).
        enable : bool, optional
            Enable bit; False makes every drive brake.
        stamp : float, optional
            Timestamp put on the frames.

        Returns
        -------
        list of can.Message
            The cycle's batch, in bus order.
        """
        self.cycle = (self.cycle + 1) & 0xFFFFFFFF
        counter = self.cycle & 0xF
        sync = self.codecs.sync
        out = [new_message(stamp, sync.frame_id, False, 8,
                           sync.pack(counter, 0, self.cycle, self.period))]
        mode = MODE_ENABLE if enable else 0
        for codec, ti, qi, dqi in zip(self.codecs.cmd, tau.tolist(), q.tolist(), dq.tolist(),
                                      strict=True):
            out.append(new_message(stamp, codec.frame_id, False, 8,
                                   codec.pack(counter, mode, ti, qi, dqi)))
        return out

    def send(self, frames: list[can.Message]) -> bool:
        """Send a cycle's batch; False (counted in ``stats.tx_errors``) if refused."""
        try:
            send_batch(self.bus, frames)
        except can.CanError:
            self.stats.tx_errors += 1
            return False
        return True

    def receive(self) -> np.ndarray:
        """Read pending state frames of the current cycle.

        Returns
        -------
        ndarray of bool, shape (n,)
            :attr:`fresh`: joints whose state was updated this cycle.
        """
        st = self.stats
        fresh = [False] * self.n
        reference = self.cycle & 0xF
        codecs = self.codecs.state
        for msg in drain(self.bus):
            i = self._state_index.get(msg.arbitration_id)
            if i is None:
                if msg.arbitration_id not in self._cmd_ids:
                    st.unknown += 1
                continue
            st.received += 1
            data = msg.data
            if len(data) != 8:
                st.corrupted += 1
                continue
            ok, counter, vals = codecs[i].unpack(data)
            if not ok:
                st.corrupted += 1
                continue
            if not st.admit(counter, self._last_counter[i], reference, fresh[i]):
                continue
            fresh[i] = True
            self._last_counter[i] = counter
            self.status[i] = int(vals[0])
            self.q[i] = vals[1]
            self.dq[i] = vals[2]
            self.tau[i] = vals[3]
        n_missing = fresh.count(False)
        if n_missing:
            st.missing += n_missing
            self.fresh[:] = fresh
            self.age += 1
            self.age[self.fresh] = 0
        else:
            self.fresh.fill(True)
            self.age.fill(0)
        return self.fresh
