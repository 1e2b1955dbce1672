"""Where a joint has moved its handle (sctd.task.kinematics): the one answer the scene,
the simulated user and the demonstrator share."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

from sctd import se3
from sctd.task import find_task, handle_jacobian, handle_pose
from sctd.task.kinds.joint import Grasp, Hinge, Joint
from tests.strategies import poses

GRASP = Grasp(0.02, 0.06, 2000.0, 60.0)


def revolute(point, axis, travel=2.0) -> Joint:
    axis = np.asarray(axis, dtype=float)
    return Joint("door", "revolute", "door_handle", travel, 1.5, 0.0, 0.0, 0.0, 0.01, GRASP,
                 Hinge(np.asarray(point, dtype=float), axis / np.linalg.norm(axis)))


def prismatic() -> Joint:
    return Joint("drawer", "prismatic", "drawer_handle", 0.3, 2.0, 0.0, 0.0, 0.0, 0.01, GRASP)


vectors = st.lists(st.floats(-0.5, 0.5), min_size=3, max_size=3).map(np.array)
directions = vectors.filter(lambda v: np.linalg.norm(v) > 0.1)


@given(poses(), vectors, directions, st.floats(-3.0, 3.0))
def test_a_turned_handle_keeps_its_distance_from_the_fixed_hinge_line(pose, point, axis, q):
    joint = revolute(point, axis)
    hinge = joint.hinge
    assume(hinge.lever >= 0.01)  # (the reader refuses a handle on its hinge line)
    T0 = se3.transform_from_pose(pose)
    T = handle_pose(joint, T0, q)
    np.testing.assert_allclose(handle_pose(joint, T0, 0.0), T0, atol=1e-12)
    np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-12)
    # the hinge line is where it was (in the world and in the turned handle's frame)
    a_world, p_world = T0[:3, :3] @ hinge.axis, T0 @ [*hinge.point, 1.0]
    np.testing.assert_allclose(T[:3, :3] @ hinge.axis, a_world, atol=1e-12)
    np.testing.assert_allclose(T @ [*hinge.point, 1.0], p_world, atol=1e-12)
    d = T[:3, 3] - p_world[:3]
    assert np.linalg.norm(d - (d @ a_world) * a_world) == pytest.approx(hinge.lever, abs=1e-12)
    # turned by q about the axis: the handle's frame rotated by q relative to its start
    R = T0[:3, :3].T @ T[:3, :3]
    assert se3.rotvec_from_matrix(R) @ hinge.axis == pytest.approx(math.remainder(q, 2 * math.pi), abs=1e-9)


@given(poses(), vectors, directions, st.floats(-3.0, 3.0))
def test_the_jacobian_is_how_the_handle_moves(pose, point, axis, q):
    joint = revolute(point, axis)
    T0 = se3.transform_from_pose(pose)
    h = 1e-6
    numeric = (handle_pose(joint, T0, q + h)[:3, 3] - handle_pose(joint, T0, q - h)[:3, 3]) / (2 * h)
    J = handle_jacobian(joint, T0, q)
    np.testing.assert_allclose(J, numeric, atol=1e-8)
    assert np.linalg.norm(J) == pytest.approx(joint.hinge.lever, abs=1e-12)


@given(poses(), st.floats(-1.0, 1.0))
def test_a_prismatic_handle_slides_along_its_own_x(pose, q):
    T0 = se3.transform_from_pose(pose)
    T = handle_pose(prismatic(), T0, q)
    np.testing.assert_array_equal(T[:3, :3], T0[:3, :3])
    np.testing.assert_array_equal(T[:3, 3], T0[:3, 3] + q * T0[:3, 0])  # to the bit, as before
    np.testing.assert_array_equal(handle_jacobian(prismatic(), T0, q), T0[:3, 0])


def test_the_cabinet_door_swings_out_towards_the_arm():
    """The shipped door: its handle, 0.321 m from the vertical hinge line, comes towards
    the arm (world -x) and to its right as the door opens, at its height."""
    task = find_task("cabinet")
    joint = task.scene.joints["door"]
    T0 = task.scene.bodies["door_handle"].T_world
    assert joint.hinge.lever == pytest.approx(math.hypot(0.03, 0.32))
    p0 = T0[:3, 3]
    p90 = handle_pose(joint, T0, math.pi / 2)[:3, 3]
    hinge = (T0 @ [*joint.hinge.point, 1.0])[:3]
    np.testing.assert_allclose(hinge, [0.72, -0.50, 0.62], atol=1e-12)
    np.testing.assert_allclose(p90, hinge + np.array([-0.32, -0.03, 0.0]), atol=1e-12)
    assert p90[0] < p0[0] and p90[1] < p0[1] and p90[2] == pytest.approx(p0[2])
    J = handle_jacobian(joint, T0, 0.0)
    assert J @ T0[:3, 0] > 0.99 * joint.hinge.lever  # at first straight out of the closed door
