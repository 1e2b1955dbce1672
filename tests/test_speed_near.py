"""The ``speed_near`` constraint: near the skill's object, a command's step moves the
capped point and turns the hand no faster than the cap, whatever the input and the
other elements ask for, the runtime's own step bound included; away from it, and in a
skill without it, nothing changes."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd import se3
from sctd.runtime.controller import Controller, RuntimeConfig, Sample
from sctd.skill import Bundle, SkillEngine, SkillError, SpeedNear, skill_from_bundle
from tests.strategies import unit_quaternions
from tests.test_controller import Fed, inp

RIM = [0.035, 0.0, 0.10]  # a point of the hand: a cup's rim, as an offset in the frame


def skill_doc(constraints: list[dict], axes=("tx", "ty", "tz", "rx", "ry", "rz"), frame="ee",
              v=0.5, w=2.0) -> dict:
    """A one-state skill: a linear mapping of six input axes on ``frame``, then
    ``constraints``; fast limits, so that the cap is what bounds the step."""
    return {"sctd_skill": 1, "name": "near", "object": "mouth",
            "limits": {"max_linear_speed": v, "max_angular_speed": w},
            "frames": {"tip": {"parent": "ee", "pose": [0.01, -0.02, 0.12, 0.0, 0.0, 0.0, 1.0]},
                       "rim": {"parent": "ee", "pose": [*RIM, 0.0, 0.0, 0.0, 1.0]}},
            "fsm": {"start": "s", "end": "s", "transitions": []},
            "states": {"s": {"input_mapping": [{"type": "linear", "frame": frame, "axes": list(axes)}],
                             "active_constraints": constraints}}}


def cap(within=0.10, v=0.03, w=0.3, **more) -> dict:
    return {"type": "speed_near", "within": within, "max_linear_speed": v, "max_angular_speed": w, **more}


def load_text(text: str):
    return skill_from_bundle(Bundle("near.yaml", text, {}))


def engine(doc: dict) -> SkillEngine:
    return SkillEngine(load_text(yaml.safe_dump(doc)))


def point_of(F, c: SpeedNear, eng: SkillEngine) -> np.ndarray:
    G = eng.workspace.frame_pose(F, c.frame)
    T = se3.transform_from_flat(G)
    p = np.zeros(3) if c.point is None else c.point
    return T[:3, :3] @ p + T[:3, 3]


def turn(F_a, F_b) -> float:
    Ra, Rb = se3.transform_from_flat(F_a)[:3, :3], se3.transform_from_flat(F_b)[:3, :3]
    return float(np.linalg.norm(se3.rotvec_from_matrix(Ra.T @ Rb)))


def within_cap(F_a, F_b, c: SpeedNear, eng: SkillEngine, dt: float) -> bool:
    """Whether the step F_a -> F_b keeps the cap (to rounding) or is away from the object."""
    a, b = point_of(F_a, c, eng), point_of(F_b, c, eng)
    if min(np.linalg.norm(a), np.linalg.norm(b)) > c.within:
        return True
    moved = float(np.linalg.norm(b - a))
    return (moved <= c.max_linear_speed * dt * (1 + 1e-9) + 1e-15
            and turn(F_a, F_b) <= c.max_angular_speed * dt * (1 + 1e-9) + 1e-12)


inputs = st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=6, max_size=6)
near_positions = st.lists(st.floats(-0.2, 0.2, allow_nan=False), min_size=3, max_size=3)


@st.composite
def capped_skills(draw) -> tuple[SkillEngine, SpeedNear]:
    """A skill whose linear mapping drives any frame, with other constraints around a
    ``speed_near`` of any frame, point, radius and cap."""
    c = cap(within=draw(st.floats(0.01, 0.3)), v=draw(st.floats(1e-3, 0.2)), w=draw(st.floats(1e-2, 1.5)),
            frame=draw(st.sampled_from(("ee", "tip"))))
    if draw(st.booleans()):
        c["point"] = draw(st.lists(st.floats(-0.2, 0.2), min_size=3, max_size=3))
    others = [{"type": "tilt_cone", "max_angle": draw(st.floats(0.1, 1.5))},
              {"type": "band", "lower": -0.05, "upper": 0.05, "frame": "tip"}]
    constraints = draw(st.permutations([c, *draw(st.lists(st.sampled_from(others), max_size=2))]))
    eng = engine(skill_doc(constraints, frame=draw(st.sampled_from(("ee", "tip")))))
    limit = next(x for x in eng.skill.states[0].active_constraints if isinstance(x, SpeedNear))
    return eng, limit


@settings(max_examples=300, deadline=None)
@given(capped_skills(), near_positions, unit_quaternions(), inputs, st.floats(1e-4, 0.02))
def test_a_command_near_the_object_never_exceeds_the_cap(skill, p, q, u, dt):
    eng, c = skill
    F = se3.flat_from_pose([*p, *q.tolist()])
    F_new = eng.command(F, u, dt)
    assert all(math.isfinite(x) for x in F_new)
    assert within_cap(F, F_new, c, eng, dt)


@settings(max_examples=200, deadline=None)
@given(capped_skills(), near_positions, unit_quaternions(), inputs, st.floats(1e-4, 0.02),
       st.floats(0.0, 1.0))
def test_any_fraction_of_a_capped_step_keeps_the_cap(skill, p, q, u, dt, s):
    """The daemon's step bound scales a step back along the same path (``limit_step``):
    whatever fraction of the capped step it keeps is within the cap too."""
    from sctd.runtime.safety import limit_step, separation

    eng, c = skill
    F = se3.flat_from_pose([*p, *q.tolist()])
    F_new = eng.command(F, u, dt)
    moved, turned = separation(F, F_new)
    F_part = limit_step(F, F_new, s * moved, s * turned)
    assert within_cap(F, F_part, c, eng, dt)


def test_a_step_that_would_leap_across_the_zone_is_capped():
    """Both ends outside the zone, the path through it: a band on a frame 12 cm above
    the hand pulls the hand 19.5 cm down through the object's origin in one command. Found
    by the property test above (a fraction of that step landed inside the zone): the cap
    holds anywhere along a step, not only at its ends."""
    c = cap(within=0.0625, v=0.125, w=1.0, frame="ee")
    band = {"type": "band", "lower": -0.05, "upper": 0.05, "frame": "tip"}
    eng = engine(skill_doc([c, band], frame="ee"))
    F = se3.flat_from_pose([0.0, 0.0, 0.125, 0.0, 0.0, 0.0, 1.0])
    dt = 1.0 / 64
    F_new = eng.command(F, [0.0] * 6, dt)
    moved = math.dist(F[9:], F_new[9:])
    assert 0.0 < moved <= 0.125 * dt * (1 + 1e-9)
    # a step beside the zone, its nearest point 7 cm from the origin: not capped
    eng = engine(skill_doc([c], frame="ee"))
    F = se3.flat_from_pose([0.07, -0.1, 0.0, 0.0, 0.0, 0.0, 1.0])
    assert math.dist(F[9:], eng.command(F, [0.0, 1.0, 0.0, 0.0, 0.0, 0.0], 0.4)[9:]) == pytest.approx(0.2)


def tick_samples(T_world_obj: np.ndarray):
    F_obj = se3.flat_from_transform(T_world_obj)

    def samples(t: float, T_meas: np.ndarray) -> tuple[Sample, Sample]:
        return (Sample(seq=0, stamp=t, received=t, F=se3.flat_from_transform(T_meas)),
                Sample(seq=0, stamp=t, received=t, F=F_obj))
    return samples


@settings(max_examples=40, deadline=None)
@given(capped_skills(), near_positions, st.lists(inputs, min_size=5, max_size=40))
def test_the_runtime_publishes_no_target_faster_than_the_cap(skill, p, us):
    """Through the whole tick (the arbiter, the skill, the daemon's speed and offset
    bounds), every published target near the object keeps the cap, and is finite."""
    eng, c = skill
    T_world_obj = se3.transform_from_pose([0.3, -0.35, 0.85, 0.0, 0.0, math.sin(0.35), math.cos(0.35)])
    T_start = T_world_obj @ se3.transform_from_pose([*p, 0.0, 0.0, 0.0, 1.0])
    fed = Fed(Controller(eng.skill, RuntimeConfig()))
    samples = tick_samples(T_world_obj)
    t, prev = 0.0, None
    for k, u in enumerate([[0.0] * 6, *us]):
        meas = fed.T_world_target if fed.T_world_target is not None else T_start
        r = fed.tick(t, t, inp(np.clip(u, -1, 1), t, seq=k), *samples(t, meas))
        T = r.T_world_target
        assert T is not None and np.all(np.isfinite(T))
        F = se3.flat_from_transform(se3.invert_transform(T_world_obj) @ T)
        if prev is not None:
            assert within_cap(prev, F, c, fed.engine, fed.config.period)
        prev = F
        t += fed.config.period


def test_near_the_object_the_point_moves_at_the_cap_and_away_from_it_at_the_limit():
    eng = engine(skill_doc([cap(point=RIM)]))
    dt = 0.001
    F_near = se3.flat_from_pose([0.03, 0.0, -0.09, 0.0, 0.0, 0.0, 1.0])  # the rim 4.5 cm from the mouth
    F = eng.command(F_near, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0), dt)
    assert F[9] - F_near[9] == pytest.approx(0.03 * dt, rel=1e-12)
    F_far = se3.flat_from_pose([0.30, 0.0, -0.09, 0.0, 0.0, 0.0, 1.0])
    F = eng.command(F_far, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0), dt)
    assert F[9] - F_far[9] == pytest.approx(0.5 * dt, rel=1e-12)  # the skill's own limit
    # tilted about the rim (it stays put), the hand turns at the angular cap; about the
    # hand's origin, the rim 0.106 m from it, at what keeps the rim at the linear cap
    about_rim = engine(skill_doc([cap(point=RIM)], axes=("rx", "ry", "rz"), frame="rim"))
    F = about_rim.command(F_near, (0.0, 1.0, 0.0), dt)
    assert turn(F_near, F) == pytest.approx(0.3 * dt, rel=1e-9)
    about_hand = engine(skill_doc([cap(point=RIM)], axes=("rx", "ry", "rz")))
    F = about_hand.command(F_near, (0.0, 1.0, 0.0), dt)
    c = about_hand.skill.states[0].active_constraints[0]
    rim_moved = float(np.linalg.norm(point_of(F, c, about_hand) - point_of(F_near, c, about_hand)))
    assert rim_moved == pytest.approx(0.03 * dt, rel=1e-6) and turn(F_near, F) < 0.3 * dt


def test_a_cap_that_never_applies_changes_no_command_to_the_bit():
    """Far from the object a ``speed_near`` leaves every command as the skill without it
    makes it: the same floats."""
    rng = np.random.default_rng(3)
    others = [{"type": "tilt_cone", "max_angle": 0.5}, {"type": "band", "lower": -0.5, "upper": 0.5}]
    plain, capped = engine(skill_doc(others)), engine(skill_doc([*others, cap(within=1e-3, point=RIM)]))
    for _ in range(200):
        F = se3.flat_from_pose([*rng.uniform(0.2, 0.6, 3), *se3.quaternion_normalize(rng.normal(size=4))])
        u = rng.uniform(-1, 1, 6)
        assert capped.command(F, u, 0.001) == plain.command(F, u, 0.001)


@pytest.mark.parametrize(("field", "value", "problem"), [
    ("within", 0.0, "must be > 0.0"),
    ("within", 3.0, "must be <= 2.0"),
    ("max_linear_speed", -0.1, "must be > 0.0"),
    ("max_angular_speed", 4.0, "must be <= 3.0"),
    ("point", [0.0, 0.0, 2.0], "must be within 1 m of the frame's origin"),
    ("point", [0.0, 0.0], "expected a list of 3 numbers"),
    ("frame", "object", "must move with the end-effector"),
    ("radius", 0.1, "unknown field"),
])
def test_a_bad_speed_near_is_refused_naming_the_field(field, value, problem):
    c = cap()
    c[field] = value
    with pytest.raises(SkillError) as e:
        load_text(yaml.safe_dump(skill_doc([c])))
    assert f"states.s.active_constraints[0].{field}" in str(e.value) and problem in str(e.value)


def test_a_missing_cap_is_refused():
    c = cap()
    del c["max_linear_speed"]
    with pytest.raises(SkillError, match=r"active_constraints\[0\]\.max_linear_speed: expected a number"):
        load_text(yaml.safe_dump(skill_doc([c])))


def test_it_reads_as_written_and_shows_in_the_summary():
    skill = load_text(yaml.safe_dump(skill_doc([cap(point=RIM)])))
    (c,) = skill.states[0].active_constraints
    assert isinstance(c, SpeedNear)
    assert (c.within, c.max_linear_speed, c.max_angular_speed) == (0.1, 0.03, 0.3)
    assert c.summary() == {"type": "speed_near", "frame": "ee", "within": 0.1, "max_linear_speed": 0.03,
                           "max_angular_speed": 0.3, "point": RIM}
