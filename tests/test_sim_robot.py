"""The arm description: URDF, limits, kinematics, inverse kinematics."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sctd_sim.arm import ee_transform
from sctd_sim.robot import URDF_PATH, inverse_kinematics, load_arm_model


@pytest.fixture(scope="module")
def arm():
    return load_arm_model()


def test_urdf_is_seven_revolute_joints_with_published_limits(arm):
    assert URDF_PATH.is_file()
    assert arm.nq == 7
    assert arm.joint_names == [f"joint_{j}" for j in range(1, 8)]
    np.testing.assert_allclose(np.degrees(arm.q_upper), [170, 120, 170, 120, 170, 120, 175],
                               atol=1e-4)
    np.testing.assert_allclose(arm.q_lower, -arm.q_upper)
    np.testing.assert_allclose(np.degrees(arm.dq_max), [98, 98, 100, 130, 140, 180, 180],
                               atol=1e-4)
    np.testing.assert_allclose(arm.tau_max, [176, 176, 110, 110, 110, 40, 40])
    assert np.all(arm.damping > 0)
    assert np.all(np.asarray(arm.model.armature) > 0)


def test_link_offsets_match_the_lbr_kinematics(arm):
    # stretched upright: base 0.34 + 0.4 + 0.4 + 0.126 flange + 0.15 hand TCP
    T = ee_transform(arm, np.zeros(7))
    np.testing.assert_allclose(T[:3, 3], [0.0, 0.0, 0.34 + 0.4 + 0.4 + 0.126 + 0.15], atol=1e-9)
    data = arm.model.createData()
    pin.framesForwardKinematics(arm.model, data, np.zeros(7))
    z = [data.oMi[j].translation[2] for j in range(1, 8)]
    np.testing.assert_allclose(z, [0.15, 0.34, 0.55, 0.74, 0.95, 1.14, 1.221], atol=1e-9)


def test_mass_is_plausible_for_a_light_weight_arm(arm):
    mass = sum(inertia.mass for inertia in arm.model.inertias)
    assert 15.0 < mass < 30.0


def test_minverse_is_filled_symmetric(arm):
    # the controller relies on Pinocchio returning the whole symmetric inverse
    data = arm.model.createData()
    rng = np.random.default_rng(0)
    q = rng.uniform(arm.q_lower, arm.q_upper)
    Minv = pin.computeMinverse(arm.model, data, q).copy()
    M = pin.crba(arm.model, data, q)
    M = np.triu(M) + np.triu(M, 1).T
    np.testing.assert_allclose(Minv, Minv.T, atol=1e-12)
    np.testing.assert_allclose(Minv @ M, np.eye(7), atol=1e-9)


@pytest.mark.parametrize("seed", range(4))
def test_inverse_kinematics_reaches_poses_of_random_postures(arm, seed):
    rng = np.random.default_rng(seed)
    q_true = arm.rest + rng.uniform(-0.4, 0.4, 7)
    T = ee_transform(arm, q_true)
    q, ok = inverse_kinematics(arm, T)
    assert ok
    np.testing.assert_allclose(ee_transform(arm, q), T, atol=1e-5)
    assert np.all(q >= arm.q_lower) and np.all(q <= arm.q_upper)
