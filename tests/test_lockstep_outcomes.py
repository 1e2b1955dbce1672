"""Lockstep trials on fixed seeds come to the outcomes recorded in
``tests/data/lockstep_outcomes.json``: the same outcome, the same times to the millisecond
and mode switches, and the same spill and progress to 1e-4; with the arm's joint values as
CAN frames and without them (lockstep's default: the values rounded as the frames would
carry them), which so come to the same outcomes.

The file was written by ``python -m tests.test_lockstep_outcomes`` on the code before the
simulator's and the lockstep step's speed-ups, and kept through them: it is the proof that
making a step cheaper did not change what a trial comes to. A change that is meant to
change outcomes (a new skill, new physics, the simulated person's new rule of 2026-12-07)
re-records it and says why in its commit.

The trials run in a child process with OpenBLAS's kernels pinned to its Haswell (AVX2)
ones, those the file was recorded with: OpenBLAS picks its kernels by the CPU, and on a
CPU with AVX-512 its SkylakeX kernels round small matrix products differently,
enough for a pour to finish 0.1 s later (pour and pour-vf seed 2) and for the readings to
move by up to 0.03. Pinned, such a machine reproduces the file to the last digit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from tests.tiers import needs

DATA = Path(__file__).parent / "data" / "lockstep_outcomes.json"
SKILLS = ("pour", "pour-vf", "drawer", "drawer-vf")
SEEDS = (0, 1, 2)
TIME_LIMIT = 30.0  # s per trial: long enough for these skills' successes, short enough to test
KERNELS = {"OPENBLAS_CORETYPE": "Haswell", "OPENBLAS_NUM_THREADS": "1"}
"""The numerics the file was recorded with (the module's docstring)."""
FIELDS = ("outcome", "reason", "time_s", "duration_s", "spill", "progress", "mode_switches")


def outcome(skill: str, seed: int, joint_bus: bool = False) -> dict[str, Any]:
    """What the lockstep trial of ``skill`` (a catalogue name) from ``seed`` comes to, its
    arm's joint values as CAN frames or not (``joint_bus``): the fields of :data:`FIELDS`,
    floats rounded to the millisecond (times) or to 1e-6."""
    needs("pinocchio")
    from sctd.skill import load_skill
    from sctd.skill.catalog import find_skill
    from sctd_services.eval.evaluate import task_of
    from sctd_services.eval.lockstep import run_trial
    from sctd_services.eval.trial import TaskSpec

    loaded = load_skill(find_skill(skill))
    task = task_of([loaded], None)
    spec = TaskSpec.of(task, time_limit=TIME_LIMIT)
    r = run_trial(loaded, replace(spec, joint_bus=joint_bus), seed, task=task).as_dict()
    # the file's spill: the task's spill reading (<held>.spilled), 0 for a task without one
    r["spill"] = next((v for k, v in r["readings"].items() if k.endswith(".spilled")), 0.0)
    got = {k: r[k] for k in FIELDS}
    for k in ("time_s", "duration_s"):
        got[k] = None if got[k] is None else round(got[k], 3)
    for k in ("spill", "progress"):
        got[k] = round(got[k], 6)
    return got


def _recorded() -> dict[str, dict[str, Any]]:
    return json.loads(DATA.read_text())["trials"]


def _has_avx2() -> bool:
    try:
        return " avx2" in Path("/proc/cpuinfo").read_text()
    except OSError:
        return False


def pinned_outcomes(skill: str, joint_bus: bool = False) -> dict[int, dict[str, Any]]:
    """:func:`outcome` of every seed, worked out in a child process whose OpenBLAS runs
    the recording's kernels (:data:`KERNELS`)."""
    if not _has_avx2():
        pytest.fail("the recorded outcomes are reproduced with OpenBLAS's AVX2 kernels: this "
                    "CPU has no AVX2 (an x86-64 CPU with AVX2 runs this test)", pytrace=False)
    root = Path(__file__).resolve().parents[1]
    bus = ["--joint-bus"] if joint_bus else []
    done = subprocess.run([sys.executable, "-m", "tests.test_lockstep_outcomes", "--print", skill, *bus],
                          cwd=root, env={**os.environ, **KERNELS}, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return {int(k): v for k, v in json.loads(done.stdout).items()}


@pytest.mark.slow
@pytest.mark.parametrize("joint_bus", [False, True], ids=["values", "frames"])
@pytest.mark.parametrize("skill", SKILLS)
def test_lockstep_trials_come_to_the_recorded_outcomes(skill: str, joint_bus: bool) -> None:
    recorded = _recorded()
    outcomes = pinned_outcomes(skill, joint_bus)
    for seed in SEEDS:
        got, want = outcomes[seed], recorded[f"{skill}/{seed}"]
        exact = [k for k in FIELDS if k not in ("spill", "progress")]
        assert {k: got[k] for k in exact} == {k: want[k] for k in exact}, f"{skill} seed {seed}"
        # the scene's readings, to well within what a different rounding of the maths moves
        assert got["spill"] == pytest.approx(want["spill"], abs=1e-4), f"{skill} seed {seed}"
        assert got["progress"] == pytest.approx(want["progress"], abs=1e-4), f"{skill} seed {seed}"


def test_the_recorded_outcomes_cover_every_skill_and_seed() -> None:
    recorded = _recorded()
    assert sorted(recorded) == sorted(f"{s}/{k}" for s in SKILLS for k in SEEDS)
    assert {r["outcome"] for r in recorded.values()} >= {"success"}


def record() -> None:
    """Write :data:`DATA` from this checkout's code (see the module's docstring; run it
    with :data:`KERNELS` in the environment)."""
    trials = {f"{s}/{k}": outcome(s, k) for s in SKILLS for k in SEEDS}
    doc = {"about": "lockstep trials (tests/test_lockstep_outcomes.py), time limit "
                    f"{TIME_LIMIT} s; recorded before the simulator speed-ups and kept through "
                    "them; recorded again where a change meant to move outcomes says so (this "
                    "file's git log)",
           "trials": trials}
    DATA.parent.mkdir(exist_ok=True)
    DATA.write_text(json.dumps(doc, indent=1) + "\n")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--print"]:  # (the test's child: one skill's outcomes on stdout)
        print(json.dumps({seed: outcome(sys.argv[2], seed, "--joint-bus" in sys.argv) for seed in SEEDS}))
    else:
        record()
    sys.exit(0)
