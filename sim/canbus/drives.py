"""Joint drives on the bus: take torque commands, brake when they stop, report state.

One :class:`JointDrives` object plays the seven drive nodes, sharing one bus endpoint
(each drive only reads its own command id, as a real node's acceptance filter would).

Per cycle (see :class:`sctd_sim.arm.SimArm`): :meth:`JointDrives.receive` reads the
SYNC and command frames, :meth:`JointDrives.output` gives the torques to apply and
which joints are braked, and after the physics step :meth:`JointDrives.state_frames`
reports position, velocity, applied torque and status.

Brake logic, per joint: the brake engages (the joint is held at its position by the
dynamics, see :class:`sctd_sim.dynamics.ArmDynamics`) when the last accepted command is
older than ``timeout`` or disables the drive; the drive reports ``BRAKED`` and, after
a timeout, ``TIMEOUT`` in its state frame and counts a brake event. It releases on the
next fresh command with the enable bit. Drives power up braked.
"""

from __future__ import annotations

import can
import numpy as np

from .codec import (
    MODE_ENABLE,
    STATUS_BRAKED,
    STATUS_ENABLED,
    STATUS_SATURATED,
    STATUS_TIMEOUT,
    SYNC_ID,
    JointBusCodecs,
)
from .frames import new_message
from .link import ACCEPTED, DUPLICATED, LinkStats, classify
from .virtual import drain, send_batch


class JointDrives:
    """The arm's joint drives as bus nodes.

    Parameters
    ----------
    bus : can.BusABC
        The drives' bus endpoint.
    codecs : JointBusCodecs
    tau_max : array_like, shape (n,)
        Torque limits, N m; commands saturate there (and report ``SATURATED``).
    timeout : float, optional
        Command timeout, s, after which a drive brakes.

    Attributes
    ----------
    tau_cmd : ndarray, shape (n,)
        Last accepted command torque per joint.
    braked : ndarray of bool, shape (n,)
    status : ndarray of int, shape (n,)
        Status bits of the last state frames.
    brake_events : int
        Times a drive engaged its brake after running.
    stats : LinkStats
        Receive-side counters over SYNC and command frames.
    """

    def __init__(self, bus: can.BusABC, codecs: JointBusCodecs, tau_max: np.ndarray,
                 timeout: float = 0.01) -> None:
        self.bus = bus
        self.codecs = codecs
        n = codecs.n_joints
        self.n = n
        self.tau_max = np.asarray(tau_max, dtype=float).copy()
        self._tau_min = -self.tau_max
        self.timeout = float(timeout)
        self.tau_cmd = np.zeros(n)
        self.braked = np.ones(n, dtype=bool)
        self.timed_out = np.zeros(n, dtype=bool)
        self.status = np.full(n, STATUS_BRAKED, dtype=int)
        self._any_saturated = False
        self.brake_events = 0
        self.stats = LinkStats()
        self._enabled = np.zeros(n, dtype=bool)
        self._last_cmd_t = np.full(n, -np.inf)
        self._last_counter: list[int | None] = [None] * n
        self._sync_counter: int | None = None
        self._sync_last: int | None = None
        self._counter = 0
        self._cmd_index = {c.frame_id: i for i, c in enumerate(codecs.cmd)}
        self._sync_codec = codecs.sync
        self._state_codecs = codecs.state
        self._state_ids = frozenset(c.frame_id for c in codecs.state)

    def receive(self, t: float) -> None:
        """Read every pending frame at time ``t`` (s) and update the commands."""
        st = self.stats
        got = [False] * self.n
        cmd_codecs = self.codecs.cmd
        last_t = self._last_cmd_t
        enabled = self._enabled
        tau_cmd = self.tau_cmd
        for msg in drain(self.bus):
            fid = msg.arbitration_id
            if fid == SYNC_ID:
                st.received += 1
                ok, counter, _vals = self._sync_codec.decode(msg.data)
                if not ok:
                    st.corrupted += 1
                    continue
                kind, lost = classify(counter, self._sync_last, None, False)
                if kind == ACCEPTED:
                    st.accepted += 1
                    st.lost += lost
                    self._sync_last = self._sync_counter = counter
                elif kind == DUPLICATED:
                    st.duplicated += 1
                else:
                    st.stale += 1
                continue
            i = self._cmd_index.get(fid)
            if i is None:
                if fid not in self._state_ids:  # state frames are other nodes' business
                    st.unknown += 1
                continue
            st.received += 1
            data = msg.data
            if len(data) != 8:
                st.corrupted += 1
                continue
            ok, counter, vals = cmd_codecs[i].unpack(data)
            if not ok:
                st.corrupted += 1
                continue
            ref = self._sync_counter
            if ref is not None and counter == ((ref + 1) & 0xF):
                ref = self._sync_counter = counter  # this cycle's SYNC was lost
            if not st.admit(counter, self._last_counter[i], ref, got[i]):
                continue
            got[i] = True
            self._last_counter[i] = counter
            last_t[i] = t
            enabled[i] = bool(int(vals[0]) & MODE_ENABLE)
            tau_cmd[i] = vals[1]
        st.missing += got.count(False)
        if self._sync_counter is not None:
            self._counter = self._sync_counter

    def output(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Torques to apply and brake states at time ``t``.

        Returns
        -------
        tau : ndarray, shape (n,)
            Saturated command torque; zero on braked joints.
        braked : ndarray of bool, shape (n,)
        """
        timed_out = (t - self._last_cmd_t) > self.timeout
        braked = timed_out | ~self._enabled
        # minimum/maximum: a third of np.clip's overhead on 7 elements
        tau = np.minimum(np.maximum(self.tau_cmd, self._tau_min), self.tau_max)
        saturated = tau != self.tau_cmd
        if np.count_nonzero(braked) or np.count_nonzero(self.braked):
            self.brake_events += int(np.count_nonzero(braked & ~self.braked))
            tau[braked] = 0.0
            self.status = (np.where(braked, STATUS_BRAKED, STATUS_ENABLED)
                           | np.where(timed_out, STATUS_TIMEOUT, 0))
        elif self.status[0] != STATUS_ENABLED or self._any_saturated:
            self.status = np.full(self.n, STATUS_ENABLED)
        self._any_saturated = bool(np.count_nonzero(saturated))
        if self._any_saturated:
            self.status = self.status | np.where(saturated, STATUS_SATURATED, 0)
        self.braked = braked
        self.timed_out = timed_out
        return tau, braked

    def state_frames(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray,
                     at_limit: np.ndarray | None = None, stamp: float = 0.0
                     ) -> list[can.Message]:
        """The cycle's state frames (one per joint), stamped with the SYNC counter."""
        status = self.status
        if at_limit is not None and np.count_nonzero(at_limit):
            status = status | np.where(at_limit, STATUS_SATURATED, 0)
        counter = self._counter
        return [
            new_message(stamp, codec.frame_id, False, 8, codec.pack(counter, si, qi, dqi, ti))
            for codec, si, qi, dqi, ti in zip(self._state_codecs, status.tolist(), q.tolist(),
                                              dq.tolist(), tau.tolist(), strict=True)
        ]

    def send(self, frames: list[can.Message]) -> bool:
        """Send state frames; False (and ``stats.tx_errors``) if the bus refused."""
        try:
            send_batch(self.bus, frames)
        except can.CanError:
            self.stats.tx_errors += 1
            return False
        return True
