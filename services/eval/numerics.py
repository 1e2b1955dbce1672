"""Which numerical kernels ran an evaluation.

A lockstep trial is deterministic on one machine, not across machines: OpenBLAS picks its
kernels by the CPU (SkylakeX on a CPU with AVX-512, Haswell on one with AVX2), and they
round small matrix products differently, enough for a trial on the edge of getting stuck
to come out the other way (docs/evaluation.md). An evaluation's JSON says which kernels
it ran on, so that figures from two machines can be compared, and
``OPENBLAS_CORETYPE=Haswell`` reproduces an AVX2 machine's figures on an AVX-512 one.
"""

from __future__ import annotations

import os
import platform
from typing import Any

import numpy as np


def numerics() -> dict[str, Any]:
    """The CPU's architecture, numpy's version, the BLAS libraries loaded in this process
    with the kernels each picked (``"openblas 0.3.31 SkylakeX"``; None when
    ``threadpoolctl``, which scikit-learn brings, is not installed) and
    ``OPENBLAS_CORETYPE`` if it is set. Worker processes on the same machine and
    environment pick the same."""
    out: dict[str, Any] = {"machine": platform.machine(), "numpy": np.__version__, "blas": None,
                           "openblas_coretype": os.environ.get("OPENBLAS_CORETYPE")}
    try:
        from threadpoolctl import threadpool_info
    except ImportError:
        return out
    out["blas"] = [" ".join(str(x) for x in (i.get("internal_api"), i.get("version"), i.get("architecture"))
                            if x) for i in threadpool_info() if i.get("user_api") == "blas"]
    return out


def describe(n: dict[str, Any]) -> str:
    """One line for a report: ``numerics: openblas 0.3.31 SkylakeX (x86_64, numpy 2.4.6)``."""
    blas = ", ".join(n["blas"]) if n.get("blas") else "BLAS unknown"
    forced = f", OPENBLAS_CORETYPE={n['openblas_coretype']}" if n.get("openblas_coretype") else ""
    return f"numerics: {blas} ({n['machine']}, numpy {n['numpy']}{forced})"
