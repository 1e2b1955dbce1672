"""The controller's end of the joint bus: SYNC and commands out, joint states in."""

from __future__ import annotations

from collections.abc import Sequence

import can
import numpy as np

from .codec import MODE_ENABLE, JointBusCodecs
from .endpoint import BusEndpoint
from .virtual import drain


class BusMaster(BusEndpoint):
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
        super().__init__(bus, codecs)
        n = self.n
        self.period = float(period)
        self.cycle = -1
        self.q = np.zeros(n)
        self.dq = np.zeros(n)
        self.tau = np.zeros(n)
        self.status = np.zeros(n, dtype=int)
        self.fresh = np.zeros(n, dtype=bool)
        self.age = np.full(n, 1 << 30)
        self._last_counter: list[int | None] = [None] * n
        self._same_counter: int | None = None  # the counter of every _last_counter, if one
        self._state_index = {c.frame_id: i for i, c in enumerate(codecs.state)}
        self._status_seen: tuple[int, ...] | None = None  # status as last set from a tuple
        self._all_fresh = False  # fresh all True and age all 0
        self._state_unpack = [c.unpack for c in codecs.state]
        self._state_group = codecs.state_group
        self._sync_frame = codecs.sync.frame
        self._cmd_group = codecs.cmd_group
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
        cycle = self.next_cycle()
        counter = cycle & 0xF
        mode = MODE_ENABLE if enable else 0
        out = self._cmd_group.frames(stamp, counter, [mode] * self.n, tau.tolist(), q.tolist(),
                                     dq.tolist())
        out.insert(0, self._sync_frame(stamp, counter, 0, cycle, self.period))
        return out

    def next_cycle(self) -> int:
        """Start a new cycle: its number (the low 4 bits are its frames' counter)."""
        self.cycle = cycle = (self.cycle + 1) & 0xFFFFFFFF
        return cycle

    def receive(self) -> np.ndarray:
        """Read pending state frames of the current cycle.

        A cycle whose state frames arrived exactly as the drives sent them (nearly
        every cycle) is decoded in one call (:meth:`FrameGroup.unpack_exact
        <sctd_sim.canbus.codec.FrameGroup>`); anything else is checked frame by frame,
        with the same outcome for the clean case (tested).

        Returns
        -------
        ndarray of bool, shape (n,)
            :attr:`fresh`: joints whose state was updated this cycle.
        """
        frames = drain(self.bus)
        reference = self.cycle & 0xF
        vals = self._state_group.unpack_exact(frames, reference)
        if vals is None:
            return self._receive_each(frames, reference)
        return self.accept(*vals)

    def accept(self, status: tuple[int, ...], q: Sequence[float], dq: Sequence[float],
               tau: Sequence[float]) -> np.ndarray:
        """The clean cycle: every joint's state frame, in order, intact, of this cycle,
        with these values (as decoded). Each is accepted (what :meth:`_receive_each`
        concludes, frame by frame). :meth:`receive` calls it for such a cycle off the bus;
        an arm without frames (:class:`~.values.BusValues`) calls it directly.

        Returns
        -------
        ndarray of bool, shape (n,)
            :attr:`fresh` (all True).
        """
        reference = self.cycle & 0xF
        n = self.n
        st = self.stats
        st.received += n
        st.accepted += n
        same = self._same_counter
        if same is not None:  # every joint's last frame was of one cycle: lost alike
            st.lost += n * ((reference - same - 1) & 0xF)
        else:
            for prev in self._last_counter:
                if prev is not None:
                    st.lost += (reference - prev - 1) & 0xF
        self._last_counter = [reference] * n
        self._same_counter = reference
        self.q[:], self.dq[:], self.tau[:] = q, dq, tau
        if status != self._status_seen:  # (status bits rarely change)
            self.status[:] = self._status_seen = status
        if not self._all_fresh:
            self.fresh.fill(True)
            self.age.fill(0)
            self._all_fresh = True
        return self.fresh

    def _receive_each(self, frames: list[can.Message], reference: int) -> np.ndarray:
        """:meth:`receive`, frame by frame: any frames, in any order and state."""
        st = self.stats
        self._same_counter = None  # (set below joint by joint)
        fresh = [False] * self.n
        index, unpack, last = self._state_index, self._state_unpack, self._last_counter
        q, dq, tau, status = self.q, self.dq, self.tau, self.status
        for msg in frames:
            i = index.get(msg.arbitration_id)
            if i is None:
                if msg.arbitration_id not in self._cmd_ids:
                    st.unknown += 1
                continue
            checked = st.check(msg.data, unpack[i])
            if checked is None:
                continue
            counter, vals = checked
            if not st.admit(counter, last[i], reference, fresh[i]):
                continue
            fresh[i] = True
            last[i] = counter
            status[i], q[i], dq[i], tau[i] = vals
        self._status_seen = None
        n_missing = fresh.count(False)
        if n_missing:
            st.missing += n_missing
            self.fresh[:] = fresh
            self.age += 1
            self.age[self.fresh] = 0
            self._all_fresh = False
        else:
            self.fresh.fill(True)
            self.age.fill(0)
            self._all_fresh = True
        return self.fresh
