"""The pure runtime tick: watchdog, hold, speed bounds, offset bound, discontinuities,
re-seeding, finite output."""

from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd import se3
from sctd.runtime.arbiter import InputArbiter
from sctd.runtime.controller import Controller, RuntimeConfig, Sample
from sctd.runtime.safety import limit_step, separation
from sctd.skill import Bundle, load_skill, skill_from_bundle
from sctd.wire.codec import InputMsg
from tests.conftest import trap_skill_yaml
from tests.strategies import poses, rotvecs

ROOT = Path(__file__).resolve().parents[1]
SKILL = load_skill(ROOT / "skills" / "pour.yaml")
T_WORLD_MUG = se3.transform_from_pose([0.6, 0.1, 0.75, 0, 0, 0, 1])
T_START = se3.transform_from_pose([0.3, 0.3, 1.0, 0, 0, 0, 1])


class Fed:
    """A Controller fed through one device's input arbiter, as the tick driver feeds it:
    ``tick`` takes an input message with its arrival time (:func:`inp`), offered once."""

    def __init__(self, c: Controller):
        self.c = c
        cfg = c.config
        self.arbiter = InputArbiter(cfg.input_timeout, cfg.deadband, cfg.stamp_check, c.counters)
        self._last = None

    def __getattr__(self, name):
        return getattr(self.c, name)

    def tick(self, now, wall, msg, state, obj):
        if msg is not None and msg is not self._last:
            self._last = msg
            self.arbiter.offer("pad", msg[0], msg[1])
        return self.c.tick(now, wall, self.arbiter.select(now, wall), state, obj)


def ctl(skill=SKILL, **cfg):
    return Fed(Controller(skill, RuntimeConfig(**cfg)))


def inp(u, t, seq=1, wall=None, buttons=()):
    """An input message sent at ``wall`` (default ``t``) that arrived at ``t``."""
    return InputMsg(seq, t if wall is None else wall, tuple(u), tuple(buttons)), t


def state(T, t, epoch=0, since=0.0):
    return Sample(seq=0, stamp=t, received=t, F=se3.flat_from_transform(T), epoch=epoch, since=since)


_OBJ_F: dict[bytes, tuple] = {}


def obj(t, T=T_WORLD_MUG):
    # the same flat tuple for the same pose, as the daemon keeps it for a still object
    F = _OBJ_F.setdefault(T.tobytes(), se3.flat_from_transform(T))
    return Sample(seq=0, stamp=t, received=t, F=F)


def run(c, us, T_meas=None, dt=0.001, t0=0.0):
    """Tick with a robot that follows the target exactly (unless T_meas is fixed)."""
    t = t0
    out = []
    for k, u in enumerate(us):
        meas = T_meas
        if meas is None:
            meas = c.T_world_target if c.T_world_target is not None else T_START
        r = c.tick(t, t, inp(u, t, seq=k), state(meas, t), obj(t))
        out.append(r)
        t += dt
    return out


def test_waits_for_state_and_object_then_starts_at_measured_pose():
    c = ctl()
    r = c.tick(0.0, 0.0, inp([1, 0, 0], 0.0), None, obj(0.0))
    assert r.mode == "waiting" and r.T_world_target is None
    r = c.tick(0.001, 0.001, inp([0, 0, 0], 0.001), state(T_START, 0.001), obj(0.001))
    assert np.allclose(r.T_world_target, T_START, atol=1e-15)
    assert np.allclose(r.pose, se3.pose_from_transform(T_START), atol=1e-15)


def test_input_moves_target_and_zero_input_never_does():
    c = ctl()
    res = run(c, [[1, 0, 0]] * 100)
    moved = res[-1].T_world_target[:3, 3] - T_START[:3, 3]
    assert np.isclose(moved[0], 0.1 * 0.099, rtol=1e-6)  # 0.1 m/s, 99 ticks of 1 ms after the seed
    held = res[-1].T_world_target.copy()
    res = run(c, [[0, 0, 0]] * 50 + [[0.01, -0.015, 0.0]] * 50, t0=1.0)  # inside the dead band
    assert all(np.array_equal(r.T_world_target, held) for r in res)



