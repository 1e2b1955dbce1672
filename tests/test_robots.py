"""The robot-driver contract's pure parts: the registry, the franky driver's clock map and
flags, the scene observer, the state's ``fault`` on the wire. (The drivers against real
arms: tests/test_robot_franky.py.)"""

from __future__ import annotations

import argparse

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sctd import se3
from sctd.robots import RobotDriver, RobotError, driver_names, get_driver
from sctd.task import find_task
from sctd.wire import codec
from sctd_services.robots.franky import ClockMap, FrankyDriver
from sctd_services.robots.observer import observer_for
from sctd_services.robots.service import driver_parser
from tests.conftest import wait_for


def test_the_built_in_drivers_are_registered_and_an_unknown_one_is_named():
    assert driver_names()[:3] == ["sim", "kinematic", "franky"]
    for name in ("sim", "kinematic", "franky"):
        cls = get_driver(name)
        assert issubclass(cls, RobotDriver) and cls.name == name and cls.description
    with pytest.raises(RobotError, match=r"unknown robot driver 'ur5'; known: sim, kinematic, franky"):
        get_driver("ur5")


def test_the_clock_map_takes_the_least_delayed_state_at_once():
    clock = ClockMap()
    # the arm's clock 1000 s behind; delays of 3, 1, 2 ms
    stamps = [clock.stamp(t, t + 1000.0 + d) for t, d in [(0.0, 0.003), (0.001, 0.001), (0.002, 0.002)]]
    assert stamps[0] == pytest.approx(1000.003)
    assert stamps[1] == pytest.approx(1000.002)  # 1 ms delay: the new offset, at once
    assert stamps[2] == pytest.approx(1000.002 + 0.05 * 0.001)  # a larger delay: a fraction of it


def test_the_clock_map_follows_an_arm_that_runs_slower_than_real_time():
    """franky-sim at 0.8 of real time: a state every 1.25 ms of wall time, its clock
    advancing 1 ms. The stamps stay within (1/0.8 - 1) * 1 ms / 0.05 = 5 ms of the wall."""
    clock = ClockMap()
    lag = [w - clock.stamp(0.001 * k, w) for k in range(5000) for w in [1e9 + 0.00125 * k]]
    assert max(lag[1000:]) < 0.0055 and min(lag) >= 0.0


def test_the_clock_map_measures_the_arms_pace():
    """An arm at 0.7 of real time (a state every 1/0.7 ms of wall time): the pace is
    measured within 1 % after a few windows; an arm at real time keeps 1; a reboot (the
    arm's clock back) starts again at 1."""
    slow, real = ClockMap(), ClockMap()
    for k in range(4000):
        slow.stamp(0.001 * k, 1e9 + 0.001 * k / 0.7)
        real.stamp(0.001 * k, 1e9 + 0.001 * k)
    assert slow.pace == pytest.approx(0.7, rel=0.01)
    assert real.pace == pytest.approx(1.0, rel=1e-6)
    slow.stamp(0.0, 1e9 + 10.0)
    assert slow.pace == 1.0


@given(st.floats(-1e3, 1e3), st.floats(0.0, 0.01))
def test_the_clock_map_never_stamps_a_state_after_it_arrived(t0, delay):
    clock = ClockMap()
    for k in range(20):
        wall = 5e8 + t0 + 0.001 * k + delay * (k % 3)
        assert clock.stamp(t0 + 0.001 * k, wall) <= wall + 1e-9


def _franky_args(*argv: str) -> argparse.Namespace:
    return driver_parser(FrankyDriver).parse_args(["--host", "127.0.0.1", *argv])


def test_the_franky_flags_are_checked_where_and_what():
    d = FrankyDriver.from_args(_franky_args("--tool", "0,0,0.1,0,0,0,1", "--stiffness", "1500"), None)
    assert d.host == "127.0.0.1" and d.stiffness == 1500.0 and d.T_ne_ee[2, 3] == pytest.approx(0.1)
    for argv, message in [(("--tool", "0,0,0.1"), r"--tool: expected 7 finite numbers"),
                          (("--base", "0,0,0,0,0,0,2"), r"--base: the quaternion .* is not a unit"),
                          (("--stiffness", "-5"), r"--stiffness: must be positive"),
                          (("--tool", "a,b"), r"--tool: not numbers"),
                          (("--friction", "1,1,1"), r"--friction: needs 7 values, one per joint, got 3"),
                          (("--friction", "1,1,1,1,1,1,-1"), r"--friction: each value must be finite"),
                          (("--friction-viscous", "0,0,0,0,0,0,0"), r"--friction-viscous: needs --friction")]:
        with pytest.raises(RobotError, match=message):
            FrankyDriver.from_args(_franky_args(*argv), None)
    with pytest.raises(RobotError, match="--host"):
        FrankyDriver.from_args(driver_parser(FrankyDriver).parse_args([]), None)
    with pytest.raises(RobotError, match=r"--load task: needs --task$"):
        FrankyDriver.from_args(_franky_args("--load", "task"), None)
    with pytest.raises(RobotError, match="--load task: needs --task with a held object"):
        FrankyDriver.from_args(_franky_args("--load", "task"), find_task("drawer"))
    mass, com = FrankyDriver.from_args(_franky_args("--load", "task"), find_task("pour")).load
    assert mass == pytest.approx(0.5) and com.tolist() == [0.0, 0.0, 0.05]  # bottle 0.2 kg + 0.3 kg inside
    assert FrankyDriver.from_args(_franky_args(), find_task("pour")).load is None
    d = FrankyDriver.from_args(_franky_args("--friction", "1,1,1,1,0.5,0.5,0.25"), None)
    assert d.friction.tolist() == [1, 1, 1, 1, 0.5, 0.5, 0.25] and d.friction_viscous is None


