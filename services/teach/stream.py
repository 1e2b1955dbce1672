"""The demonstrator's hand on the simulated arm: targets streamed over Zenoh.

:class:`Teacher` publishes full 6-DoF targets on ``sctd/<robot>/target`` at a fixed
rate (absolute deadlines, stamped with ``time.time()``), the stand-in for a person
moving the arm by hand: no shared-control daemon is involved. It reads the arm's state,
the task object and the scene through a :class:`~sctd_services.record.Recorder`.

What keeps it safe, whatever a motion asks:

- **Paced by the arm.** A motion's clock advances only while the arm keeps up: at full
  rate while the measured pose is within ``lag`` of the last target, slower beyond,
  not at all at twice that (a loaded machine's simulator falling behind real time
  slows the demonstration, it does not wind up the target). So a target is never far
  from the arm (the arm's own guard, :mod:`sctd_sim.guard`, refuses one 0.10 m or
  0.5 rad away). An arm that stays behind for ``stall`` s ends the demonstration.
- **Bounded steps.** Each target is at most ``max_speed`` / ``max_turn`` times the
  period from the previous one (:func:`sctd.runtime.safety.limit_step`), above every
  planned motion's peak speed and below the guard's limits.
- **Finite.** A non-finite target is never published (it ends the demonstration).
- **One commander.** A status message on ``sctd/<robot>/status`` means a shared-control
  daemon commands this robot; two commanders would fight over the arm, so the teacher
  stops at once (:class:`CommanderConflict`), before its first target or at any tick.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import zenoh
from numpy.typing import NDArray

from sctd import se3
from sctd.runtime.safety import limit_step, separation
from sctd.timing import Ticker
from sctd.wire import codec
from sctd.wire.session import MSGPACK

from ..record import Recorder
from .motion import Motion

Array = NDArray[np.float64]
SKILL = "sctd-teach"  # the target messages' ``skill`` field: who commands
GRIP_REPEAT = 0.1  # s between repeats of the fingers' newest command (the wire contract: >= 10 Hz)


class CommanderConflict(RuntimeError):
    """Another program (a shared-control daemon) commands the same robot."""


class TeachingError(RuntimeError):
    """The arm, the simulator or the scene did not do what a demonstration needs."""


class SimulatorLost(TeachingError):
    """No simulator (state, task object, scene) answers: the session cannot go on."""


class WrongScene(TeachingError):
    """The simulator runs another scene than the one to teach."""


@dataclass(frozen=True)
class StreamLimits:
    """How the teacher streams targets.

    Attributes
    ----------
    rate : float
        Targets per second.
    lag : float
        m the arm may trail the last target before a motion slows (it stops at twice).
    lag_rotation : float
        rad, likewise.
    stall : float
        s a motion may wait for the arm before the demonstration ends.
    max_speed, max_turn : float
        m/s and rad/s no step between two targets exceeds.
    state_timeout : float
        s without a state after which the simulator counts as gone: long enough that a
        machine too busy to keep time for a few seconds is not taken for a lost simulator.
    """

    rate: float = 250.0
    lag: float = 0.02
    lag_rotation: float = 0.12
    stall: float = 5.0
    max_speed: float = 0.25
    max_turn: float = 1.5
    state_timeout: float = 5.0


class Teacher:
    """Targets for the simulated arm, the scene reset, the watch for another commander.

    A context manager: the target publisher and the status subscriber are declared
    while entered.

    Parameters
    ----------
    session : zenoh.Session
    rec : Recorder
        Entered; its newest state, task-object pose and scene message are what the
        teacher sees.
    limits : StreamLimits, optional
    """

    def __init__(self, session: zenoh.Session, rec: Recorder, limits: StreamLimits | None = None):
        self.session = session
        self.rec = rec
        self.keys = rec.keys
        self.limits = limits = limits or StreamLimits()
        self.period = 1.0 / limits.rate
        self.phase = "idle"  # the targets' ``state`` field: what the hand does
        self.commander: str | None = None  # who else commands, once seen
        self.T_target: Array | None = None  # the last target published (world)
        self.seq = 0
        self._F_last: se3.Flat | None = None
        self.reseeds = 0  # times the last target was dropped for the measured pose
        self._decls = contextlib.ExitStack()
        # the fingers' newest command, repeated with the targets (numbers new to the robot:
        # from this teacher's start time, in ms, as the runtime's)
        self._grip: codec.GripperCmd | None = None
        self._grip_sent = 0.0
        self._grip_n = int(time.time() * 1000)
        self._grip_seq = 0

    def __enter__(self) -> Teacher:
        with contextlib.ExitStack() as stack:
            self.pub = stack.enter_context(self.session.declare_publisher(
                self.keys.target, congestion_control=zenoh.CongestionControl.DROP, express=True,
                encoding=MSGPACK))
            self.pub_gripper = stack.enter_context(self.session.declare_publisher(
                self.keys.gripper, express=True, encoding=MSGPACK))
            stack.enter_context(self.session.declare_subscriber(self.keys.status, self._on_status))
            self._decls = stack.pop_all()
        return self

    def __exit__(self, *exc: object) -> None:
        self._decls.close()

    def _on_status(self, sample: zenoh.Sample) -> None:
        if self.commander is not None:
            return
        try:
            msg = codec.unpack_map(sample.payload.to_bytes())
            who = f"skill {msg.get('skill_name') or msg.get('skill')!s}, mode {msg.get('mode')!s}"
        except codec.DecodeError:
            who = "a status message that does not decode"
        self.commander = f"{who} on {self.keys.status}"

    def check_commander(self) -> None:
        """Raise :class:`CommanderConflict` once another commander's status was seen."""
        if self.commander is not None:
            raise CommanderConflict(
                f"a shared-control daemon commands sctd/{self.keys.robot} ({self.commander}): two "
                "commanders would fight over the arm; stop it, or teach another --robot")

    # -- what the arm is doing --------------------------------------------------------
    def measured(self) -> Array:
        """The arm's newest ``T_world_ee``.

        Raises
        ------
        SimulatorLost
            No state for ``state_timeout`` s (the simulator went away).
        """
        st = self.rec.state
        if st is None or time.time() - st.stamp > self.limits.state_timeout:
            raise SimulatorLost(f"no state on {self.keys.state} for {self.limits.state_timeout:g} s: "
                                "the simulator is gone or stalled")
        return se3.transform_from_pose(st.pose)

    def target(self) -> Array:
        """The last target published (world), else the arm's measured pose."""
        return self.T_target.copy() if self.T_target is not None else self.measured()

    def object_pose(self) -> Array:
        """``T_world_obj`` of the recorder's task object (newest)."""
        name = self.rec.object_name
        pose = self.rec.objects.get(name) if name else None
        if pose is None:
            raise TeachingError(f"no pose of the task object {name!r} on {self.keys.objects(name or '*')}")
        return se3.transform_from_pose(pose)

    def _pace(self, T_measured: Array) -> float:
        """1 while the arm is within ``lag`` of the last target, 0 from twice that."""
        if self._F_last is None:
            return 1.0
        d, a = separation(se3.flat_from_transform(T_measured), self._F_last)
        L = self.limits
        return min(1.0, max(0.0, min(2.0 - d / L.lag, 2.0 - a / L.lag_rotation)))

    # -- targets ----------------------------------------------------------------------
    def _publish(self, T_world: Array) -> None:
        """One target: bounded step from the previous one, finite, stamped now."""
        F = se3.flat_from_transform(T_world)
        if self._F_last is not None:
            F = limit_step(self._F_last, F, self.limits.max_speed * self.period,
                           self.limits.max_turn * self.period)
        pose = se3.pose_from_flat(F)
        if not all(math.isfinite(x) for x in pose):
            raise TeachingError(f"a non-finite target in phase {self.phase}: {pose}")
        now = time.time()
        self.pub.put(codec.encode_target(self.seq, now, pose, self.phase, SKILL, -1))
        self.seq += 1
        if self._grip is not None and now - self._grip_sent >= GRIP_REPEAT:
            self._put_grip(now)
        self._F_last = F
        self.T_target = se3.transform_from_flat(F)

    def grip(self, action: str, force: float | None = None) -> None:
        """Command the fingers (``close`` squeezing at most ``force`` N, ``open``): sent at
        once, then repeated with the targets every :data:`GRIP_REPEAT` s."""
        self._grip_n += 1
        self._grip = codec.GripperCmd(0, 0.0, self._grip_n, action, force=force, skill=SKILL)
        self._put_grip(time.time())

    def _put_grip(self, now: float) -> None:
        assert self._grip is not None
        self.pub_gripper.put(codec.encode_gripper(self._grip._replace(seq=self._grip_seq, stamp=now)))
        self._grip_seq += 1
        self._grip_sent = now

    def hold(self, until: Callable[[], bool], timeout: float) -> bool:
        """Hold the last target (the arm's pose if there is none yet) until ``until()``
        is true (True) or ``timeout`` s passed (False)."""
        if self.T_target is None:
            self.T_target = self.measured()
        ticker = Ticker(self.period, spin=0.0)
        end = time.monotonic() + timeout
        while True:
            now, _ = ticker.wait()
            self.check_commander()
            self.measured()
            self._publish(self.T_target)
            if until():
                return True
            if now > end:
                return False

    def follow(self, motion: Motion, T_world_obj: Array,
               stop_when: Callable[[], bool] | None = None) -> bool:
        """Stream ``motion`` (object frame, placed at ``T_world_obj``), paced by the arm;
        True when it ran to its end, False when ``stop_when()`` became true first.

        Raises
        ------
        TeachingError
            The arm stayed ``lag`` behind for ``stall`` s, or the simulator went away.
        CommanderConflict
        """
        ticker = Ticker(self.period, spin=0.0)
        t = waited = 0.0
        while True:
            ticker.wait()
            self.check_commander()
            T_meas = self.measured()
            k = self._pace(T_meas)
            t = min(motion.duration, t + k * self.period)
            waited = waited + self.period if k == 0.0 else 0.0
            if waited > self.limits.stall:
                assert self._F_last is not None
                d, a = separation(se3.flat_from_transform(T_meas), self._F_last)
                raise TeachingError(f"the arm did not follow in phase {self.phase}: {d * 100:.1f} cm "
                                    f"and {math.degrees(a):.0f} deg behind its target for "
                                    f"{self.limits.stall:g} s")
            self._publish(T_world_obj @ motion.pose(t))
            if stop_when is not None and stop_when():
                return False
            if t >= motion.duration:
                return True

    def reseed_if_behind(self) -> bool:
        """Forget the last target when the arm is more than ``lag`` behind it (it could
        not follow: a joint limit, a collision), so that the next motion starts from
        where the arm is rather than chasing a target it cannot reach; whether it did.
        The next target is then the measured pose (the robot's guard may refuse that one
        jump, and follows from the next)."""
        if self._F_last is None:
            return False
        d, a = separation(se3.flat_from_transform(self.measured()), self._F_last)
        if d <= self.limits.lag and a <= self.limits.lag_rotation:
            return False
        self._F_last = None
        self.T_target = None
        self.reseeds += 1
        return True

    def settle(self, tolerance: float = 0.005, tolerance_rotation: float = 0.03,
               timeout: float = 3.0) -> bool:
        """Hold the last target until the arm is within the tolerances of it."""
        return self.hold(lambda: self.settled(tolerance, tolerance_rotation), timeout)

    def settled(self, tolerance: float = 0.005, tolerance_rotation: float = 0.03) -> bool:
        """Whether the arm is within the tolerances (m, rad) of the last target."""
        assert self._F_last is not None
        d, a = separation(se3.flat_from_transform(self.measured()), self._F_last)
        return d <= tolerance and a <= tolerance_rotation

    # -- the scene --------------------------------------------------------------------
    def reset_scene(self, scene: str, timeout: float = 10.0, home: bool = False) -> dict:
        """Reset the scene (``sim/reset``) while holding the arm; with ``home``, the arm
        put back at rest in its start posture as well (the teacher then starts again from
        where the arm is); the reply's map.

        Raises
        ------
        TeachingError
            An error reply, or none within ``timeout`` s.
        """
        request = {"scene": scene, "arm": True} if home else {"scene": scene}
        replies = self.session.get(self.keys.sim_reset, payload=codec.pack(request),
                                   encoding=MSGPACK, timeout=timeout)
        got: list[zenoh.Reply] = []

        def answered() -> bool:
            try:
                r = replies.try_recv()
            except zenoh.ZError:  # closed: no (more) replies
                return True
            if r is not None:
                got.append(r)
            return bool(got)
        if home:  # (no target meanwhile: the arm is put where no old target may pull it from)
            end = time.monotonic() + timeout + 1.0
            while not answered() and time.monotonic() < end:
                time.sleep(self.period)
        else:
            self.hold(answered, timeout + 1.0)
        if not got:
            raise TeachingError(f"no simulator answered on {self.keys.sim_reset} within {timeout:g} s")
        reply = got[0]
        sample = reply.ok if reply.ok is not None else reply.err
        try:
            if sample is None:
                raise codec.DecodeError("empty")
            body = codec.unpack_map(sample.payload.to_bytes())
        except codec.DecodeError as e:
            raise TeachingError(f"{self.keys.sim_reset}: a reply that does not decode ({e})") from None
        if reply.ok is None:
            raise TeachingError(f"{self.keys.sim_reset}: refused: {body.get('error')}")
        if home:  # start again from the arm, once its state shows it there
            asked = time.time()
            self._F_last = self.T_target = None
            end = time.monotonic() + self.limits.state_timeout
            while (self.rec.state is None or self.rec.state.stamp <= asked) and time.monotonic() < end:
                time.sleep(self.period)
        return body

    def scene_after(self, stamp: float, timeout: float = 3.0) -> dict:
        """The first scene message stamped after ``stamp`` (Unix s), holding the arm
        meanwhile.

        Raises
        ------
        TeachingError
            None within ``timeout`` s.
        """
        def fresh() -> bool:
            sc = self.rec.scene
            return sc is not None and float(sc.get("stamp", 0.0)) > stamp
        if not self.hold(fresh, timeout):
            raise TeachingError(f"no scene message on {self.keys.scene} within {timeout:g} s")
        assert self.rec.scene is not None
        return self.rec.scene