def test_ticks_that_catch_up_after_a_stall_move_by_the_time_that_passed():
    """The daemon's ticker runs a few overdue ticks back to back after a stall (5 before
    it skips). Each steps by the time since the last tick, from an allowance of at most
    two periods: over the stall and its catch-up burst the target moves at most the
    speed times the time that passed plus two periods, where a period a tick (the old
    bound) gave the burst five more steps of 0.1 mm. On a steady clock every tick still
    steps a whole period."""
    c = ctl()
    res = run(c, [[1, 0, 0]] * 50)
    x = lambda r: float(r.T_world_target[0, 3])  # noqa: E731
    steps = np.diff([x(r) for r in res[1:]])
    assert np.allclose(steps, 0.1 * 0.001, rtol=1e-9)  # a period a tick, to the last bits
    t0, x0 = 0.049, x(res[-1])
    # a 20 ms stall, then 6 ticks 10 us apart, then on time again
    times = [t0 + 0.020 + k * 1e-5 for k in range(6)] + [t0 + 0.021 + k * 0.001 for k in range(5)]
    out = []
    for k, t in enumerate(times):
        out.append(c.tick(t, t, inp([1, 0, 0], t, seq=100 + k), state(c.T_world_target, t), obj(t)))
    burst = x(out[5]) - x0
    assert burst <= 0.1 * (times[5] - t0 + 2 * 0.001) + 1e-12  # not 6 steps: 0.6 mm
    assert np.isclose(burst, 0.1 * (0.002 + 5e-5), rtol=1e-6)  # the allowance's two periods, then 5 x 10 us
    late = np.diff([x(r) for r in out[5:]])
    assert np.all(late <= 0.1 * np.diff(times[5:]) * (1 + 1e-6) + 1e-15)  # then the time that passed
    assert x(out[-1]) > x(out[5])  # and it moves on


def test_watchdog_stale_input_stops_motion():
    c = ctl()
    run(c, [[1, 0, 0]] * 10)
    T = c.T_world_target.copy()
    t = 0.2  # last input arrived at 0.009: older than 0.1 s
    r = c.tick(t, t, inp([1, 0, 0], 0.009), state(T, t), obj(t))
    assert r.mode == "stopped" and np.array_equal(r.T_world_target, T)
    # A fresh arrival with an old sender stamp is stale too.
    r = c.tick(t, t, inp([1, 0, 0], t, seq=99, wall=t - 0.5), state(T, t), obj(t))
    assert np.array_equal(r.T_world_target, T) and c.counters.stale_input >= 1


def test_stale_object_holds_the_target_stale_state_publishes_nothing_then_reseeds():
    c = ctl()
    run(c, [[1, 0, 0]] * 5)
    T, pose = c.T_world_target.copy(), list(c._pose)
    r = c.tick(3.0, 3.0, inp([1, 0, 0], 3.0), state(T, 3.0), obj(1.0))
    assert r.mode == "hold" and r.pose == pose and np.array_equal(r.T_world_target, T)
    r = c.tick(3.1, 3.1, inp([1, 0, 0], 3.1), state(T, 3.1), obj(3.1))  # back: no re-seed
    assert r.mode == "running" and c.counters.reseeds == 0
    T = c.T_world_target.copy()
    r = c.tick(3.5, 3.5, inp([1, 0, 0], 3.5), state(T, 3.3), obj(3.5))
    assert r.mode == "hold" and r.pose is None and r.T_world_target is None
    # A fresh state arriving with an old sender stamp is stale as well.
    r = c.tick(3.6, 3.6, inp([1, 0, 0], 3.6), Sample(7, 3.0, 3.6, F=se3.flat_from_transform(T)), obj(3.6))
    assert r.mode == "hold" and r.pose is None and c.counters.stale_state >= 1
    # Back: the target starts again at the arm's pose (3 cm from the old target), then
    # moves with the input; nothing jumps.
    T_arm = T @ se3.transform_from_pose([0.03, 0, 0, 0, 0, 0, 1])
    r = c.tick(4.0, 4.0, inp([0, 0, 0], 4.0), state(T_arm, 4.0), obj(4.0))
    assert r.mode == "running" and np.allclose(r.T_world_target, T_arm, atol=1e-15)
    assert c.counters.reseeds == 1


def test_stamp_check_off_judges_state_and_objects_by_arrival_only():
    for check, mode in ((True, "waiting"), (False, "running")):
        c = ctl(stamp_check=check)
        r = c.tick(1.0, 1.0, inp([0, 0, 0], 1.0), Sample(0, -50.0, 1.0, F=se3.flat_from_transform(T_START)),
                   Sample(0, -50.0, 1.0, F=se3.flat_from_transform(T_WORLD_MUG)))
        assert r.mode == mode and (r.pose is not None) == (not check)


