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

from collections.abc import Sequence

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
from .endpoint import BusEndpoint
from .link import ACCEPTED, DUPLICATED, classify
from .virtual import drain


class JointDrives(BusEndpoint):
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
        Status bits of the last state frames (a new array when they change, never
        modified in place).
    brake_events : int
        Times a drive engaged its brake after running.
    stats : LinkStats
        Receive-side counters over SYNC and command frames.
    """

    def __init__(self, bus: can.BusABC, codecs: JointBusCodecs, tau_max: np.ndarray,
                 timeout: float = 0.01) -> None:
        super().__init__(bus, codecs)
        n = self.n
        self.tau_max = np.asarray(tau_max, dtype=float).copy()
        self._tau_min = -self.tau_max
        self.timeout = float(timeout)
        self.tau_cmd = np.zeros(n)
        self.braked = np.ones(n, dtype=bool)
        self.timed_out = np.zeros(n, dtype=bool)
        self.status = np.full(n, STATUS_BRAKED, dtype=int)
        self._any_saturated = False
        self.brake_events = 0
        self._enabled = np.zeros(n, dtype=bool)
        self._last_cmd_t = np.full(n, -np.inf)
        self._last_counter: list[int | None] = [None] * n
        self._same_counter: int | None = None  # the counter of every _last_counter, if one
        self._sync_counter: int | None = None
        self._sync_last: int | None = None
        self._counter = 0
        self._cmd_index = {c.frame_id: i for i, c in enumerate(codecs.cmd)}
        self._cmd_unpack = [c.unpack for c in codecs.cmd]
        self._sync_codec = codecs.sync
        self._unpack_cmds = codecs.cmd_group.unpacker(("Mode", "Torque"))
        self._state_group = codecs.state_group
        self._tau_hi = self.tau_max.tolist()
        self._tau_hi_min = min(self._tau_hi)
        self._modes_on = (MODE_ENABLE,) * n
        self._any_braked = True  # drives power up braked
        self._running_t: float | None = None
        self._status_of_list: np.ndarray | None = None  # self.status as _status_list
        self._status_list: list[int] = []
        self._state_ids = frozenset(c.frame_id for c in codecs.state)

    def receive(self, t: float) -> None:
        """Read every pending frame at time ``t`` (s) and update the commands.

        A cycle whose SYNC and commands arrived exactly as the controller sent them
        (nearly every cycle) is decoded in one call; anything else is checked frame by
        frame, with the same outcome for the clean case (tested).
        """
        frames = drain(self.bus)
        n = self.n
        if len(frames) == n + 1 and frames[0].arbitration_id == SYNC_ID:
            ok, counter, _vals = self._sync_codec.decode(frames[0].data)
            if ok:
                kind, lost = classify(counter, self._sync_last, None, False)
                vals = self._unpack_cmds(frames[1:], counter) if kind == ACCEPTED else None
                if vals is not None:
                    self._receive_clean(t, counter, lost, vals[0], vals[1])
                    return
        self._receive_each(frames, t)

    def take(self, t: float, counter: int, modes: tuple[int, ...], taus: Sequence[float]) -> None:
        """The clean cycle at time ``t`` (s) without its frames: a SYNC with ``counter``,
        then every joint's command with these values (as decoded: ``Mode``, ``Torque``).
        What :meth:`receive` makes of those frames off the bus; an arm without frames
        (:class:`~.values.BusValues`) calls it directly.

        Raises
        ------
        ValueError
            ``counter`` is not the next cycle's (frames off a bus would be checked one
            by one; values handed over directly come in order).
        """
        kind, lost = classify(counter, self._sync_last, None, False)
        if kind != ACCEPTED:
            raise ValueError(f"JointDrives.take: counter {counter} after {self._sync_last} is not a "
                             "new cycle's")
        self._receive_clean(t, counter, lost, modes, taus)

    def _receive_clean(self, t: float, counter: int, sync_lost: int, modes: tuple[int, ...],
                       taus: Sequence[float]) -> None:
        """The clean cycle: a new SYNC, then every joint's command, in order, intact, of
        the SYNC's cycle. Each is accepted (what :meth:`_receive_each` concludes, frame
        by frame)."""
        n = self.n
        st = self.stats
        st.received += n + 1
        st.accepted += n + 1
        st.lost += sync_lost
        same = self._same_counter
        if same is not None:  # every joint's last command was of one cycle: lost alike
            st.lost += n * ((counter - same - 1) & 0xF)
        else:
            for prev in self._last_counter:
                if prev is not None:
                    st.lost += (counter - prev - 1) & 0xF
        self._sync_last = self._sync_counter = self._counter = counter
        self._last_counter = [counter] * n
        self._same_counter = counter
        self._last_cmd_t.fill(t)
        self.tau_cmd[:] = taus
        if modes == self._modes_on:  # (the usual case, without a loop)
            self._enabled.fill(True)
            # within every limit; the smallest limit decides at once for small torques
            lim = self._tau_hi_min
            running = ((-lim <= min(taus) and max(taus) <= lim)
                       or all(-hi <= x <= hi for x, hi in zip(taus, self._tau_hi, strict=True)))
        else:
            self._enabled[:] = [bool(m & MODE_ENABLE) for m in modes]
            running = False
        # every drive got an enabling, unsaturated command now: output()'s quick case
        self._running_t = t if running else None

    def _receive_each(self, frames: list[can.Message], t: float) -> None:
        """:meth:`receive`, frame by frame: any frames, in any order and state."""
        st = self.stats
        self._same_counter = None  # (set below joint by joint)
        n = self.n
        got = [False] * n
        index, unpack, last = self._cmd_index, self._cmd_unpack, self._last_counter
        tau_hi = self._tau_hi
        last_t = self._last_cmd_t
        enabled = self._enabled
        tau_cmd = self.tau_cmd
        n_running = 0  # joints with an accepted enabling command within their limits
        for msg in frames:
            fid = msg.arbitration_id
            i = index.get(fid)
            if i is None:
                if fid == SYNC_ID:
                    self._receive_sync(msg.data)
                elif fid not in self._state_ids:  # state frames are other nodes' business
                    st.unknown += 1
                continue
            checked = st.check(msg.data, unpack[i])
            if checked is None:
                continue
            counter, vals = checked
            ref = self._sync_counter
            if ref is not None and counter == ((ref + 1) & 0xF):
                ref = self._sync_counter = counter  # this cycle's SYNC was lost
            if not st.admit(counter, last[i], ref, got[i]):
                continue
            got[i] = True
            last[i] = counter
            last_t[i] = t
            mode, tau = vals[0], vals[1]
            enabled[i] = on = bool(int(mode) & MODE_ENABLE)
            tau_cmd[i] = tau
            if on and -tau_hi[i] <= tau <= tau_hi[i]:
                n_running += 1
        st.missing += got.count(False)
        if self._sync_counter is not None:
            self._counter = self._sync_counter
        # every drive got an enabling, unsaturated command now: output()'s quick case
        self._running_t = t if n_running == n else None

    def _receive_sync(self, data: bytes | bytearray) -> None:
        st = self.stats
        st.received += 1
        ok, counter, _vals = self._sync_codec.decode(data)
        if not ok:
            st.corrupted += 1
            return
        kind, lost = classify(counter, self._sync_last, None, False)
        if kind == ACCEPTED:
            st.accepted += 1
            st.lost += lost
            self._sync_last = self._sync_counter = counter
        elif kind == DUPLICATED:
            st.duplicated += 1
        else:
            st.stale += 1

    def output(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Torques to apply and brake states at time ``t``.

        Returns
        -------
        tau : ndarray, shape (n,)
            Saturated command torque; zero on braked joints.
        braked : ndarray of bool, shape (n,)
        """
        if self._running_t == t and self.timeout >= 0.0 and not self._any_braked:
            # Every drive was commanded at t, enabled, within its torque limit, and none
            # was braked: nothing times out or saturates (what the general case below
            # computes, without its dozen array operations).
            if self._any_saturated or self.status[0] != STATUS_ENABLED:
                self.status = np.full(self.n, STATUS_ENABLED)
            self._any_saturated = False
            return self.tau_cmd.copy(), self.braked
        timed_out = (t - self._last_cmd_t) > self.timeout
        braked = timed_out | ~self._enabled
        # minimum/maximum: a third of np.clip's overhead on 7 elements
        tau = np.minimum(np.maximum(self.tau_cmd, self._tau_min), self.tau_max)
        saturated = tau != self.tau_cmd
        if np.count_nonzero(braked) or self._any_braked:
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
        self._any_braked = bool(np.count_nonzero(braked))
        self.timed_out = timed_out
        return tau, braked

    def state_frames(self, q: np.ndarray, dq: np.ndarray, tau: np.ndarray,
                     at_limit: np.ndarray | None = None, stamp: float = 0.0
                     ) -> list[can.Message]:
        """The cycle's state frames (one per joint), stamped with the SYNC counter."""
        return self._state_group.frames(stamp, self._counter, self.state_status(at_limit), q.tolist(),
                                        dq.tolist(), tau.tolist())

    def state_status(self, at_limit: np.ndarray | None = None) -> list[int]:
        """The status bits the cycle's state frames carry, one per joint: :attr:`status`,
        and ``SATURATED`` where the joint is ``at_limit`` (shape (n,), bool). The list is
        shared between cycles while the bits stay the same: do not modify it."""
        if at_limit is not None and np.count_nonzero(at_limit):
            return (self.status | np.where(at_limit, STATUS_SATURATED, 0)).tolist()
        if self.status is not self._status_of_list:  # (a new array on every change)
            self._status_of_list = self.status
            self._status_list = self.status.tolist()
        return self._status_list
