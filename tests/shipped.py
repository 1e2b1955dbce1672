"""Comparing what the learner writes today with a shipped skill's models.

The shipped model files were written on one machine; the learner's arithmetic on
another CPU picks other BLAS kernels (OpenBLAS's Haswell kernels on an AMD EPYC or an
AVX2 Intel CPU, SkylakeX's on an AVX-512 Intel one), which round a field's weight or
centre differently in the last bits. A learned skill is the shipped one when its
fields have the same kinds, counts and texts and their numbers agree to that rounding
(a relative 1e-9, far below any figure a skill file prints); the YAML's own text,
which prints the fields to 4-6 decimals, is compared whole by the tests themselves.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sctd.skill.modelfile import VectorFieldModel

RTOL = 1e-9  # relative: last-bit rounding of a few kernels' sums, with room
ATOL = 1e-12  # for numbers at zero


def assert_same_value(a: Any, b: Any, where: str) -> None:
    """``a`` and ``b`` (a field's ``to_yaml`` values) equal, numbers to RTOL/ATOL."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), f"{where}: keys {sorted(a)} != {sorted(b)}"
        for k in a:
            assert_same_value(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        assert len(a) == len(b), f"{where}: {len(a)} != {len(b)} entries"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same_value(x, y, f"{where}[{i}]")
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)) and not isinstance(a, bool):
        assert type(a) is type(b) or float(a) == float(b), f"{where}: {a!r} != {b!r}"
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=ATOL, err_msg=where)
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def assert_same_models(learned: VectorFieldModel, shipped: VectorFieldModel, where: str = "model") -> None:
    """The learned model is the shipped one: its fields (kinds, parameters) and its
    demonstration points, to the kernels' rounding."""
    assert_same_value([f.to_yaml() for f in learned.fields], [f.to_yaml() for f in shipped.fields],
                      f"{where}.fields")
    for x in ("points", "quaternions", "responsibilities"):
        np.testing.assert_allclose(getattr(learned, x), getattr(shipped, x), rtol=RTOL, atol=1e-9,
                                   err_msg=f"{where}.{x}")