@given(st.lists(st.lists(st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                                   st.floats(-1, 1)), min_size=3, max_size=3),
                min_size=1, max_size=30))
@settings(max_examples=60, deadline=None)
def test_output_finite_and_steps_bounded_for_any_input(us):
    c = ctl()
    prev = T_START
    for r in run(c, us):
        T = r.T_world_target
        assert np.all(np.isfinite(T))
        step = np.linalg.norm(T[:3, 3] - prev[:3, 3])
        rot = se3.angle_between3(prev[:3, :3], T[:3, :3])
        assert step <= 0.1 * 0.001 + 1e-12  # skill 0.1 m/s caps the daemon's 0.25
        assert rot <= 0.5 * 0.001 + 1e-9
        prev = T


def test_nan_input_changes_nothing():
    c = ctl()
    run(c, [[0.5, 0, 0]] * 3)
    T = c.T_world_target.copy()
    res = run(c, [[float("nan"), 1, 1], [float("inf"), 0, 0]], t0=0.01)
    assert all(np.array_equal(r.T_world_target, T) for r in res)
    assert c.counters.nonfinite_input == 2


def test_step_scales_with_input_magnitude():
    c = ctl()
    r = run(c, [[0.5, 0, 0], [0.5, 0, 0]])
    assert np.isclose(r[1].T_world_target[0, 3] - r[0].T_world_target[0, 3], 0.5 * 0.1 * 0.001)


def test_target_offset_from_blocked_arm_is_bounded_by_refusing_steps():
    c = ctl(max_offset=0.02)
    res = run(c, [[1, 0, 0]] * 600, T_meas=T_START)  # arm does not move
    d = np.linalg.norm(res[-1].T_world_target[:3, 3] - T_START[:3, 3])
    assert 0.02 - 0.1 * 0.001 < d <= 0.02 and c.counters.offset_limited > 0
    # backing off is allowed; pushing on is not
    T = res[-1].T_world_target.copy()
    back = run(c, [[-1, 0, 0]] * 10, T_meas=T_START, t0=1.0)
    assert back[-1].T_world_target[0, 3] < T[0, 3]


def test_far_measured_pose_with_zero_input_never_moves_the_target():
    """The audit's jump: one state 1.1 m away, zero input. The target stays put (no
    dragging), and a state stream that jumps is a fault: nothing is published."""
    c = ctl()
    run(c, [[0.5, 0, 0]] * 20)
    T = c.T_world_target.copy()
    far = T @ se3.transform_from_pose([1.1, 0, 0, 0, 0, 0, 1])
    r = c.tick(0.1, 0.1, inp([0, 0, 0], 0.1), state(far, 0.1), obj(0.1))  # same epoch: no fault
    assert np.array_equal(r.T_world_target, T)
    r = c.tick(0.101, 0.101, inp([0, 0, 0], 0.101), state(far, 0.101, epoch=1, since=0.101), obj(0.101))
    assert r.mode == "fault" and r.pose is None


def test_fault_reseeds_after_continuous_state_and_zero_input():
    cfg = dict(reseed_after=0.5)
    c = ctl(**cfg)
    run(c, [[0.5, 0, 0]] * 20)
    T_new = T_START @ se3.transform_from_pose([0.2, -0.1, 0.05, 0, 0, 0, 1])
    t, since = 1.0, 1.0
    modes = []
    while t < 1.7:
        u = [1, 0, 0] if t < 1.6 else [0, 0, 0]  # pushing holds the fault past reseed_after
        r = c.tick(t, t, inp(u, t), state(T_new, t, epoch=1, since=since), obj(t))
        modes.append((round(t, 3), r.mode))
        if r.pose is not None:
            break
        t += 0.001
    assert all(m == "fault" for _, m in modes[:-1]) and modes[-1][0] >= 1.6
    assert np.allclose(r.T_world_target, T_new, atol=1e-15) and c.counters.reseeds == 1
    # then it moves from there, within the bound
    r2 = c.tick(t + 0.001, t + 0.001, inp([1, 0, 0], t + 0.001), state(T_new, t + 0.001, 1, since), obj(t))
    assert 0 < np.linalg.norm(r2.T_world_target[:3, 3] - T_new[:3, 3]) <= 0.1 * 0.001 + 1e-12


