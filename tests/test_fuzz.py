"""A short coverage-guided fuzz run of every decoder (the full one is `sctd bench fuzz`):
only the documented errors may escape (DecodeError, FrameDecodeError, SkillError, FileError,
InputError, LogError)."""

import pytest

from sctd.bench.fuzz import TARGETS, run_target
from tests.conftest import ROOT
from tests.tiers import needs

pytestmark = pytest.mark.slow  # fuzzing, in a child

needs("atheris")  # the dev extra: skipped naming it where it is missing, a failure under CI


@pytest.mark.parametrize("target", TARGETS)
def test_decoder_raises_only_its_documented_error(target, tmp_path):
    r = run_target(target, 2000, ROOT / "skills", tmp_path, timeout=300)
    assert r["ok"], r["log_tail"]
    assert r["runs"] >= 2000 and r["coverage"]
