"""The pure runtime tick: watchdog, hold, speed bounds, offset bound, finite output."""

from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd import se3
from sctd.runtime.controller import Controller, RuntimeConfig, Sample
from sctd.runtime.safety import rotation_angle_between
from sctd.skill import load_skill

ROOT = Path(__file__).resolve().parents[1]
SKILL = load_skill(ROOT / "skills" / "pour.yaml")
T_WORLD_MUG = se3.transform_from_pose([0.6, 0.1, 0.75, 0, 0, 0, 1])
T_START = se3.transform_from_pose([0.3, 0.3, 1.0, 0, 0, 0, 1])


def ctl(**cfg):
    return Controller(SKILL, RuntimeConfig(**cfg))


def inp(u, t, seq=1, wall=None):
    return Sample(seq=seq, stamp=t if wall is None else wall, received=t, u=tuple(u))


def state(T, t):
    return Sample(seq=0, stamp=t, received=t, T=T)


def obj(t, T=T_WORLD_MUG):
    return Sample(seq=0, stamp=t, received=t, T=T)


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
    assert np.array_equal(r.T_world_target, T_START)


def test_input_moves_target_and_zero_input_never_does():
    c = ctl()
    res = run(c, [[1, 0, 0]] * 100)
    moved = res[-1].T_world_target[:3, 3] - T_START[:3, 3]
    assert np.isclose(moved[0], 0.1 * 0.1, rtol=1e-6)  # skill max 0.1 m/s, 100 ticks of 1 ms
    held = res[-1].T_world_target.copy()
    res = run(c, [[0, 0, 0]] * 50 + [[0.01, -0.015, 0.0]] * 50, t0=1.0)  # inside the dead band
    assert all(np.array_equal(r.T_world_target, held) for r in res)


def test_watchdog_stale_input_stops_motion():
    c = ctl()
    run(c, [[1, 0, 0]] * 10)
    T = c.T_world_target.copy()
    t = 0.2  # last input arrived at 0.009: older than 0.1 s
    r = c.tick(t, t, inp([1, 0, 0], 0.009), state(T, t), obj(t))
    assert r.mode == "stopped" and np.array_equal(r.T_world_target, T)
    # A fresh arrival with an old sender stamp is stale too.
    r = c.tick(t, t, Sample(seq=99, stamp=t - 0.5, received=t, u=(1, 0, 0)), state(T, t), obj(t))
    assert np.array_equal(r.T_world_target, T) and c.counters.stale_input >= 1


def test_stale_state_or_object_holds():
    c = ctl()
    run(c, [[1, 0, 0]] * 5)
    T = c.T_world_target.copy()
    r = c.tick(1.0, 1.0, inp([1, 0, 0], 1.0), state(T, 0.5), obj(1.0))
    assert r.mode == "hold" and np.array_equal(r.T_world_target, T)
    r = c.tick(3.0, 3.0, inp([1, 0, 0], 3.0), state(T, 3.0), obj(1.0))
    assert r.mode == "hold" and np.array_equal(r.T_world_target, T)


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
        rot = rotation_angle_between(prev[:3, :3], T[:3, :3])
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


def test_target_offset_from_blocked_arm_is_bounded():
    c = ctl(max_offset=0.02)
    res = run(c, [[1, 0, 0]] * 600, T_meas=T_START)  # arm does not move
    d = np.linalg.norm(res[-1].T_world_target[:3, 3] - T_START[:3, 3])
    assert np.isclose(d, 0.02) and c.counters.offset_limited > 0


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
    c.engine.command_flat = lambda F, u, dt: (float("nan"),) * 12
    res = run(c, [[0.5, 0, 0]] * 3, t0=0.01)
    assert c.counters.nonfinite_output == 3
    assert all(np.array_equal(r.T_world_target, T) and r.pose == pose for r in res)


def pour_mix(n):
    """Inputs that translate, tilt and pour (the approach and pour states rotate)."""
    k = np.arange(n)
    return np.stack([0.8 * np.sin(k * 0.013), 0.8 * np.cos(k * 0.007), np.sin(k * 0.005)], 1).tolist()


@given(st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3), st.floats(-np.pi, np.pi))
@settings(max_examples=25, deadline=None)
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
    from sctd.runtime.timing import Histogram
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


def test_decoder_thread_survives_a_failing_handler():
    """A handler that raises costs one message (counted), not the decoder thread."""
    from types import SimpleNamespace

    from sctd.runtime.daemon import _Decoder
    errors, seen = [], []

    def bad(sample, received):
        raise RuntimeError("bug")

    def good(sample, received):
        seen.append((sample.key_expr, received))

    d = _Decoder(0, errors.append)
    d.start()
    for k, handler in enumerate([good, bad, good, bad, good]):
        d.queue.put((handler, SimpleNamespace(key_expr=f"k/{k}"), float(k)))
    d.close()
    assert not d.is_alive()
    assert seen == [("k/0", 0.0), ("k/2", 2.0), ("k/4", 4.0)] and errors == ["decoder_error"] * 2