def test_unused_input_axes_do_not_move_the_target():
    """pour's carry state maps three axes; a 6-axis input with only axes 3-5 pushed is a
    zero command for it, so constraint corrections cannot move the target either."""
    c = ctl()
    run(c, [[0, 0, 0]] * 3)
    T = c.T_world_target.copy()
    assert c.engine.input_axes == (0, 1, 2)
    res = run(c, [[0, 0, 0, 1, 1, 1]] * 20, t0=0.01)
    assert all(np.array_equal(r.T_world_target, T) for r in res)


def test_fsm_changes_state_along_the_way():
    c = ctl()
    # Put the tip near the mug opening: ee 0.12 below the tip.
    T_near = T_WORLD_MUG @ se3.transform_from_pose([0.0, 0.0, 0.08 - 0.12, 0, 0, 0, 1])
    c.tick(0.0, 0.0, inp([0, 0, 0], 0.0), state(T_near, 0.0), obj(0.0))
    states = [r.state for r in run(c, [[0, 0, 0]] * 400, T_meas=T_near, t0=0.001)]
    assert states[-1] == "pour" and "approach" in states


def test_swap_keeps_state_by_name():
    c = ctl()
    c.engine.reset(0.0, "approach")
    c.swap(load_skill(ROOT / "skills" / "pour.yaml"), 1.0)
    assert c.engine.state == "approach" and c.counters.swaps == 1
    c.swap(load_skill(ROOT / "skills" / "drawer.yaml"), 2.0)
    assert c.engine.state == "reach"


def test_non_finite_target_is_refused_and_counted():
    c = ctl()
    run(c, [[0.5, 0, 0]] * 3)
    T, pose = c.T_world_target.copy(), list(c._pose)
    c.engine.command = lambda F, u, dt: (float("nan"),) * 12
    res = run(c, [[0.5, 0, 0]] * 3, t0=0.01)
    assert c.counters.nonfinite_output == 3
    assert all(np.array_equal(r.T_world_target, T) and r.pose == pose for r in res)


def pour_mix(n):
    """Inputs that translate, tilt and pour (the approach and pour states rotate)."""
    k = np.arange(n)
    return np.stack([0.8 * np.sin(k * 0.013), 0.8 * np.cos(k * 0.007), np.sin(k * 0.005)], 1).tolist()


@given(st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3), st.floats(-np.pi, np.pi))
@settings(max_examples=10, deadline=None)  # 1,500 ticks each
def test_published_pose_is_the_world_target_and_stays_orthonormal(offset, yaw):
    """The pose composed on floats (object pose times object-frame target) is the world
    target's, for any object pose; orientations stay on SO(3) over many rotating ticks."""
    T_mug = se3.transform_from_pose([*offset, *se3.quaternion_from_rotvec([0.1, -0.2, yaw]).tolist()])
    T_near = T_mug @ se3.transform_from_pose([0.0, 0.0, 0.08 - 0.12, 0, 0, 0, 1])
    c = ctl()
    t = 0.0
    states = set()
    for k, u in enumerate(pour_mix(1500)):
        meas = c.T_world_target if c.T_world_target is not None else T_near
        r = c.tick(t, t, inp(u, t, seq=k), state(meas, t), obj(t, T_mug))
        states.add(r.state)
        t += 0.001
        T = r.T_world_target
        assert np.allclose(se3.transform_from_pose(r.pose), T, atol=1e-12)
        assert np.isclose(np.linalg.norm(r.pose[3:]), 1.0, atol=1e-12) and r.pose[6] >= 0.0
        assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)
    assert {"approach", "pour"} <= states  # the rotating states were exercised


def test_moving_object_without_input_never_moves_the_target():
    """A new object pose re-expresses the held target; the world target stays put."""
    c = ctl()
    run(c, [[0.5, 0.2, 0]] * 5)
    T, pose = c.T_world_target.copy(), list(c._pose)
    for k in range(20):
        t = 0.01 + 0.001 * k
        T_mug = se3.transform_from_pose([0.6 + 0.001 * k, 0.1, 0.75, 0, 0, 0.01 * k, 1])
        r = c.tick(t, t, inp([0, 0, 0], t), state(T, t), obj(t, T_mug))
        assert np.array_equal(r.T_world_target, T) and r.pose == pose


