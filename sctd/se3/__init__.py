"""SE(3) pose math on plain numpy arrays.

Poses are ``[x, y, z, qx, qy, qz, qw]`` (quaternion x-y-z-w, Hamilton, as ROS);
transforms are 4x4 homogeneous matrices; frames live in variable names
(``T_obj_ee`` is the end-effector's pose in the object frame). Conversions are named
``<out>_from_<in>``. See :mod:`sctd.se3._transforms` for the displacement convention
shared by the runtime and the learner.
"""

from ._fast import (
    angle_between3,
    compose_quaternions,
    invert4,
    matrix3_from_rotvec,
    matrix4_from_pose,
    pose_from_matrix4,
    quaternion_from_matrix3,
    quaternion_from_rows,
    rotvec_from_matrix3,
    rows_from_quaternion,
    rows_from_rotvec,
)
from ._rotations import (
    average_quaternion,
    euler_xyz_from_matrix,
    hat,
    matrix_from_euler_xyz,
    matrix_from_quaternion,
    matrix_from_rotvec,
    quaternion_angle,
    quaternion_conjugate,
    quaternion_from_matrix,
    quaternion_from_rotvec,
    quaternion_multiply,
    quaternion_normalize,
    rotation_angle,
    rotation_between,
    rotvec_from_matrix,
    rotvec_from_quaternion,
)
from ._transforms import (
    apply_displacement,
    displacement_from_transforms,
    exp_se3,
    invert_transform,
    log_se3,
    pose_from_transform,
    tf_norm,
    tf_norm_of_displacement,
    transform_from_displacement,
    transform_from_pose,
    transform_from_rt,
)

__all__ = [
    "angle_between3",
    "apply_displacement",
    "average_quaternion",
    "compose_quaternions",
    "displacement_from_transforms",
    "euler_xyz_from_matrix",
    "exp_se3",
    "hat",
    "invert4",
    "invert_transform",
    "log_se3",
    "matrix3_from_rotvec",
    "matrix4_from_pose",
    "matrix_from_euler_xyz",
    "matrix_from_quaternion",
    "matrix_from_rotvec",
    "pose_from_matrix4",
    "pose_from_transform",
    "quaternion_angle",
    "quaternion_conjugate",
    "quaternion_from_matrix",
    "quaternion_from_matrix3",
    "quaternion_from_rotvec",
    "quaternion_from_rows",
    "quaternion_multiply",
    "quaternion_normalize",
    "rotation_angle",
    "rotation_between",
    "rotvec_from_matrix",
    "rotvec_from_matrix3",
    "rotvec_from_quaternion",
    "rows_from_quaternion",
    "rows_from_rotvec",
    "tf_norm",
    "tf_norm_of_displacement",
    "transform_from_displacement",
    "transform_from_pose",
    "transform_from_rt",
]
