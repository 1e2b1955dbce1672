"""The robot's own target guard (sctd_sim.guard): far, fast, out-of-order and
pre-start targets are refused; a stream of bounded steps is followed."""

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd import se3
from sctd.runtime.safety import separation
from sctd_sim.guard import TargetGuard, TargetLimits, distance_and_angle
from sctd_sim.kinematic import towards

ARM = [0.4, 0.1, 0.9, 0.0, 0.0, 0.0, 1.0]
F_ARM = se3.flat_from_pose(ARM)


def moved(pose, dx=0.0, rz=0.0):
    q = se3.quaternion_multiply(se3.quaternion_from_rotvec([0, 0, rz]), pose[3:])
    return [pose[0] + dx, pose[1], pose[2], *q.tolist()]


def guard(**kw):
    return TargetGuard(TargetLimits(**kw), period=0.001, started=100.0)


def test_far_target_is_refused_near_one_followed():
    g = guard()
    assert not g.admit(moved(ARM, dx=0.21), 101.0, F_ARM, following=False)
    assert not g.admit(moved(ARM, rz=0.6), 101.0, F_ARM, following=False)
    assert g.rejected == {"offset": 2}
    assert g.admit(moved(ARM, dx=0.05), 101.0, F_ARM, following=False)


def test_target_stamped_before_the_start_is_never_followed():
    g = guard()
    assert not g.admit(ARM, 99.9, F_ARM, following=False) and g.rejected["before_start"] == 1
    g = TargetGuard(TargetLimits(), 0.001, 100.0, stamp_check=False)
    assert g.admit(ARM, 99.9, F_ARM, following=False)


def test_implied_speed_is_bounded_and_out_of_order_refused():
    g = guard()
    assert g.admit(ARM, 101.0, F_ARM, following=False)
    # 2 mm in 1 ms = 2 m/s > 1.5 m/s
    assert not g.admit(moved(ARM, dx=0.002), 101.001, F_ARM, following=True)
    assert g.rejected["speed"] == 1
    # after a refusal the arm holds: the next target is judged by its offset alone
    assert g.admit(moved(ARM, dx=0.002), 101.002, F_ARM, following=False)
    assert g.admit(moved(ARM, dx=0.003), 101.003, F_ARM, following=True)  # 1 m/s
    assert not g.admit(moved(ARM, dx=0.003), 101.003, F_ARM, following=True)
    assert g.rejected["out_of_order"] == 1
    # rotation: 0.01 rad in 1 ms = 10 rad/s > 4
    g = guard()
    assert g.admit(ARM, 101.0, F_ARM, following=False)
    assert not g.admit(moved(ARM, rz=0.01), 101.001, F_ARM, following=True)


def test_a_late_sender_catching_up_is_judged_over_one_period_at_least():
    g = guard()
    assert g.admit(ARM, 101.0, F_ARM, following=False)
    # 0.25 mm steps 50 us apart (a runtime catching up late ticks): 0.25 m/s over a period
    pose = ARM
    for k in range(1, 6):
        pose = moved(pose, dx=0.00025)
        assert g.admit(pose, 101.0 + 5e-5 * k, F_ARM, following=True)


@given(st.lists(st.floats(-1.0, 1.0), min_size=1, max_size=50), st.floats(0.01, 1.4))
@settings(max_examples=50, deadline=None)
def test_steps_within_the_limits_are_always_followed(directions, speed):
    g = guard()
    pose, t = ARM, 101.0
    assert g.admit(pose, t, F_ARM, following=False)
    for d in directions:
        t += 0.001
        pose = moved(pose, dx=d * speed * 0.001)
        F_meas = se3.flat_from_pose(pose)  # the arm follows
        assert g.admit(pose, t, F_meas, following=True)
    assert g.total_rejected == 0 and math.isfinite(t) and np.isfinite(pose).all()


# The guard's own distance and angle: known answers, and agreement with the runtime's
# (written apart: two implementations that agree on random poses pin each other).

def test_distance_and_angle_known_answers():
    F = se3.flat_from_pose([1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0])
    G = se3.flat_from_pose([4.0, 6.0, 3.0, *se3.quaternion_from_rotvec([0.0, 0.0, 0.3]).tolist()])
    d, angle = distance_and_angle(F, G)
    assert d == 5.0 and math.isclose(angle, 0.3, rel_tol=1e-12)
    assert distance_and_angle(F, F) == (0.0, 0.0)
    # a half turn, where a cosine alone loses its accuracy
    H = se3.flat_from_pose([1.0, 2.0, 3.0, *se3.quaternion_from_rotvec([0.0, math.pi - 1e-7, 0.0]).tolist()])
    assert math.isclose(distance_and_angle(F, H)[1], math.pi - 1e-7, abs_tol=1e-9)


@given(st.lists(st.floats(-1.0, 1.0), min_size=12, max_size=12), st.floats(0.0, math.pi))
def test_distance_and_angle_agree_with_the_runtime_and_are_symmetric(xs, angle):
    axis = np.array(xs[3:6]) + np.array([0.0, 0.0, 1e-3])
    w = angle * axis / np.linalg.norm(axis)
    F = se3.flat_from_pose([*xs[:3], *se3.quaternion_from_rotvec(xs[6:9]).tolist()])
    R = se3.matrix_from_rotvec(xs[6:9]) @ se3.matrix_from_rotvec(w)
    G = se3.flat_from_pose([*xs[9:12], *se3.quaternion_from_matrix(R).tolist()])
    d, a = distance_and_angle(F, G)
    assert math.isclose(a, angle, abs_tol=1e-6)
    assert np.allclose((d, a), distance_and_angle(G, F), rtol=0.0, atol=1e-12)
    d_rt, a_rt = separation(F, G)
    assert math.isclose(d, d_rt, abs_tol=1e-12) and math.isclose(a, a_rt, abs_tol=2e-6)


@given(st.lists(st.floats(-1.0, 1.0), min_size=12, max_size=12), st.floats(0.0, 1.0))
def test_the_stand_in_robot_moves_along_the_way_it_should(xs, s):
    T_a = se3.transform_from_pose([*xs[:3], *se3.quaternion_from_rotvec(xs[3:6]).tolist()])
    T_b = se3.transform_from_pose([*xs[6:9], *se3.quaternion_from_rotvec(xs[9:12]).tolist()])
    T = towards(T_a, T_b, s)
    d_ab, a_ab = distance_and_angle(se3.flat_from_transform(T_a), se3.flat_from_transform(T_b))
    d_a, a_a = distance_and_angle(se3.flat_from_transform(T_a), se3.flat_from_transform(T))
    d_b, a_b = distance_and_angle(se3.flat_from_transform(T), se3.flat_from_transform(T_b))
    assert math.isclose(d_a, s * d_ab, abs_tol=1e-9) and math.isclose(d_b, (1 - s) * d_ab, abs_tol=1e-9)
    assert math.isclose(a_a, s * a_ab, abs_tol=1e-6) and math.isclose(a_b, (1 - s) * a_ab, abs_tol=1e-6)
    assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-12) and np.all(T[3] == [0, 0, 0, 1])
