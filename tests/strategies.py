"""Shared hypothesis strategies: unit quaternions, poses, small displacements."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

finite = st.floats(-1.0, 1.0, allow_nan=False, allow_infinity=False)


@st.composite
def unit_quaternions(draw):
    v = np.array([draw(st.floats(-1, 1)) for _ in range(4)])
    if np.linalg.norm(v) < 1e-3:
        v = np.array([0.0, 0.0, 0.0, 1.0])
    v = v / np.linalg.norm(v)
    return v if v[3] >= 0 else -v


@st.composite
def poses(draw, scale=1.0):
    t = np.array([draw(st.floats(-scale, scale)) for _ in range(3)])
    return np.concatenate([t, draw(unit_quaternions())])


@st.composite
def rotvecs(draw, max_angle=np.pi - 1e-3):
    axis = np.array([draw(st.floats(-1, 1)) for _ in range(3)])
    if np.linalg.norm(axis) < 1e-3:
        axis = np.array([0.0, 0.0, 1.0])
    axis /= np.linalg.norm(axis)
    return axis * draw(st.floats(0.0, max_angle))
