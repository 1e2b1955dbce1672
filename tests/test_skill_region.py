"""A skill's region, where its demonstrations went (sctd.skill.region): the box, its
file form and its checks, what the learner writes, and status.region, which tells the
person from the first status on that the hand is outside it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import given
from hypothesis import strategies as st

from sctd import se3
from sctd.runtime.controller import RuntimeConfig
from sctd.runtime.driver import TickDriver
from sctd.skill import Bundle, SkillError, load_skill, skill_from_bundle
from sctd.skill.region import MARGIN, Region
from sctd.skill.writer import dump_skill
from sctd.wire.codec import ObjectMsg, StateMsg

ROOT = Path(__file__).resolve().parents[1]
finite = st.floats(-2.0, 2.0, allow_nan=False)


def test_the_box_around_points_is_widened_by_the_margin_and_measures_from_its_faces():
    r = Region.around("mug", [[0.0, 0.0, 0.0], [0.2, 0.1, -0.1]], demonstrations=2)
    assert r.centre == (0.1, 0.05, -0.05)
    assert r.half_extents == pytest.approx((0.1 + MARGIN, 0.05 + MARGIN, 0.05 + MARGIN))
    assert r.outside_by((0.1, 0.05, -0.05)) == 0.0 and r.outside_by((0.25, 0.15, 0.05)) == 0.0
    assert r.outside_by((0.35, 0.05, -0.05)) == pytest.approx(0.1)  # 0.1 beyond the +x face
    assert r.outside_by((0.35, 0.25, -0.05)) == pytest.approx(math.hypot(0.1, 0.1))  # past a corner
    with pytest.raises(ValueError, match="at least one"):
        Region.around("mug", np.zeros((0, 3)))


@given(st.lists(st.tuples(finite, finite, finite), min_size=1, max_size=20),
       st.tuples(finite, finite, finite))
def test_every_point_it_was_drawn_around_is_inside_and_distance_is_never_negative(points, q):
    r = Region.around("mug", points)
    assert all(r.outside_by(p) <= 1e-3 for p in points)  # (the centre and extents rounded to 0.1 mm)
    assert r.outside_by(q) >= 0.0


def _with_region(text: str, region) -> Bundle:
    doc = yaml.safe_load(text)
    doc["region"] = region
    return Bundle("x.yaml", yaml.safe_dump(doc, sort_keys=False), {})


POUR = (ROOT / "skills" / "pour.yaml").read_text()


def test_a_skill_file_round_trips_its_region_and_bad_ones_are_named():
    good = {"frame": "mug", "centre": [0.1, 0.0, 0.05], "half_extents": [0.2, 0.2, 0.1], "demonstrations": 8}
    skill = skill_from_bundle(_with_region(POUR, good))
    assert skill.region == Region("mug", (0.1, 0.0, 0.05), (0.2, 0.2, 0.1), 8)
    again = skill_from_bundle(Bundle("y.yaml", dump_skill(skill), {}))
    assert again.region == skill.region
    for bad, says in (({**good, "frame": "cup"}, "region.frame: 'cup' is no body of the skill (mug)"),
                      ({**good, "half_extents": [0.2, 0.0, 0.1]}, "region.half_extents[1]: must be > 0"),
                      ({**good, "centre": [0.1, 0.0]}, "region.centre: expected a list of 3 numbers"),
                      ({**good, "shape": "ball"}, "region.shape: unknown field"),
                      ({**good, "demonstrations": -1}, "region.demonstrations: must be >= 0")):
        with pytest.raises(SkillError) as e:
            skill_from_bundle(_with_region(POUR, bad))
        assert says in str(e.value), str(e.value)


def test_the_learner_writes_the_region_its_demonstrations_went_through():
    """Every shipped learned skill has one (skills/README.md's commands write it), in the
    frame it was learned in, around every demonstrated position of the hand."""
    from sctd.learn.demos import read_demos

    tap = load_skill(ROOT / "skills" / "tap-linear.yaml")
    assert tap.region is not None and tap.region.frame == "tap" and tap.region.demonstrations == 10
    for demo in read_demos(ROOT / "skills" / "demos" / "tap"):
        assert max(tap.region.outside_by(p) for p in demo.poses[:, :3].tolist()) < 0.02
    cup = load_skill(ROOT / "skills" / "cup_to_table-linear.yaml")  # learned in the shelf's frame
    assert cup.region is not None and cup.region.frame == "shelf"


class Rig:
    """A tick driver of ``skill`` with the hand at ``hand`` and the body ``body`` at
    ``at`` (world poses)."""

    def __init__(self, skill, body: str, at, hand):
        self.drv = TickDriver(skill, RuntimeConfig())
        self.drv.take_object(body, ObjectMsg(1, 0.001, list(at)), 0.001)
        self.drv.take_state(StateMsg(1, 0.001, list(hand), None), 0.001)


def test_status_region_tells_where_the_hand_is_against_the_region():
    """The box is in the body's frame: a body turned a quarter about the vertical turns
    the box with it. Inside: 0; outside: how far. No region, or the body unseen: None."""
    skill = skill_from_bundle(_with_region(POUR, {"frame": "mug", "centre": [0.2, 0.0, 0.0],
                                                  "half_extents": [0.1, 0.05, 0.05]}))
    q = se3.quaternion_from_matrix(se3.matrix_from_rotvec([0.0, 0.0, math.pi / 2])).tolist()
    mug = [1.0, 0.0, 0.5, *q]  # its x along the world's y
    inside = Rig(skill, "mug", mug, [1.0, 0.25, 0.5, 0, 0, 0, 1]).drv.region()
    assert inside is not None and inside["inside"] and inside["outside_by"] == 0.0
    assert inside["frame"] == "mug" and inside["centre"] == [0.2, 0.0, 0.0]
    out = Rig(skill, "mug", mug, [1.2, 0.2, 0.5, 0, 0, 0, 1]).drv.region()  # 0.2 along the mug's -y
    assert out is not None and not out["inside"] and out["outside_by"] == pytest.approx(0.15)
    assert Rig(skill, "cup", mug, [1.0, 0.25, 0.5, 0, 0, 0, 1]).drv.region() is None  # (the mug unseen)
    plain = load_skill(ROOT / "skills" / "pour.yaml")
    assert plain.region is None and Rig(plain, "mug", mug, [1.0, 0.25, 0.5, 0, 0, 0, 1]).drv.region() is None


def test_a_skill_out_of_its_region_whose_object_is_absent_or_stale_holds_and_says_why():
    """cabinet-vf pushed from outside its region: with the handle never seen it waits and
    publishes nothing (no region to tell); seen once, it runs and says how far outside
    its region the hand is; once the handle's pose is older than the object timeout the
    hand holds where it was, still saying so."""
    from sctd.wire.codec import InputMsg

    drv = TickDriver(load_skill(ROOT / "skills" / "cabinet-vf.yaml"), RuntimeConfig())
    hand = [0.3, 0.3, 0.7, 0.0, 0.0, 0.0, 1.0]
    held = None
    for k in range(1, 1400):
        t = 0.001 * k
        drv.take_state(StateMsg(k, t, hand, None), t)
        if k == 100:
            drv.take_object("door_handle", ObjectMsg(1, t, [0.69, -0.18, 0.62, 0.0, 0.0, 1.0, 0.0]), t)
        drv.take_input("pad", InputMsg(k, t, (1.0, 0.0, 0.0), ()), t)
        res = drv.tick(t, t)
        drv.after_tick()
        region = drv.region()
        if k < 100:
            assert res.mode == "waiting" and res.pose is None and region is None
            continue
        assert region is not None and not region["inside"] and region["outside_by"] > 0.2
        stale_at = 0.1 + RuntimeConfig().object_timeout
        if t > stale_at + 0.01:
            assert res.mode == "hold"
            held = held or res.pose
            assert res.pose == held
        elif 0.11 < t < stale_at - 0.01:
            assert res.mode == "running"
    assert held is not None and drv.counters.stale_object >= 1
