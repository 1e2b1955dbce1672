import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from sctd import se3
from tests.strategies import poses, rotvecs, unit_quaternions


def same_rotation(q1, q2):
    return np.allclose(q1, q2, atol=1e-9) or np.allclose(q1, -q2, atol=1e-9)


@given(unit_quaternions())
def test_quaternion_matrix_round_trip(q):
    R = se3.matrix_from_quaternion(q)
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
    assert np.isclose(np.linalg.det(R), 1.0)
    assert same_rotation(se3.quaternion_from_matrix(R), q)


@given(poses(scale=5.0))
def test_pose_transform_round_trip(pose):
    T = se3.transform_from_pose(pose)
    back = se3.pose_from_transform(T)
    assert np.allclose(back[:3], pose[:3], atol=1e-9)
    assert same_rotation(back[3:], pose[3:])
    assert np.allclose(T @ se3.invert_transform(T), np.eye(4), atol=1e-12)


@given(rotvecs())
def test_exp_log_round_trip(w):
    R = se3.matrix_from_rotvec(w)
    assert np.allclose(se3.rotvec_from_matrix(R), w, atol=1e-7)
    assert np.isclose(se3.rotation_angle(R), np.linalg.norm(w), atol=1e-9)
    q = se3.quaternion_from_rotvec(w)
    assert np.allclose(se3.matrix_from_quaternion(q), R, atol=1e-12)
    assert np.allclose(se3.rotvec_from_quaternion(q), w, atol=1e-7)


@given(unit_quaternions(), unit_quaternions())
def test_quaternion_product_matches_matrix_product(q1, q2):
    R = se3.matrix_from_quaternion(se3.quaternion_multiply(q1, q2))
    assert np.allclose(R, se3.matrix_from_quaternion(q1) @ se3.matrix_from_quaternion(q2))


@given(poses(), st.lists(st.floats(-0.2, 0.2), min_size=6, max_size=6))
def test_displacement_round_trip(pose, d6):
    """apply_displacement and displacement_from_transforms are inverse (docs/skill-format.md)."""
    T = se3.transform_from_pose(pose)
    T2 = se3.apply_displacement(T, d6)
    assert np.allclose(se3.displacement_from_transforms(T, T2), d6, atol=1e-9)


@given(poses(), poses())
def test_displacement_reaches_target(pa, pb):
    Ta, Tb = se3.transform_from_pose(pa), se3.transform_from_pose(pb)
    d = se3.displacement_from_transforms(Ta, Tb)
    assert np.allclose(se3.apply_displacement(Ta, d), Tb, atol=1e-9)


def test_displacement_convention_known_answer():
    """Translation is in the parent's axes, rotation about the frame's own axes."""
    T = se3.transform_from_rt(se3.matrix_from_rotvec([0, 0, np.pi / 2]), [1.0, 0.0, 0.0])
    T2 = se3.apply_displacement(T, [0.1, 0, 0, 0.3, 0, 0])
    assert np.allclose(T2[:3, 3], [1.1, 0.0, 0.0])  # parent x, not the frame's x (= parent y)
    # Rotation about the frame's own x axis (= parent y): frame z tilts towards -parent x.
    expected = T[:3, :3] @ se3.matrix_from_rotvec([0.3, 0, 0])
    assert np.allclose(T2[:3, :3], expected)


@given(poses(), st.floats(0.1, 1.0))
def test_tf_norm_of_displacement_matches_transform(pose, alpha):
    d6 = se3.displacement_from_transforms(np.eye(4), se3.transform_from_pose(pose))
    T = se3.transform_from_displacement(d6)
    assert np.isclose(se3.tf_norm_of_displacement(d6, alpha), se3.tf_norm(T, alpha), atol=1e-9)


def test_tf_norm_known_answer():
    """Eq. 4.9: 3-4-5 translation plus alpha times a quarter turn."""
    T = se3.transform_from_rt(se3.matrix_from_rotvec([0, np.pi / 2, 0]), [0.3, 0.4, 0.0])
    assert np.isclose(se3.tf_norm(T, alpha=0.5), 0.5 + 0.5 * np.pi / 2)


@given(st.lists(st.floats(-1.5, 1.5), min_size=3, max_size=3))
def test_euler_round_trip(e):
    R = se3.matrix_from_euler_xyz(e)
    assert np.allclose(se3.matrix_from_euler_xyz(se3.euler_xyz_from_matrix(R)), R, atol=1e-9)