def test_histogram_percentiles_and_clear():
    from sctd.timing import Histogram
    h = Histogram()
    for k in range(1, 101):
        h.add(k * 1e-5)  # 0.01 .. 1 ms
    h.add(1.0)  # beyond the last bin: reported as the max
    assert abs(h.percentile(50) - 0.51e-3) < 2 * Histogram.BIN  # within a bin
    assert h.percentile(100) == 1.0 and h.n == 101
    h.clear()
    assert h.n == 0 and h.max == 0.0 and not any(h.counts) and h.percentile(99) == 0.0
    h.add(2e-5)
    assert abs(h.percentile(99) - 2e-5) < 2 * Histogram.BIN
    # merged: the samples of both, as if added to one
    other, both = Histogram(), Histogram()
    for x in (1e-5, 3e-4, 2e-3):
        other.add(x)
        both.add(x)
    both.add(2e-5)
    h.merge(other)
    assert h.counts == both.counts and h.n == both.n == 4 and h.max == both.max == 2e-3


@given(st.lists(st.tuples(st.sampled_from(["still", "drift", "jump", "restart", "stale"]),
                          st.sampled_from([(0, 0, 0), (1, 0, 0), (0.3, -0.7, 0.2), (0, 0, 0, 1, 0, 0)])),
                min_size=5, max_size=60))
@settings(max_examples=80, deadline=None)
def test_every_published_target_is_a_bounded_step_or_the_measured_pose(events):
    """Whatever the state stream does (drift, jumps, restarts, gaps) and whatever the
    input, each published target is within the per-tick bound of the previous published
    one, or (right after a re-seed) the measured pose; zero input never moves it."""
    from sctd.runtime.safety import StateWatch

    c = ctl(reseed_after=0.005, state_timeout=0.002)
    cfg = c.config
    last_state = None
    watch = StateWatch(cfg.state_jump, cfg.state_jump_rotation)
    T_meas, seq, t = T_START.copy(), 0, 0.0
    prev = None  # last published world target
    bound = 0.1 * cfg.period * (1 + 1e-9) + 1e-15  # pour's skill speed
    for kind, u in events:
        for _ in range(4):
            t += cfg.period
            if kind == "drift":
                T_meas = T_meas @ se3.transform_from_pose([0.0004, 0, 0, 0, 0, 0, 1])
            elif kind == "jump":
                T_meas = T_meas @ se3.transform_from_pose([0.2, 0, 0, 0, 0, 0, 1])
            elif kind == "restart":
                seq = 0
            if kind != "stale":
                seq += 1
                F = se3.flat_from_transform(T_meas)
                watch.observe(seq, F, t)
                last_state = Sample(seq, t, t, F=F, epoch=watch.epoch, since=watch.since)
            r = c.tick(t, t, inp(u, t, seq=int(t * 1e6)), last_state, obj(t))  # "stale": it ages
            if r.pose is None:
                continue
            T = r.T_world_target
            assert np.all(np.isfinite(T))
            if prev is not None and np.linalg.norm(T[:3, 3] - prev[:3, 3]) > bound:
                assert np.allclose(T, T_meas, atol=1e-12), "a jump that is not a re-seed"
            elif prev is not None and not any(u):
                assert np.allclose(T, prev, atol=1e-12) or np.allclose(T, T_meas, atol=1e-12)
            prev = T


def test_state_watch_flags_jumps_turns_and_restarts():
    from sctd.runtime.safety import StateWatch

    w = StateWatch(0.05, 0.3)
    F = se3.flat_from_transform
    T = T_START
    assert not w.observe(1, F(T), 0.0) and w.epoch == 0
    assert not w.observe(2, F(T @ se3.transform_from_pose([0.049, 0, 0, 0, 0, 0, 1])), 0.001)
    assert w.observe(3, F(T @ se3.transform_from_pose([0.2, 0, 0, 0, 0, 0, 1])), 0.002)
    assert w.epoch == 1 and w.since == 0.002
    turned = T @ se3.transform_from_pose([0.2, 0, 0, *se3.quaternion_from_rotvec([0, 0, 0.35])])
    assert w.observe(4, F(turned), 0.003) and w.epoch == 2
    assert w.observe(1, F(turned), 0.004) and w.epoch == 3  # seq backwards: a restart
    assert not w.observe(2, F(turned), 0.005) and w.since == 0.004


