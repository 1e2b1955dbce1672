"""The arm's cycle without the joint bus's frames (``SimArm(joint_bus=False)``, lockstep's
path) comes to the same numbers as with them, bit for bit: the signals' rounding, the
arm's cycle, and a lockstep trial's whole record."""

from __future__ import annotations

import json
import math
import random
import struct
from dataclasses import replace

import numpy as np
import pytest

from sctd.skill import load_skill
from sctd.skill.catalog import find_skill
from sctd_services.eval.evaluate import task_of
from sctd_services.eval.lockstep import run_trial
from sctd_services.eval.trial import TaskSpec
from sctd_sim.arm import SimArm
from sctd_sim.canbus import BusValues, FaultConfig, JointBusCodecs, signal_rounding


def _bits(xs) -> list[bytes]:
    """The doubles' bit patterns (0.0 and -0.0 differ, as NaN payloads would)."""
    return [struct.pack("<d", float(x)) for x in xs]


def _values(scale: float, lo: float, hi: float, rng: random.Random) -> list[float]:
    """Values over a signal's range and beyond it: random, exact half steps (where the
    rounding's tie rule shows), zeros of both signs, tiny ones, the range's ends."""
    span = hi - lo
    xs = [rng.uniform(lo - 0.1 * span, hi + 0.1 * span) for _ in range(400)]
    xs += [(rng.randint(int(lo / scale), int(hi / scale)) + 0.5) * scale for _ in range(200)]
    xs += [0.0, -0.0, 1e-12, -1e-12, scale / 2, -scale / 2, lo, hi, lo - scale, hi + scale, 1e9, -1e9]
    return xs


@pytest.mark.parametrize("kind, names", [("cmd", ("Torque",)),
                                         ("state", ("Position", "Velocity", "Torque"))])
def test_the_rounding_is_what_a_frame_carries_bit_for_bit(kind: str, names: tuple[str, ...]) -> None:
    codecs = JointBusCodecs()
    codec = (codecs.cmd if kind == "cmd" else codecs.state)[2]
    rng = random.Random(7)
    for name in names:
        i = codec.signal_names.index(name)
        xs = _values(codec.resolution(name), *codec.limits(name), rng)
        got = signal_rounding(codec.field(name))(xs)
        want = []
        for x in xs:
            vals = [0.0] * len(codec.signal_names)
            vals[i] = x
            ok, _counter, decoded = codec.decode(codec.encode(5, vals))
            assert ok
            want.append(decoded[i])
        assert _bits(got) == _bits(want), name
        assert any(g != x for g, x in zip(got, xs, strict=True)), "nothing was rounded: nothing checked"


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_value_the_frame_cannot_carry_is_refused_as_the_encoder_refuses_it(bad: float) -> None:
    codecs = JointBusCodecs()
    with pytest.raises((ValueError, OverflowError)):
        codecs.cmd[0].encode(0, [1, bad, 0.0, 0.0])
    with pytest.raises((ValueError, OverflowError)):
        BusValues(codecs).command(np.array([0.0, bad, 0, 0, 0, 0, 0]), True)


def _cycles(joint_bus: bool, n: int = 2500) -> tuple[list[bytes], dict]:
    """``n`` cycles of the arm after a target that moves, drops far away (saturated
    torques), with the drives disabled for a while: every cycle's measured and true
    state, commands and status bits, and the link's counters at the end."""
    out = []
    with SimArm(joint_bus=joint_bus) as arm:
        T0 = arm.T_world_ee
        for k in range(n):
            T = T0.copy()
            T[0, 3] += 0.2 * math.sin(0.004 * k)
            T[2, 3] -= 0.6 if k > 1200 else 0.0
            arm.set_target(T, 0.001 * k)
            arm.enabled = not 1800 <= k < 1900
            arm.step()
            m, d = arm.master, arm.drives
            out.append(b"".join(a.tobytes() for a in (m.q, m.dq, m.tau, m.status, m.fresh, arm.dynamics.q,
                                                      arm.dynamics.dq, d.tau_cmd, d.braked, d.status)))
        return out, arm.link_stats()


def test_the_cycle_without_frames_is_the_cycle_with_them() -> None:
    with_bus, stats_bus = _cycles(True)
    without, stats = _cycles(False)
    first = next((k for k, (a, b) in enumerate(zip(with_bus, without, strict=True)) if a != b), None)
    assert first is None, f"cycle {first} differs"
    assert stats == stats_bus
    assert stats["brake_events"] > 0  # the disabled stretch braked: that part was exercised


def test_the_cycle_without_frames_has_no_faults_to_inject() -> None:
    with pytest.raises(ValueError, match="joint_bus"):
        SimArm(joint_bus=False, faults=FaultConfig(seed=1))


@pytest.mark.parametrize("skill", ["pour-vf", "drawer"])
def test_a_lockstep_trial_comes_to_the_same_record_either_way(skill: str) -> None:
    loaded = load_skill(find_skill(skill))
    task = task_of([loaded], None)
    spec = TaskSpec.of(task, time_limit=2.5)
    got = {bus: run_trial(loaded, replace(spec, joint_bus=bus), 1, task=task).as_dict(with_trajectory=True)
           for bus in (True, False)}
    assert json.dumps(got[True], sort_keys=True) == json.dumps(got[False], sort_keys=True)
    assert len(got[True]["trajectory"]) > 100  # a trajectory was compared