def test_small_euler_agrees_with_rotvec():
    w = np.array([1e-3, -2e-3, 1.5e-3])
    e = se3.euler_xyz_from_matrix(se3.matrix_from_rotvec(w))
    assert np.allclose(e, w, atol=1e-5)


@given(st.lists(st.floats(-1, 1), min_size=6, max_size=6))
@settings(max_examples=50)
def test_exp_log_se3_round_trip(xi):
    xi = np.asarray(xi)
    assert np.allclose(se3.log_se3(se3.exp_se3(xi)), xi, atol=1e-7)


@given(unit_quaternions(), unit_quaternions())
def test_rotation_between(qa, qb):
    a = se3.matrix_from_quaternion(qa)[:, 2]
    b = se3.matrix_from_quaternion(qb)[:, 2]
    assert np.allclose(se3.rotation_between(a, b) @ a, b, atol=1e-9)


def test_average_quaternion_sign_invariant():
    q = se3.quaternion_from_rotvec([0.0, 0.0, 0.2])
    qs = np.stack([q, -q, se3.quaternion_from_rotvec([0, 0, 0.4])])
    mean = se3.average_quaternion(qs, [1.0, 1.0, 0.0])
    assert se3.quaternion_angle(mean, q) < 1e-9


@given(st.lists(poses(scale=5.0), min_size=1, max_size=4), st.floats(0.5, 2.0))
def test_one_pose_gives_the_floats_of_the_batch_path(batch, scale):
    """A single pose takes a fast path on floats: bit for bit the batch path's matrices,
    for lists, tuples and arrays, with quaternions of any norm."""
    P = np.array(batch)
    P[:, 3:] *= scale
    T = se3.transform_from_pose(P)
    for i, pose in enumerate(P):
        for one in (pose, pose.tolist(), tuple(pose.tolist())):
            assert se3.transform_from_pose(one).tobytes() == T[i].tobytes()


def test_zero_quaternion_rejected():
    with pytest.raises(ValueError):
        se3.transform_from_pose([0, 0, 0, 0, 0, 0, 0])


# --- the tick's Flat transforms, against numpy written out -----------------------------


@given(poses(scale=2.0), poses(scale=2.0))
def test_flat_pose_conversions(pa, pb):
    Ta = se3.transform_from_pose(pa)
    Fa = se3.flat_from_pose(pa.tolist())
    assert type(Fa) is tuple and len(Fa) == 12 and all(type(x) is float for x in Fa)
    assert np.array_equal(se3.transform_from_flat(Fa), Ta)  # the same floats as the batch path
    back = se3.pose_from_flat(Fa)
    assert np.allclose(back[:3], pa[:3], atol=1e-12) and same_rotation(np.array(back[3:]), pa[3:])
    assert same_rotation(np.array(se3.quaternion_from_flat(Fa)), pa[3:])
    q = se3.compose_quaternions(tuple(pa[3:]), tuple(pb[3:]))
    assert same_rotation(np.array(q), se3.quaternion_multiply(pa[3:], pb[3:]))
    Tb = se3.transform_from_pose(pb)
    R_ab = Ta[:3, :3].T @ Tb[:3, :3]
    angle = np.arccos(np.clip((np.trace(R_ab) - 1.0) / 2.0, -1.0, 1.0))
    assert np.isclose(se3.angle_between3(Ta[:3, :3], Tb[:3, :3]), angle, atol=1e-6)


@given(rotvecs())
def test_flat_rotvec_is_rodrigues(w):
    theta = float(np.linalg.norm(w))
    K = np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])
    R = np.eye(3) if theta < 1e-12 else (
        np.eye(3) + np.sin(theta) / theta * K + (1.0 - np.cos(theta)) / theta**2 * (K @ K))
    F = se3.flat_from_rotvec(*w)
    assert type(F) is tuple and len(F) == 12 and F[9:] == (0.0, 0.0, 0.0)
    assert np.allclose(np.reshape(F[:9], (3, 3)), R, atol=1e-12)
    assert np.allclose(se3.matrix3_from_rotvec(*w), R, atol=1e-12)
    assert np.allclose(se3.rotvec_from_matrix3(R), w, atol=1e-7)