def test_the_engine_says_where_the_mode_button_leads_from_the_active_state():
    """``status.mode_button``: skills/teleop.yaml's button 0 leads from translate to
    rotate and back, as a press then does; a learned vector-field skill has no button
    transition, so the mode button leads nowhere in any of its states."""
    from sctd.skill import SkillEngine

    eng = SkillEngine(load_skill(ROOT / "skills" / "teleop.yaml"))
    assert eng.state == "translate" and eng.leads_to() == "rotate" and eng.leads_to(3) is None
    eng.update(se3.flat_from_transform(np.eye(4)), 1.0, pressed={0})
    assert eng.state == "rotate" and eng.leads_to() == "translate"
    vf = load_skill(ROOT / "skills" / "pour-vf.yaml")
    eng = SkillEngine(vf)
    for s in vf.states:
        eng.reset(0.0, s.name)
        assert eng.leads_to() is None, s.name


def test_buttons_switch_teleop_modes_and_enable_gates_the_command():
    """skills/teleop.yaml: button 0 toggles translate/rotate (rising edge, counted per
    message by the arbiter); enable (button 1) = 0 makes the command zero."""
    from sctd.skill import WORLD_OBJECT

    teleop = load_skill(ROOT / "skills" / "teleop.yaml")
    assert teleop.object == WORLD_OBJECT
    c = ctl(teleop)
    world = Sample(0, 0.0, 0.0, F=se3.flat_from_transform(np.eye(4)))
    T = T_START.copy()
    seq = 0

    def tick(t, u, buttons=(0, 1, 0)):
        nonlocal seq, T
        seq += 1
        world.received = world.stamp = t
        r = c.tick(t, t, inp(u, t, seq, buttons=buttons), state(T, t), world)
        T = r.T_world_target
        return r

    t = 0.0
    for _ in range(50):
        t += 0.001
        r = tick(t, [1, 0, 0])
    assert r.state == "translate" and T[0, 3] > T_START[0, 3] + 0.004
    p = T[:3, 3].copy()
    # press (two messages with the button down count once), then rotate about world z
    for b in [(1, 1, 0), (1, 1, 0), (0, 1, 0)]:
        t += 0.001
        r = tick(t, [0, 0, 0], b)
    assert r.state == "rotate" and c.counters.presses == 1
    R0 = T[:3, :3].copy()
    for _ in range(100):
        t += 0.001
        r = tick(t, [0, 0, 1])
    assert np.allclose(T[:3, 3], p, atol=1e-12)  # rotation about the hand's origin
    w = se3.rotvec_from_matrix(R0.T @ T[:3, :3])
    assert w[2] > 0.04 and abs(w[0]) < 1e-9 and abs(w[1]) < 1e-9
    # deadman released: no motion, counted
    held = T.copy()
    for _ in range(20):
        t += 0.001
        r = tick(t, [0, 0, 1], (0, 0, 0))
    assert np.array_equal(T, held) and c.counters.disabled_input > 0 and r.mode == "stopped"


def test_a_press_on_stale_input_does_nothing():
    c = ctl(load_skill(ROOT / "skills" / "teleop.yaml"))
    world = Sample(0, 0.0, 0.0, F=se3.flat_from_transform(np.eye(4)))
    c.tick(0.0, 0.0, None, state(T_START, 0.0), world)
    old = inp((0, 0, 0), 0.0, buttons=(1, 1, 0))
    r = c.tick(0.5, 0.5, old, state(T_START, 0.5), Sample(0, 0.5, 0.5, F=world.F))
    assert r.state == "translate" and c.counters.presses == 0


# --- stuck detection and escape (thesis Ch. 6.2) ------------------------------------------

def trap_skill():
    return skill_from_bundle(Bundle("trap.yaml", trap_skill_yaml(0.01), {}))


class Pad:
    """A controller driven by (u, buttons) steps through the input arbiter, 1 ms apart,
    with a robot that follows the target."""

    def __init__(self, c):
        self.c, self.t, self.seq = Fed(c), 0.0, 0

    def run(self, steps):
        c, out = self.c, []
        for u, buttons in steps:
            meas = c.T_world_target if c.T_world_target is not None else T_WORLD_MUG
            self.seq += 1
            s = inp(u, self.t, self.seq, buttons=buttons)
            out.append(c.tick(self.t, self.t, s, state(meas, self.t), obj(self.t)))
            self.t += 0.001
        return out


