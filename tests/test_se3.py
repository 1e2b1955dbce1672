import numpy as np
import pytest
from hypothesis import given, settings
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
    """apply_displacement and displacement_from_transforms are inverse (DESIGN §4)."""
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


def test_zero_quaternion_rejected():
    with pytest.raises(ValueError):
        se3.transform_from_pose([0, 0, 0, 0, 0, 0, 0])


# --- the tick's fast paths agree with the vectorised functions -------------------------


@given(poses(scale=2.0), poses(scale=2.0))
def test_fast_paths_agree_with_vectorised(pa, pb):
    Ta, Tb = se3.transform_from_pose(pa), se3.transform_from_pose(pb)
    assert np.allclose(se3.matrix4_from_pose(pa.tolist()), Ta, atol=1e-12)
    back = se3.pose_from_matrix4(Ta)
    assert np.allclose(back[:3], pa[:3], atol=1e-12) and same_rotation(np.array(back[3:]), pa[3:])
    assert same_rotation(np.array(se3.quaternion_from_matrix3(Ta[:3, :3])), pa[3:])
    assert np.allclose(se3.rows_from_quaternion(*pa[3:]), Ta[:3, :3].ravel(), atol=1e-12)
    q = se3.compose_quaternions(tuple(pa[3:]), tuple(pb[3:]))
    assert same_rotation(np.array(q), se3.quaternion_multiply(pa[3:], pb[3:]))
    R_ab = Ta[:3, :3].T @ Tb[:3, :3]
    assert np.isclose(se3.angle_between3(Ta[:3, :3], Tb[:3, :3]), se3.rotation_angle(R_ab), atol=1e-9)


@given(rotvecs())
def test_fast_rotvec_paths_agree(w):
    R = se3.matrix_from_rotvec(w)
    assert np.allclose(se3.matrix3_from_rotvec(*w), R, atol=1e-12)
    assert np.allclose(se3.rows_from_rotvec(*w), R.ravel(), atol=1e-12)
    assert np.allclose(se3.rotvec_from_matrix3(R), se3.rotvec_from_matrix(R), atol=1e-9)


@given(poses(scale=2.0), poses(scale=2.0))
def test_flat_transforms_agree_with_matrices(pa, pb):
    Ta, Tb = se3.transform_from_pose(pa), se3.transform_from_pose(pb)
    Fa, Fb = se3.flat_from_matrix4(Ta), se3.flat_from_matrix4(Tb)
    assert len(Fa) == 12 and all(type(x) is float for x in Fa)
    assert np.array_equal(se3.matrix4_from_flat(Fa), Ta)
    assert np.allclose(se3.matrix4_from_flat(se3.compose_flat(Fa, Fb)), Ta @ Tb, atol=1e-12)
    assert np.allclose(se3.matrix4_from_flat(se3.invert_flat(Fa)), se3.invert_transform(Ta),
                       atol=1e-12)


@pytest.mark.parametrize("k", range(9))
@pytest.mark.parametrize("bad", [float("nan"), float("inf"), float("-inf")])
def test_quaternion_from_rows_propagates_non_finite(k, bad):
    """Every Shepperd branch reads all nine entries: one bad entry spoils the result."""
    for w in ([0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.0, 0.0, 3.0]):
        rows = list(se3.rows_from_rotvec(*w))
        rows[k] = bad
        assert not all(np.isfinite(se3.quaternion_from_rows(*rows)))
