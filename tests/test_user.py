"""The simulated user's parts: the device model it learns, the task intents, and the
whole user driving a toy device whose mapping it does not know."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd import se3
from sctd_services.user import DeviceModel, Observation, SimulatedUser, make_intent
from sctd_services.user.human import PROFILES


@given(st.integers(0, 10_000))
@settings(max_examples=25, deadline=None)
def test_device_model_recovers_a_linear_device(seed):
    rng = np.random.default_rng(seed)
    B = rng.normal(0, 0.1, (6, 3))
    m = DeviceModel(3, forgetting=0.98)
    for _ in range(60):
        u = rng.uniform(-1, 1, 3)
        m.update(u, B @ u + rng.normal(0, 1e-4, 6))
    assert m.known and all(np.allclose(m.predict(v), B @ v, atol=5e-3)
                           for v in rng.uniform(-1, 1, (10, 3)))
    # and it commands what it predicts: a twist the device can make, reached
    want = B @ np.array([0.3, -0.5, 0.2])
    u, residual = m.command(want, np.eye(6) / 0.1)  # weights as the intents give them
    assert residual < 0.05 and np.allclose(B @ u, want, atol=5e-3)


def test_device_model_ignores_rest_and_command_stays_in_bounds():
    m = DeviceModel(3)
    m.update(np.zeros(3), np.ones(6))  # no input: nothing to learn
    assert m.updates == 0 and not m.known
    B = np.zeros((6, 3))
    B[0, 0] = 0.1
    for k in range(20):
        u = np.eye(3)[k % 3] * (1 if k % 2 else -1)
        m.update(u, B @ u)
    u, residual = m.command(np.array([1.0, 0, 0, 0, 0, 0]), np.eye(6))  # ten times too fast
    assert np.all(np.abs(u) <= 1.0 + 1e-12) and u[0] > 0.99 and residual > 0.5


def _drawer_obs(t, p, opening, attached, mode="m"):
    T = np.eye(4)
    T[:3, 3] = p
    H = se3.transform_from_pose([0.5, 0.0, 0.6, 0, 0, 1, 0])  # x of the handle = world -x
    return Observation(t, T, {"drawer_handle": H}, {"opening": opening, "attached": attached,
                                                    "target_opening": 0.2}, mode)


def test_drawer_intent_reaches_then_pulls_along_the_handle_axis():
    it = make_intent("drawer")
    d = it.desire(_drawer_obs(0.0, [0.3, 0.1, 0.7], 0.0, False))
    assert d.phase == "reach" and d.twist[0] > 0 and d.twist[1] < 0 and d.twist[2] < 0
    d = it.desire(_drawer_obs(1.0, [0.5, 0.0, 0.6], 0.05, True))
    assert d.phase == "pull" and d.twist[0] < -0.05  # out of the drawer: world -x
    d = it.desire(_drawer_obs(2.0, [0.3, 0.0, 0.6], 0.21, True))
    assert d.phase == "done" and d.done and not np.any(d.twist)


class ToyDrawer:
    """A hand that moves as ``B`` maps the stick (translation only), and a drawer that
    opens as the hand pulls the grasped handle: a device the user has never seen."""

    def __init__(self, B):
        self.B = B
        self.p = np.array([0.3, 0.1, 0.7])
        self.opening, self.attached = 0.0, False

    def step(self, u, dt):
        self.p = self.p + (self.B @ np.asarray(u))[:3] * dt
        handle = np.array([0.5 - self.opening, 0.0, 0.6])
        if np.linalg.norm(self.p - handle) < 0.02:
            self.attached = True
        if self.attached:
            self.opening = float(np.clip(0.5 - self.p[0], 0.0, 0.3))


@pytest.mark.parametrize("perm, signs", [((0, 1, 2), (1, 1, 1)), ((2, 0, 1), (-1, 1, -1)),
                                         ((1, 2, 0), (1, -1, 1))])
def test_user_learns_an_unknown_device_and_opens_the_toy_drawer(perm, signs):
    """Whatever the stick's axes are wired to (permuted, inverted), the user finds out by
    trying them, then opens the drawer."""
    B = np.zeros((6, 3))
    for axis, (j, s) in enumerate(zip(perm, signs, strict=True)):
        B[axis, j] = 0.1 * s
    toy = ToyDrawer(B)
    user = SimulatedUser("drawer", 3, PROFILES["steady"], seed=1)
    t, dt = 0.0, 0.01
    while t < 30.0 and not user.done:
        u, buttons = user.step(t, _drawer_obs(t, toy.p, toy.opening, toy.attached))
        assert buttons[1] == 1 and all(abs(x) <= 1.0 for x in u)
        toy.step(u, dt)
        t += dt
    assert user.done and toy.opening >= 0.2, (t, toy.p, toy.opening)


def test_user_at_rest_sends_exactly_zero():
    """A user with nothing to do makes no deflection at all (no noise on a released
    stick): zero input never moves the robot, and the simulated user respects that."""
    user = SimulatedUser("drawer", 3, PROFILES["noisy"], seed=3)
    for k in range(200):
        u, _ = user.step(0.01 * k, _drawer_obs(0.01 * k, [0.2, 0.0, 0.6], 0.25, True))
        if k > 60:
            assert u == (0.0, 0.0, 0.0)