def test_held_input_in_a_trap_counts_stuck_once_and_escape_returns():
    """slide maps only x; its way on needs z. Pushing x in it for longer than stuck_after
    is one stuck episode (status names the state); the targets are the same as with the
    detector off; escape (button 2) returns to free."""
    on, off = Pad(Controller(trap_skill(), RuntimeConfig(stuck_after=0.2))), \
        Pad(Controller(trap_skill(), RuntimeConfig(stuck_after=0.0)))
    enable, escape = (0, 1, 0), (0, 1, 1)
    go = [([1, 0, 0], enable)] * 150  # +x crosses free -> slide at x > 0.01 (0.1 m/s)
    # y and z are not slide's axes: no push at all, never stuck
    other = [([0, 1, 0], enable)] * 10 + [([0, 0, 1], enable)] * 500
    push = [([-0.01, 0, 0], enable)] * 5 + [([0.5, 0, 0], enable)] * 300  # dead band, then x
    for p in (on, off):
        res = p.run(go + other)
        assert res[-1].state == "slide" and p.c.engine.previous == "free"
        assert p.c.counters.stuck == 0 and p.c.stuck(p.t) is None
        res = p.run(push)
        assert res[-1].state == "slide"
    c = on.c
    assert c.counters.stuck == 1 and off.c.counters.stuck == 0 and off.c.stuck(off.t) is None
    st = c.stuck(on.t)
    assert st["state"] == "slide" and st["since"] >= 0.2
    # detection only: the two controllers published the same targets
    assert np.array_equal(c.T_world_target, off.c.T_world_target)
    # released: the episode ends; escape returns to free and is counted
    res = on.run([([0, 0, 0], enable)] * 3 + [([0, 0, 0], escape)] * 2 + [([0, 0, 0], enable)])
    assert c.stuck(on.t) is None and res[-1].state == "free"
    assert c.counters.escapes == 1 and c.counters.presses == 1 and c.engine.previous is None
    # at the start of the path escape does nothing
    res = on.run([([0, 0, 0], escape), ([0, 0, 0], enable)])
    assert res[-1].state == "free" and c.counters.escapes == 1 and c.counters.presses == 2
    # the hand is still past free -> slide, which waits until it has been back once
    res = on.run([([-1, 0, 0], enable)] * 400)
    assert all(r.state == "free" for r in res) and c.T_world_target[0, 3] < T_WORLD_MUG[0, 3] + 0.01
    res = on.run([([1, 0, 0], enable)] * 400)
    assert res[-1].state == "slide" and c.engine.previous == "free"


def test_held_input_against_a_wall_counts_stuck_progress_clears_it():
    """pour's carry state: the arm is blocked (the measured pose stays); pushing towards
    the mug makes no progress towards carry -> approach. Once the arm moves towards the
    mug the episode ends."""
    c = ctl(stuck_after=0.3)
    blocked = T_START.copy()
    res = run(c, [[1, 0, 0]] * 400, T_meas=blocked)
    assert res[-1].state == "carry" and c.counters.stuck == 1
    assert c.stuck(0.399)["state"] == "carry"
    res = run(c, [[1, 0, 0]] * 50, t0=0.4)  # the arm follows the target again: progress
    assert c.stuck(0.45) is None and c.counters.stuck == 1


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.sampled_from([-1.0, -0.4, 0.0, 0.3, 1.0]), st.sampled_from([0.0, 1.0]),
                          st.sampled_from([(0, 1, 0), (0, 1, 1), (0, 0, 0)]), st.integers(1, 120)),
                min_size=1, max_size=12))
def test_the_stuck_detector_never_changes_a_target(events):
    """Detection only: with the detector on (a short stuck_after) and off, any inputs,
    escapes and deadman releases publish the same targets, states and modes."""
    on, off = Pad(Controller(trap_skill(), RuntimeConfig(stuck_after=0.05))), \
        Pad(Controller(trap_skill(), RuntimeConfig(stuck_after=0.0)))
    steps = [((x, 0.0, z), b) for x, z, b, n in events for _ in range(n)]
    for a, b in zip(on.run(steps), off.run(steps), strict=True):
        assert (a.mode, a.state, a.pose) == (b.mode, b.state, b.pose)
    assert off.c.counters.stuck == 0 and on.c.counters.escapes == off.c.counters.escapes


