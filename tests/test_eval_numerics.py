"""An evaluation says which numerical kernels ran it (sctd_services.eval.numerics):
lockstep trials are deterministic per machine, and the BLAS kernels are what differs
between machines."""

import subprocess
import sys

import pytest

from sctd_services.eval.numerics import describe, numerics


def test_the_blas_kernels_and_the_forced_core_type_are_named(monkeypatch):
    pytest.importorskip("threadpoolctl")
    import numpy as np

    np.ones((8, 8)) @ np.ones((8, 8))  # (BLAS loaded)
    monkeypatch.setenv("OPENBLAS_CORETYPE", "Haswell")
    n = numerics()
    assert n["numpy"] == np.__version__ and n["machine"]
    assert n["blas"] and all(b.split()[0] in {"openblas", "mkl", "blis", "flexiblas"} for b in n["blas"])
    assert n["openblas_coretype"] == "Haswell"
    line = describe(n)
    assert line.startswith("numerics: ") and "OPENBLAS_CORETYPE=Haswell" in line and n["blas"][0] in line
    assert "OPENBLAS_CORETYPE" not in describe({**n, "openblas_coretype": None})
    assert "BLAS unknown" in describe({**n, "blas": None})


@pytest.mark.slow
def test_a_forced_core_type_is_the_one_openblas_runs():
    """OpenBLAS reads OPENBLAS_CORETYPE when it loads: a child process told Haswell
    reports Haswell kernels (what reproduces an AVX2 machine's lockstep figures)."""
    code = "import numpy; from sctd_services.eval.numerics import numerics; print(numerics()['blas'])"
    env = {"OPENBLAS_CORETYPE": "Haswell", "PATH": "/usr/bin"}
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "openblas" in out.stdout and "Haswell" in out.stdout, out.stdout