def test_the_observer_judges_a_pour_from_the_hand_and_refuses_contact_tasks():
    pour = find_task("pour")
    obs = observer_for(pour)
    T0 = obs.scene.start_pose()
    assert set(obs.objects()) == {"mug", "bottle_tip"}
    for k in range(100):
        obs.step(10.0 + 0.001 * k, T0)  # still: nothing poured
    out = obs.outcome()
    assert out["done"] is False and out["progress"] == 0.0 and obs.t == pytest.approx(0.099)
    # the hand carries the held frames
    T1 = T0 @ se3.transform_from_pose([0.0, 0.1, 0.0, 0, 0, 0, 1])
    obs.step(10.2, T1)
    tip = obs.objects()["bottle_tip"]
    assert np.allclose(tip[:3, 3], (T1 @ pour.scene.held.frames["bottle_tip"])[:3, 3])
    assert "face.force" in observer_for(find_task("drink")).scene.readings()  # watched, not felt
    for contact_task in ("drawer", "light_switch"):
        with pytest.raises(RobotError, match="needs contact physics"):
            observer_for(find_task(contact_task))


def test_a_state_fault_round_trips_and_a_bad_one_is_refused():
    data = codec.encode_state(3, 1.0, [0, 0, 0, 0, 0, 0, 1], fault="reflex: cartesian_reflex")
    assert codec.decode_state(data).fault == "reflex: cartesian_reflex"
    assert codec.decode_state(codec.encode_state(3, 1.0, [0, 0, 0, 0, 0, 0, 1])).fault is None
    bad = codec.pack({"seq": 1, "stamp": 1.0, "pose": [0, 0, 0, 0, 0, 0, 1], "fault": 7})
    with pytest.raises(codec.DecodeError) as e:
        codec.decode_state(bad)
    assert e.value.reason == "bad_fault"
    long = codec.encode_state(1, 1.0, [0, 0, 0, 0, 0, 0, 1], fault="x" * 5000)
    assert len(codec.decode_state(long).fault or "") == codec.MAX_FAULT_CHARS


class _Arm(RobotDriver):
    """A scripted arm: still at the start pose; ``fail_at`` readings in, it faults."""

    name, description = "scripted", "a test's arm"

    def __init__(self, fail_at: int | None = None):
        self.n, self.fail_at, self.faulted, self.commands, self.recoveries = 0, fail_at, False, [], 0

    @classmethod
    def from_args(cls, args, task):
        return cls()

    @property
    def rate(self) -> float:
        return 1000.0

    def connect(self) -> None:
        pass

    def read(self, timeout: float):
        from sctd.robots import Reading, RobotFault

        self.n += 1
        if self.n == self.fail_at:
            self.faulted = True
            raise RobotFault("reflex", "cartesian_reflex")
        return Reading(float(self.n), se3.transform_from_pose([0.4, 0, 0.5, 0, 0, 0, 1]), mode="move")

    def command(self, T_world_ee, stamp=None) -> None:
        self.commands.append(T_world_ee)

    def recover(self) -> None:
        self.recoveries += 1
        self.faulted = False


def test_the_robot_service_marks_faulted_states_and_starts_seq_again_after_a_recovery():
    from sctd.wire import Keys
    from sctd.wire.session import close_session, open_session
    from sctd_services.robots.service import RobotService, _Recovery
    from sctd_sim.guard import TargetLimits

    session = open_session()
    states: list = []
    sub = session.declare_subscriber(Keys("t").state,
                                     lambda s: states.append(codec.decode_state(s.payload.to_bytes())))
    arm = _Arm(fail_at=4)
    try:
        with RobotService(session, arm, Keys("t"), TargetLimits()) as svc:
            for _ in range(6):
                svc.cycle()
            assert svc.fault is not None and svc.fault.kind == "reflex" and svc.status_message()["fault"]
            svc._recovery = _Recovery()
            svc._run_recovery()
            assert arm.recoveries == 1 and svc.fault is None and svc.seq == 0
            svc.cycle()
            svc._recovery = rec = _Recovery()  # no fault now: nothing to recover
            svc._run_recovery()
            assert rec.error is not None and "no fault" in rec.error and arm.recoveries == 1
            assert wait_for(lambda: len(states) >= 6, timeout=5)
    finally:
        sub.undeclare()
        close_session(session)
    assert [m.seq for m in states] == [0, 1, 2, 3, 4, 0]
    assert [m.fault is not None for m in states] == [False, False, False, True, True, False]
    assert "reflex: cartesian_reflex" in (states[3].fault or "")