@given(poses(scale=2.0), poses(scale=2.0), st.lists(st.floats(-1, 1), min_size=3, max_size=3))
def test_flat_transforms_are_matrix_products(pa, pb, p):
    Ta, Tb = se3.transform_from_pose(pa), se3.transform_from_pose(pb)
    Fa, Fb = se3.flat_from_transform(Ta), se3.flat_from_transform(Tb)
    assert type(Fa) is tuple and len(Fa) == 12 and all(type(x) is float for x in Fa)
    assert np.array_equal(se3.transform_from_flat(Fa), Ta)
    assert np.allclose(se3.transform_from_flat(se3.compose_flat(Fa, Fb)), Ta @ Tb, atol=1e-12)
    inv = np.eye(4)
    inv[:3, :3] = Ta[:3, :3].T
    inv[:3, 3] = -Ta[:3, :3].T @ Ta[:3, 3]
    assert np.allclose(se3.transform_from_flat(se3.invert_flat(Fa)), inv, atol=1e-12)
    moved = se3.transform_from_flat(se3.translate_flat(Fa, *p))
    assert np.array_equal(moved[:3, :3], Ta[:3, :3]) and np.allclose(moved[:3, 3], Ta[:3, 3] + p)
    # a rotation about p keeps p where it is, and turns like R
    M = se3.transform_from_flat(se3.flat_rotation_about(Fa, *p))
    assert np.allclose(M[:3, :3], Ta[:3, :3]) and np.allclose(M[:3, :3] @ p + M[:3, 3], p, atol=1e-12)


def test_flat_known_answer():
    """A quarter turn about z at (1, 0, 0), applied to the point (0, 1, 0)."""
    F = se3.flat_from_pose([1.0, 0.0, 0.0, 0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)])
    G = se3.compose_flat(F, se3.flat_from_pose([0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0]))
    assert np.allclose(G[9:], [0.0, 0.0, 0.0], atol=1e-15)
    assert np.allclose(se3.quaternion_from_flat(G), [0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)])
    assert se3.FLAT_IDENTITY == se3.flat_from_pose([0, 0, 0, 0, 0, 0, 1])


@pytest.mark.parametrize("k", range(9))
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
def test_quaternion_from_flat_propagates_non_finite(k, bad):
    """Every Shepperd branch reads all nine entries: one bad entry spoils the result."""
    for w in ([0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 3.0]):
        rows = list(se3.flat_from_rotvec(*w))
        rows[k] = bad
        assert not all(np.isfinite(se3.quaternion_from_flat(tuple(rows))))


def test_unchecked_pose_gives_nan_instead_of_raising():
    with np.errstate(invalid="ignore"):
        T = se3.transform_from_pose([0, 0, 0, 0, 0, 0, 0], check=False)
    assert np.isnan(T[:3, :3]).all()


@given(poses(), poses(), st.floats(0.0, 1.0))
@settings(max_examples=200, deadline=None)
def test_the_flat_relative_rotation_and_the_geodesic_agree_with_scipys(a, b, s):
    """``relative_quaternion_flat`` is scipy's ``R_a^-1 R_b`` (w >= 0), at any angle;
    ``interpolate_flat`` goes the fraction ``s`` of that rotation from R_a and of the
    straight line between the origins, and reaches F_b at s = 1."""
    from scipy.spatial.transform import Rotation

    F_a, F_b = se3.flat_from_pose(a), se3.flat_from_pose(b)
    R_a, R_b = Rotation.from_quat(a[3:]), Rotation.from_quat(b[3:])
    q = se3.relative_quaternion_flat(F_a, F_b)
    assert q[3] >= 0.0 and (Rotation.from_quat(q).inv() * R_a.inv() * R_b).magnitude() < 1e-8
    F = se3.interpolate_flat(F_a, F_b, s, q)
    assert np.allclose(F[9:], a[:3] + s * (b[:3] - a[:3]), atol=1e-12)
    step = Rotation.from_quat(q).as_rotvec()
    assume(np.linalg.norm(step) < np.pi - 1e-6)  # a half turn has two geodesics, both right
    want = (R_a * Rotation.from_rotvec(s * step)).as_matrix()
    assert np.allclose(np.reshape(F[:9], (3, 3)), want, atol=1e-8)
    end = se3.interpolate_flat(F_a, F_b, 1.0, q)
    assert np.allclose(end, F_b, atol=1e-8)
