"""Physics: gravity compensation, passivity, limits, brakes, external wrench."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from sctd_sim.arm import SimArm
from sctd_sim.dynamics import ArmDynamics
from sctd_sim.robot import load_arm_model

DT = 1e-3


@pytest.fixture(scope="module")
def arm():
    return load_arm_model()


def gravity(arm, q):
    return pin.computeGeneralizedGravity(arm.model, arm.model.createData(), q).copy()


def test_gravity_compensated_arm_holds_still(arm):
    dyn = ArmDynamics(arm)
    q0 = dyn.q.copy()
    for _ in range(1000):
        dyn.step(gravity(arm, dyn.q), DT)
    assert np.abs(dyn.dq).max() < 1e-9
    assert np.abs(dyn.q - q0).max() < 1e-9


def test_gravity_compensated_arm_holds_still_through_the_bus():
    with SimArm() as sim:
        p0 = sim.T_world_ee[:3, 3]
        sim.run(1.0)
        assert np.linalg.norm(sim.T_world_ee[:3, 3] - p0) < 5e-5
        assert np.abs(sim.dq).max() < 1e-3


def test_energy_does_not_grow_without_input(arm):
    # no torque, no friction: semi-implicit Euler keeps energy bounded (no drift up);
    # the hard stops can only remove energy.
    dyn = ArmDynamics(arm, q0=arm.rest + np.array([0.3, -0.2, 0.4, 0.3, -0.5, 0.2, 0.1]),
                      friction=False)
    e0 = dyn.energy()
    energies = []
    for _ in range(2000):
        dyn.step(np.zeros(7), DT)
        energies.append(dyn.energy())
    # bounded oscillation of the integrator, relative to the energy swing of the motion
    swing = max(energies) - min(energies)
    assert max(energies) <= e0 + 0.02 * max(swing, 1.0)


def test_friction_dissipates(arm):
    dyn = ArmDynamics(arm, friction=True)
    dyn.dq[:] = 0.5
    k0 = dyn.kinetic_energy()
    kinetic = []
    for _ in range(500):
        dyn.step(gravity(arm, dyn.q), DT)
        kinetic.append(dyn.kinetic_energy())
    # gravity compensated: M ddq + C dq = -b dq, so dT/dt = -dq^T b dq <= 0
    assert max(kinetic) <= k0 * (1 + 1e-3)
    assert kinetic[-1] < 0.9 * k0


def test_position_limits_are_hard_stops(arm):
    dyn = ArmDynamics(arm)
    push = np.zeros(7)
    push[3] = 30.0  # push joint 4 into its upper stop
    for _ in range(2000):
        dyn.step(push + gravity(arm, dyn.q), DT)
    assert np.all(dyn.q <= arm.q_upper + 1e-12) and np.all(dyn.q >= arm.q_lower - 1e-12)
    assert dyn.q[3] == pytest.approx(arm.q_upper[3])
    assert dyn.at_limit[3]


def test_velocity_and_torque_limits(arm):
    dyn = ArmDynamics(arm, friction=False)
    tau = np.zeros(7)
    tau[6] = 1e4  # far beyond the 40 N m limit of joint 7
    for _ in range(300):
        dyn.step(tau + gravity(arm, dyn.q), DT)
    assert dyn.tau_motor[6] <= arm.tau_max[6]
    assert np.all(np.abs(dyn.dq) <= arm.dq_max + 1e-12)
    assert abs(dyn.dq[6]) == pytest.approx(arm.dq_max[6]) or dyn.at_limit[6]


def test_braked_joints_hold_their_position(arm):
    dyn = ArmDynamics(arm, q0=arm.rest + np.array([0.0, 0.0, 0.3, 0.0, 0.3, -0.6, 0.0]))
    braked = np.array([True, True, False, True, False, False, False])
    q0 = dyn.q.copy()
    for _ in range(500):
        dyn.step(np.zeros(7), DT, braked)  # no gravity compensation at all
    np.testing.assert_array_equal(dyn.q[braked], q0[braked])
    assert np.all(dyn.dq[braked] == 0.0)
    assert np.abs(dyn.q[~braked] - q0[~braked]).max() > 1e-3  # the free joints fall


def test_external_wrench_maps_through_the_jacobian(arm):
    dyn = ArmDynamics(arm)
    w = np.array([5.0, -3.0, 2.0, 0.1, 0.2, -0.3])
    dyn.set_external_wrench(w)
    J = pin.computeFrameJacobian(arm.model, arm.model.createData(), dyn.q, arm.ee_frame_id,
                                 pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    np.testing.assert_allclose(dyn.external_torque(), J.T @ w, atol=1e-12)


def test_impedance_deflects_under_a_force_by_force_over_stiffness():
    with SimArm() as sim:
        p0 = sim.T_world_ee[:3, 3]
        sim.run(0.05)
        sim.set_external_wrench(np.array([10.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
        sim.run(1.5)
        k = sim.controller.gains.k_trans
        deflection = sim.T_world_ee[:3, 3] - p0
        assert deflection[0] == pytest.approx(10.0 / k, rel=0.1)
        assert abs(deflection[1]) < 2e-4 and abs(deflection[2]) < 5e-4


def test_step_updates_the_state_in_place(arm):
    dyn = ArmDynamics(arm)
    q, dq = dyn.q, dyn.dq
    dyn.step(np.zeros(7), DT)  # unsupported: the arm starts to fall
    assert dyn.q is q and dyn.dq is dq
    assert np.abs(dq).max() > 0


def test_kinematics_follow_the_posture_and_are_shared_read_only(arm):
    """The ee pose, twist and external torque come from one Jacobian per posture: the
    same numbers as Pinocchio's own calls, again after q changes, and not writable."""
    dyn = ArmDynamics(arm)
    data = arm.model.createData()
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    rng = np.random.default_rng(0)
    w = np.array([5.0, -3.0, 2.0, 0.1, 0.2, -0.3])
    dyn.set_external_wrench(w)
    for _ in range(3):
        dyn.q[:] = rng.uniform(arm.q_lower, arm.q_upper)  # in place, as the integrator does
        dyn.dq[:] = rng.normal(size=7)
        pin.framesForwardKinematics(arm.model, data, dyn.q)
        J = pin.computeFrameJacobian(arm.model, data, dyn.q, arm.ee_frame_id, lwa)
        T = dyn.ee_transform()
        assert T.tobytes() == data.oMf[arm.ee_frame_id].homogeneous.tobytes()
        assert dyn.ee_velocity().tobytes() == (J @ dyn.dq).tobytes()
        assert dyn.external_torque().tobytes() == J.T.dot(w).tobytes()
        with pytest.raises(ValueError):
            T[0, 3] = 1.0