def test_the_feed_forward_twist_converges_to_the_targets_velocity():
    """Targets moving at 0.1 m/s along x and turning at 0.5 rad/s about z, one per ms:
    the filtered twist reaches both within 1 % after 10 time constants; a hold (a first
    target again) starts from zero."""
    d = FrankyDriver("127.0.0.1")
    twist = np.zeros(6)
    for k in range(300):
        t = 0.001 * k
        T = se3.transform_from_rt(se3.matrix_from_rotvec([0.0, 0.0, 0.5 * t]), [0.4 + 0.1 * t, 0.0, 0.5])
        twist = d._feed_forward(T, 1000.0 + t)
    assert np.allclose(twist, [0.1, 0, 0, 0, 0, 0.5], rtol=0.01, atol=1e-6)
    d._last_ref = None
    assert np.allclose(d._feed_forward(T, 2000.0), 0.0)


def test_the_feed_forward_twist_is_in_the_arms_time():
    """An arm at half real time (a simulator on a loaded machine) moves its hand in its
    own time: targets at 0.1 m/s of this host's time are 0.2 m/s of the arm's."""
    d = FrankyDriver("127.0.0.1")
    d.clock.pace = 0.5
    twist = np.zeros(6)
    for k in range(300):
        t = 0.001 * k
        twist = d._feed_forward(se3.transform_from_rt(np.eye(3), [0.4 + 0.1 * t, 0.0, 0.5]), 1000.0 + t)
    assert twist[0] == pytest.approx(0.2, rel=0.01)


class _HandArm(_Arm):
    """The scripted arm with a gripper that records the commands it was given."""

    def __init__(self, fail_at: int | None = None):
        super().__init__(fail_at)
        self.grips: list = []

    @property
    def has_gripper(self) -> bool:
        return True

    def grip(self, cmd) -> None:
        self.grips.append((cmd.cmd, cmd.action))


def test_the_robot_service_carries_out_each_gripper_command_once_and_none_late():
    """Repeats of a command number are carried out once; a command that arrives while
    the arm is faulted is passed over, and not carried out after the recovery, though
    its sender still repeats it; a stale one waits for a fresh repeat."""
    import time

    from sctd.wire import Keys
    from sctd.wire.session import close_session, open_session
    from sctd_services.robots.service import RobotService, _Recovery
    from sctd_sim.guard import TargetLimits

    session = open_session()
    pub = session.declare_publisher(Keys("t").gripper)
    arm = _HandArm()

    def repeat(cmd: int, action: str, until, age: float = 0.0) -> None:
        """The sender repeating ``cmd``, a cycle of the service each time, until ``until()``."""
        force = 10.0 if action == "close" else None

        def once() -> bool:
            pub.put(codec.encode_gripper(codec.GripperCmd(0, time.time() - age, cmd, action, None, force)))
            svc.cycle()
            return until()
        assert wait_for(once, 5), (cmd, action, arm.grips, dict(svc.gripper))

    try:
        with RobotService(session, arm, Keys("t"), TargetLimits()) as svc:
            repeat(1, "open", lambda: arm.grips == [(1, "open")])
            repeat(1, "open", lambda: svc._grip_cmd == 1 and len(arm.grips) == 1 and arm.n > 20)
            repeat(2, "close", lambda: svc.gripper["stale"] >= 3, age=5.0)  # stale: not carried out
            assert arm.grips == [(1, "open")]
            repeat(2, "close", lambda: arm.grips[-1] == (2, "close"))
            arm.fail_at = arm.n + 1  # the next reading faults: this open comes while faulted
            repeat(3, "open", lambda: svc.gripper["faulted"] == 1)
            assert svc.fault is not None
            svc._recovery = _Recovery()
            svc._run_recovery()
            n = arm.n
            repeat(3, "open", lambda: arm.n > n + 20)  # its sender goes on repeating it: passed over
            assert arm.grips == [(1, "open"), (2, "close")]
            repeat(4, "open", lambda: arm.grips[-1] == (4, "open"))
            assert svc.status_message()["gripper"] == {"carried_out": 3, "stale": svc.gripper["stale"],
                                                       "faulted": 1, "cmd": 4}
    finally:
        pub.undeclare()
        close_session(session)
