"""What a skill looks like (sctd.skill.sketch, sctd_services.view.skill_scene): each
element's shapes say what the element does, the arrows of an input axis are what the
mapping does, and the demonstrations are coloured by the state the skill's FSM is in."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sctd import se3
from sctd.learn.demos import read_demos, spike_mask
from sctd.skill import (
    CONSTRAINTS,
    FIELDS,
    TRANSITIONS,
    Band,
    Box,
    CylinderField,
    Distance,
    Hyperplane,
    SpeedNear,
    SphereField,
    TiltCone,
    load_skill,
)
from sctd.skill.catalog import shipped_folder
from sctd.skill.fields import PointField
from sctd.skill.sketch import Arrow, Cone, Cuboid, Dots, Line, Plane, Shape, Sphere, direction_words
from sctd.skill.workspace import Workspace
from sctd_services.view.skill_scene import axis_effects, demo_states, field_arrows, skill_scene

SKILLS = shipped_folder()
G0 = se3.flat_from_transform(se3.transform_from_pose([0.1, -0.2, 0.3, 0.0, 0.0, 0.0, 1.0]))


def test_a_tilt_cone_is_its_cone_at_the_frames_origin():
    c = TiltCone(frame="tip", axis=np.array([0.0, 0.0, 1.0]), reference=np.array([0.0, 0.6, 0.8]),
                 max_angle=0.4)
    (cone,) = c.sketch(G0)
    assert isinstance(cone, Cone)
    assert np.allclose(cone.apex, G0[9:]) and np.allclose(cone.axis, [0.0, 0.6, 0.8])
    assert cone.angle == 0.4 and "23 deg" in cone.label


def test_a_band_is_its_two_bounds_under_and_over_the_frame():
    n = np.array([0.0, 0.0, 1.0])
    b = Band(frame="tip", normal=n, point=np.array([0.0, 0.0, 0.05]), lower=0.03, upper=0.6)
    lo, hi = b.sketch(G0)
    assert isinstance(lo, Plane) and isinstance(hi, Plane)
    assert np.allclose(lo.point, [0.1, -0.2, 0.08]) and np.allclose(hi.point, [0.1, -0.2, 0.65])
    assert np.allclose(lo.normal, n)


def test_a_box_a_cap_and_the_guards_are_their_regions():
    (box,) = Box(lower=np.array([-0.01, -0.02, 0.0]), upper=np.array([0.3, 0.02, 0.05])).sketch(G0)
    assert isinstance(box, Cuboid) and np.allclose(box.upper, [0.3, 0.02, 0.05])
    (zone,) = SpeedNear(within=0.1, max_linear_speed=0.03, max_angular_speed=0.3).sketch(G0)
    assert isinstance(zone, Sphere) and zone.radius == 0.1 and not np.any(zone.centre)
    (guard,) = Distance(source="a", target="b", frame="tip", point=np.array([0.0, 0.0, 0.06]),
                        threshold=0.03).sketch()
    assert isinstance(guard, Sphere) and guard.radius == 0.03 and "within 0.03 m" in guard.label
    assert "a -> b" in guard.label
    n = np.array([0.6, 0.0, 0.8])
    plane, arrow = Hyperplane(source="a", target="b", normal=n, offset=-0.05).sketch()
    assert isinstance(plane, Plane) and isinstance(arrow, Arrow)
    assert math.isclose(float(n @ plane.point) - 0.05, 0.0, abs_tol=1e-12)  # on the plane
    assert np.allclose(arrow.vector / np.linalg.norm(arrow.vector), n)  # towards where it fires


def test_fields_show_their_fitted_parameters_where_their_points_lie():
    pts = np.array([[0.1, 0.0, 0.2], [0.1, 0.05, 0.3]])
    (axis,) = CylinderField(point=np.array([0.0, 0.0, 0.0]), axis=np.array([0.0, 0.0, 1.0])).sketch(pts)
    assert isinstance(axis, Line) and np.allclose((axis.a + axis.b) / 2, [0.0, 0.0, 0.25])
    centre, sphere = SphereField(centre=np.array([0.0, 0.0, 0.1]), radius=0.12).sketch(pts)
    assert isinstance(centre, Dots) and np.allclose(centre.points, [[0.0, 0.0, 0.1]])
    assert isinstance(sphere, Sphere) and sphere.radius == 0.12
    (goal,) = PointField(point=np.array([0.0, 0.1, 0.0])).sketch(pts)
    assert np.allclose(goal.points, [[0.0, 0.1, 0.0]])


@pytest.mark.parametrize("registry", [CONSTRAINTS, TRANSITIONS, FIELDS], ids=lambda r: r.kind)
def test_every_kind_says_how_it_looks(registry):
    """A kind added to a registry has a sketch (possibly no shape): the view never meets
    an element it cannot draw."""
    for name in registry.names():
        assert callable(getattr(registry[name], "sketch", None)), name


def test_direction_words():
    assert direction_words([0.0, 0.0, -2.0]) == "-z"
    assert direction_words([1.0, 0.0, 1.0]) == "(0.71, 0.00, 0.71)"
    assert direction_words([0.0, 0.0, 0.0]) == "nowhere"


def test_an_axis_does_what_the_skill_file_says():
    """The hand-written pour's approach maps axis 3 to -0.5 tz + 1 ry on the tip: at the
    skill's limits (0.1 m/s, 0.35 rad/s) the tip goes down at 0.05 m/s while turning
    about +y at 0.35 rad/s; axes 1 and 2 move it along x and y at 0.1 m/s."""
    skill = load_skill(SKILLS / "pour.yaml")
    ws = Workspace(skill.limits.speeds, skill.frames, skill.models())
    approach = skill.states[skill.state_index("approach")]
    F = se3.flat_from_transform(se3.transform_from_pose([0.02, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]))
    e1, e2, e3 = axis_effects(approach.input_mappings[0], F, ws)
    assert np.allclose(e1.velocity, [0.1, 0.0, 0.0], atol=1e-9) and np.allclose(e1.turn, 0.0, atol=1e-9)
    assert np.allclose(e2.velocity, [0.0, 0.1, 0.0], atol=1e-9)
    assert np.allclose(e3.velocity, [0.0, 0.0, -0.05], atol=1e-6)
    assert np.allclose(e3.turn, [0.0, 0.35, 0.0], atol=1e-6)
    assert np.allclose(e3.origin, [0.02, 0.0, 0.12])  # drawn at the tip
    assert e3.words("mug") == "axis 3: moves tip along mug -z at 0.05 m/s, turns about mug +y at 0.35 rad/s"


def test_demonstrations_take_the_states_the_fsm_gives_them():
    """Each sample's state is where the skill's own engine is: in the learned linear
    pour, from s0, a state changes exactly at a sample where a guard out of it fires
    (by its margin), and never while one fires after the dwell; the pour's demonstrations
    cross the learned plane into s1, and some back as the bottle comes upright."""
    skill = load_skill(SKILLS / "pour-linear.yaml")
    ws = Workspace(skill.limits.speeds, skill.frames, skill.models())
    names = [st.name for st in skill.states]
    changes = 0
    for demo in read_demos(SKILLS / "demos" / "pour")[:4]:
        states = demo_states(skill, demo)
        assert states[0] == 0 and np.any(states == 1)
        entered = demo.t[0]
        for k in range(1, len(demo)):
            F = se3.flat_from_pose(demo.poses[k].tolist())
            out = [t for t in skill.transitions if t.source == names[states[k - 1]]]
            firing = [t for t in out if t.fires(F, demo.t[k] - entered, None, ws)]
            if states[k] != states[k - 1]:
                assert names[states[k]] in [t.target for t in firing]
                entered, changes = demo.t[k], changes + 1
            elif demo.t[k] - entered >= skill.min_dwell:
                assert not firing
    assert changes >= 4


def test_each_state_is_shown_where_the_demonstrations_are_in_it():
    skill = load_skill(SKILLS / "pour-linear.yaml")
    demos = read_demos(SKILLS / "demos" / "pour")
    scene = skill_scene(skill, demos)
    for i, st in enumerate(scene.states):
        in_state = np.concatenate([d.points[d.states == i] for d in scene.demos])
        assert np.min(np.linalg.norm(in_state - st.T_obj_ee[:3, 3], axis=1)) < 1e-12
        assert st.effects and all(isinstance(s, Shape) for _, s in st.shapes)
    # the learner's outliers are set apart, every sample is one or the other
    assert [len(d.points) + len(d.spikes) for d in scene.demos] == [len(d) for d in demos]
    assert all(0 < len(d.spikes) < 0.2 * len(d.points) for d in scene.demos)  # the shipped demos have spikes
    for d, raw in zip(scene.demos, demos, strict=True):
        keep = spike_mask(raw.poses)
        assert np.array_equal(d.points, raw.poses[keep, :3])
        assert np.array_equal(d.spikes, raw.poses[~keep, :3])
        assert np.linalg.norm(np.diff(d.points, axis=0), axis=1).max() < 0.02  # no 10 cm jumps left


def test_a_hand_written_skill_shows_a_state_where_its_guard_leads_in():
    """Without demonstrations, the drawer's pull is shown where the grasp guard fires:
    the hand at the handle."""
    scene = skill_scene(load_skill(SKILLS / "drawer.yaml"))
    pull = next(st for st in scene.states if st.name == "pull")
    assert np.allclose(pull.T_obj_ee[:3, 3], 0.0)
    assert any(isinstance(s, Cuboid) for _, s in pull.shapes)


def test_a_fields_arrows_lie_near_its_points_and_follow_it():
    skill = load_skill(SKILLS / "drawer-vf.yaml")
    (mapping,) = skill.states[0].input_mappings
    (_, model), = mapping.models()
    owner = np.argmax(model.responsibilities, axis=1)
    for k, f in enumerate(model.fields):
        mine = model.points[owner == k]
        fa = field_arrows("f", k, f, mine)
        assert len(fa.points) > 5
        d = np.linalg.norm(fa.points[:, None, :] - mine[None, :, :], axis=2).min(axis=1)
        assert np.all(d < 0.04)
        assert np.allclose(fa.vectors, f.vectors(fa.points))
        assert np.allclose(np.linalg.norm(fa.vectors, axis=1), 1.0)