def test_constraint_activity_counts_the_commands_each_constraint_changed():
    """pour's carry state (tilt cone, then band 0.03-0.60 m above the mug): pushing up
    until the band's top holds the tip, the band acts on every command and the cone on
    none; pushing down it lets go; zero input computes no command; entering another
    state starts a new count."""
    c = ctl()
    eng = c.engine
    run(c, [[0, 0, 1]] * 6000)
    assert eng.state == "carry" and eng.commands > 5000
    tilt, band = eng.acted
    assert tilt == 0 and band > 500, eng.acted
    commands, acted = eng.commands, list(eng.acted)
    run(c, [[0, 0, 1]] * 200, t0=6.0)
    assert eng.commands - commands == 200 and eng.acted == [0, acted[1] + 200]
    commands, acted = eng.commands, list(eng.acted)
    run(c, [[0, 0, 0]] * 100, t0=6.2)  # at rest: no command
    assert eng.commands == commands
    run(c, [[0, 0, -1]] * 200, t0=6.3)  # away from the limit: free
    assert eng.commands - commands == 200 and eng.acted == acted
    entries = eng.entries
    eng.reset(6.5, "approach")
    assert eng.entries == entries + 1 and eng.commands == 0
    assert eng.acted == [0] * len(SKILL.states[SKILL.state_index("approach")].active_constraints)


def test_a_faulted_arm_holds_the_target_and_re_seeds_only_from_zero_input():
    """A state that carries the arm's ``fault`` publishes nothing (mode ``fault``) while
    the person pushes; once the arm reports no fault, a held push still moves nothing: the
    target re-seeds at the measured pose only with the input at zero."""
    c = ctl(reseed_after=0.0)
    run(c, [[0.5, 0, 0]] * 20)
    assert c.T_world_target is not None
    T = c.T_world_target.copy()
    faulted = Sample(seq=0, stamp=1.0, received=1.0, F=se3.flat_from_transform(T), fault="reflex: collision")
    r = c.tick(1.0, 1.0, inp([1, 0, 0], 1.0), faulted, obj(1.0))
    assert r.mode == "fault" and r.pose is None and c.counters.robot_fault_ticks == 1
    for k in range(1, 50):  # recovered, the push still held: nothing
        t = 1.0 + 0.001 * k
        r = c.tick(t, t, inp([1, 0, 0], t, seq=k + 1), state(T, t), obj(t))
        assert r.mode == "fault" and r.pose is None
    t += 0.001
    r = c.tick(t, t, inp([0, 0, 0], t, seq=99), state(T, t), obj(t))
    assert r.pose is not None and r.seed and np.allclose(r.T_world_target, T, atol=1e-15)



@given(poses(), poses(scale=0.01), rotvecs(max_angle=0.5), st.floats(1e-5, 0.02), st.floats(1e-4, 0.3))
@settings(max_examples=200, deadline=None)
def test_a_limited_step_is_within_both_bounds_on_the_geodesic_from_the_previous_pose(
        a, moved, w, max_t, max_r):
    """``limit_step`` against scipy's rotations: the step comes out within the translation
    and the rotation bound (to rounding), the same fraction of the way along both parts
    (the direction of motion kept), the rotation along the geodesic from the previous
    orientation; a step within both bounds is returned as it is."""
    from scipy.spatial.transform import Rotation

    dt = moved[:3]
    R_a = Rotation.from_quat(a[3:])
    R_b = R_a * Rotation.from_rotvec(w)
    F_a = se3.flat_from_pose(a)
    F_b = se3.flat_from_pose(np.concatenate([a[:3] + dt, R_b.as_quat()]))
    out = limit_step(F_a, F_b, max_t, max_r)
    d, angle = np.linalg.norm(dt), np.linalg.norm(w)
    if d <= max_t and angle <= max_r:
        assert out is F_b
        return
    s = min(1.0 if d <= max_t else max_t / d, 1.0 if angle <= max_r else max_r / angle)
    assert np.allclose(out[9:], a[:3] + s * dt, atol=1e-12)
    want = (R_a * Rotation.from_rotvec(s * w)).as_matrix()
    assert np.allclose(np.reshape(out[:9], (3, 3)), want, atol=1e-9)
    d_out, r_out = separation(F_a, out)
    assert d_out <= max_t * (1 + 1e-9) + 1e-15 and r_out <= max_r * (1 + 1e-6) + 1e-9
