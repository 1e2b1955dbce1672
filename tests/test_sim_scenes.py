"""Task scenes (pure outcome logic) and the Simulation facade a service drives."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pinocchio as pin
import pytest
from can.interfaces import virtual as can_virtual

from sctd import se3
from sctd.task import TaskError, find_task, handle_jacobian, handle_pose
from sctd.task.judge import holds
from sctd.task.kinds import World
from sctd.task.kinds.contents import outlet_geometry, outlet_stream
from sctd.task.kinds.joint import joint_force
from sctd.task.model import Near
from sctd_sim.scenes import EmptyScene, TaskScene, make_scene
from sctd_sim.simulation import Simulation
from tests.oracles import HandleState, reference_handle_step

DT = 1e-3


@pytest.fixture(autouse=True)
def no_leaked_buses():
    before = set(can_virtual.channels)
    yield
    assert set(can_virtual.channels) == before


def rot_about(axis, angle):
    return se3.matrix_from_rotvec(np.asarray(axis, dtype=float) * angle)


TIP = "bottle_tip"


def ee_for_tip(scene, p_tip, tilt, tilt_axis=(1.0, 0.0, 0.0)):
    """ee pose that puts the bottle opening at p_tip, bottle tilted by tilt."""
    R_world_tip = rot_about(tilt_axis, tilt)
    T_world_tip = se3.transform_from_rt(R_world_tip, p_tip)
    return T_world_tip @ se3.invert_transform(scene.held.frames[TIP])


# -- pour -----------------------------------------------------------------------------
def mug_opening(scene, above=0.03, radial=(0.0, 0.0)):
    return scene.poses["mug"][:3, 3] + np.array([radial[0], radial[1], above])


def pour_scene() -> TaskScene:
    scene = make_scene(find_task("pour"))
    assert isinstance(scene, TaskScene)
    return scene


def test_start_pose_holds_the_bottle_upright():
    scene = pour_scene()
    T_tip = scene.objects(scene.start_pose())[TIP]
    mug = scene.task.scene.bodies["mug"].container
    g = outlet_geometry(T_tip, mug, se3.invert_transform(scene.poses["mug"]))
    assert g.tilt == pytest.approx(0.0, abs=1e-9)
    assert T_tip[2, 3] > scene.start_pose()[2, 3]  # the opening is above the hand


def test_geometry_over_the_opening_and_beside_it():
    scene = pour_scene()
    C, inv = scene.task.scene.bodies["mug"].container, se3.invert_transform(scene.poses["mug"])
    upright = se3.transform_from_rt(np.eye(3), mug_opening(scene))
    g = outlet_geometry(upright, C, inv)
    assert g.over_opening and g.radial == pytest.approx(0.0) and g.tilt == pytest.approx(0.0)
    assert g.above_rim == pytest.approx(0.03)
    beside = se3.transform_from_rt(np.eye(3), mug_opening(scene, radial=(0.05, 0.0)))
    assert not outlet_geometry(beside, C, inv).over_opening
    too_high = se3.transform_from_rt(np.eye(3), mug_opening(scene, above=0.5))
    assert not outlet_geometry(too_high, C, inv).over_opening
    below_rim = se3.transform_from_rt(np.eye(3), mug_opening(scene, above=-0.02))
    assert not outlet_geometry(below_rim, C, inv).over_opening


def test_flow_only_past_the_pouring_angle():
    c = pour_scene().task.scene.held.contents
    assert c.flow_angle == pytest.approx(math.radians(75.0))
    assert outlet_stream(c.flow_angle - 0.01, c) == 0.0
    assert outlet_stream(c.flow_angle + 0.3, c) > outlet_stream(c.flow_angle + 0.1, c) > 0.0
    assert outlet_stream(math.pi, c) <= c.flow_rate


def test_pouring_over_the_mug_fills_it_without_spilling():
    scene = pour_scene()
    T_ee = ee_for_tip(scene, mug_opening(scene), math.radians(110))
    for _ in range(2000):  # 0.6 sin(35 deg) of the bottle per second: about 0.69 poured
        scene.step(T_ee, np.zeros(6), DT)
    out = scene.outcome()
    assert out["over_opening"] and out["tilt"] == pytest.approx(math.radians(110))
    assert out["poured"] > out["fill_target"] == 0.5
    assert not out["spilled"]
    assert out["poured"] + out["remaining"] == pytest.approx(1.0)
    assert out["pouring"] and not out["done"] and not out["success"]  # judged once it stops
    upright = ee_for_tip(scene, mug_opening(scene), 0.0)
    scene.step(upright, np.zeros(6), DT)
    out = scene.outcome()
    assert out["done"] and out["success"] and out["readings"]["bottle.poured"] == out["poured"]
    assert out["progress"] == out["poured"] and out["thresholds"] == {"bottle.poured": 0.5}


def test_tilting_beside_the_mug_spills():
    scene = pour_scene()
    T_ee = ee_for_tip(scene, mug_opening(scene, radial=(0.1, 0.0)), math.radians(100))
    scene.step(T_ee, np.zeros(6), DT)
    out = scene.outcome()
    assert out["spilled"] and out["pouring"] and not out["success"]
    assert out["poured"] == 0.0 and out["readings"]["bottle.spilled"] > 0.0


def test_tilting_below_the_pouring_angle_does_nothing():
    scene = pour_scene()
    T_ee = ee_for_tip(scene, mug_opening(scene, radial=(0.2, 0.0)), math.radians(60))
    for _ in range(1000):
        scene.step(T_ee, np.zeros(6), DT)
    out = scene.outcome()
    assert not out["spilled"] and out["remaining"] == 1.0 and not out["pouring"]


def test_an_empty_bottle_stops_pouring_and_gets_lighter():
    scene = pour_scene()
    T_ee = ee_for_tip(scene, mug_opening(scene), math.radians(170))
    w_full = scene.step(T_ee, np.zeros(6), DT)
    for _ in range(200):
        w = scene.step(T_ee, np.zeros(6), 0.1)
    r = scene.readings()
    assert r["bottle.remaining"] == pytest.approx(0.0, abs=1e-12) and r["bottle.remaining"] >= 0.0
    assert r["bottle.poured"] == pytest.approx(1.0)
    assert w[2] == pytest.approx(-scene.held.mass * 9.81)
    assert w_full[2] == pytest.approx(-(scene.held.mass + scene.held.contents.mass) * 9.81, rel=1e-3)
    assert w_full[2] < w[2] < 0.0


def test_pour_objects():
    scene = pour_scene()
    T_ee = scene.start_pose()
    objs = scene.objects(T_ee)
    assert list(objs) == ["mug", TIP]
    np.testing.assert_allclose(objs[TIP], T_ee @ scene.held.frames[TIP])
    assert scene.task_object == "mug"


def test_a_held_frame_is_judged_where_the_turned_hand_holds_it():
    """The scene's predicates (a ``near`` on a held frame) see the frame where the hand
    holds it, turned with the hand: a bottle tilted on its side has its opening beside
    the hand, not above it."""
    scene = pour_scene()
    T_ee = ee_for_tip(scene, mug_opening(scene, above=0.05), math.pi / 2)
    scene.step(T_ee, np.zeros(6), DT)
    tip = scene.positions()[TIP]
    np.testing.assert_allclose(tip, mug_opening(scene, above=0.05), atol=1e-12)
    assert np.linalg.norm(tip - (T_ee[:3, 3] + [0.0, 0.0, 0.12])) > 0.1  # not above the hand
    assert holds(Near(TIP, "mug", 0.06), {}, scene.positions())


# -- drawer ---------------------------------------------------------------------------
def ee_at(p):
    return se3.transform_from_rt(np.eye(3), p)


def drawer_scene(**joint) -> TaskScene:
    scene = make_scene(find_task("drawer"))
    if joint:  # the same task with other joint parameters
        task = scene.task
        j = dataclasses.replace(task.scene.joints["drawer"], **joint)
        sc = dataclasses.replace(task.scene, sections={**task.scene.sections, "joints": {"drawer": j}})
        scene = make_scene(dataclasses.replace(task, scene=sc))
    assert isinstance(scene, TaskScene)
    return scene


def handle_now(scene):
    return scene.handles[0].handle_transform(scene.poses["drawer_handle"])


def test_drawer_is_grasped_only_within_the_grasp_radius():
    scene = drawer_scene()
    p_handle = handle_now(scene)[:3, 3]
    w = scene.step(ee_at(p_handle + np.array([0, 0, 0.05])), np.zeros(6), DT)
    assert not scene.handles[0].attached and not w.any()
    scene.step(ee_at(p_handle + np.array([0, 0, 0.01])), np.zeros(6), DT)
    assert scene.handles[0].attached and scene.outcome()["grasps"] == 1
    assert scene.outcome()["readings"]["drawer.held"] is True


def test_pulling_the_handle_opens_the_drawer_against_its_resistance():
    scene = drawer_scene()
    joint = scene.handles[0]
    axis = scene.poses["drawer_handle"][:3, 0]
    p = handle_now(scene)[:3, 3].copy()
    v = 0.1 * axis
    forces = []
    for _ in range(2200):  # pull at 0.1 m/s for 2.2 s
        p = p + v * DT
        w = scene.step(ee_at(p), np.concatenate([v, np.zeros(3)]), DT)
        forces.append(w[:3] @ axis)
    out = scene.outcome()
    assert out["attached"]
    assert out["opening"] == pytest.approx(0.22, abs=0.01)
    assert out["success"] and out["done"] and out["target_opening"] == 0.2
    # the drawer pulls back on the hand: spring + damping + friction
    expected = joint_force(joint.position, 0.1, joint.joint)
    assert forces[-1] == pytest.approx(expected, rel=0.1)
    assert all(f <= 0.0 for f in forces[100:])


def test_drawer_stops_at_its_end_and_the_grasp_slips_if_pulled_further():
    scene = drawer_scene(travel=0.1)
    axis = scene.poses["drawer_handle"][:3, 0]
    p = handle_now(scene)[:3, 3].copy()
    for _ in range(3000):
        p = p + 0.1 * axis * DT
        scene.step(ee_at(p), np.concatenate([0.1 * axis, np.zeros(3)]), DT)
    assert not scene.handles[0].attached
    assert scene.outcome()["max_opening"] == pytest.approx(0.1)
    assert scene.handles[0].position < 0.1  # released: the soft-close spring pulls it back


def test_released_drawer_closes_by_its_soft_close_spring():
    scene = drawer_scene()
    scene.handles[0].position = 0.1
    for _ in range(5000):
        scene.step(ee_at([0.0, 0.0, 0.0]), np.zeros(6), DT)
    assert scene.handles[0].position < 0.1
    assert scene.handles[0].position >= 0.0


def test_make_scene():
    assert make_scene(find_task("pour")).task_object == "mug"
    assert make_scene(find_task("drawer")).task_object == "drawer_handle"
    assert EmptyScene().objects(np.eye(4)) == {}
    with pytest.raises(TaskError, match="juggle: no such file, and no task of that name"):
        make_scene(find_task("juggle"))


def test_a_seeded_start_moves_what_the_file_says_and_nothing_else():
    """``vary``: the hand within 10 cm per axis and 15 deg of yaw, the mug within 5 cm
    on the table (never up or down); the same seed, the same start."""
    for seed in range(20):
        a, b = make_scene(find_task("pour"), trial_seed=seed), make_scene(find_task("pour"), trial_seed=seed)
        np.testing.assert_array_equal(a.start_pose(), b.start_pose())
        d = a.start_pose()[:3, 3] - a.default_start_pose[:3, 3]
        assert np.all(np.abs(d) <= 0.10) and abs(a.start_yaw) <= math.radians(15.0)
        shift = a.poses["mug"][:3, 3] - a.task.scene.bodies["mug"].T_world[:3, 3]
        assert np.all(np.abs(shift[:2]) <= 0.05) and shift[2] == 0.0


# -- the Simulation facade ------------------------------------------------------------
def test_simulation_messages_are_plain_data():
    with Simulation(find_task("pour")) as sim:
        sim.run(0.02)
        msg = sim.state_message()
        assert set(msg) == {"pose", "q", "dq", "wrench", "gripper"}
        assert [len(msg[k]) for k in ("pose", "q", "dq", "wrench")] == [7, 7, 7, 6]
        g = msg["gripper"]  # (the fingers, open: no command taken)
        assert g.width == 0.08 and g.grasped is False and g.moving is False and g.cmd == -1
        assert all(isinstance(x, float) for x in msg["pose"])
        # bus-decoded measurement agrees with the physics to the frame resolution
        np.testing.assert_allclose(msg["pose"][:3], sim.arm.ee_pose[:3], atol=1e-4)
        objs = sim.objects()
        assert set(objs) == {"mug", "bottle_tip"} and all(len(p) == 7 for p in objs.values())
        T_world_tip = se3.transform_from_pose(objs["bottle_tip"])
        T_world_ee = se3.transform_from_pose(msg["pose"])
        np.testing.assert_allclose(se3.invert_transform(T_world_ee) @ T_world_tip,
                                   sim.scene.held.frames["bottle_tip"], atol=1e-3)
        out = sim.scene_outcome()
        assert out["scene"] == "pour" and out["t"] == pytest.approx(0.02)
        assert not out["spilled"]
        assert msg["wrench"][2] < 0.0  # the bottle's weight


def test_state_message_pose_is_the_forward_kinematics_of_the_decoded_joints():
    """The reported pose is the controller's kinematics of what crossed the bus (shared
    with its next update): Pinocchio's forward kinematics of the decoded q, bit for bit."""
    with Simulation(find_task("pour")) as sim:
        model = sim.arm.arm
        data = model.model.createData()
        for _ in range(3):
            sim.run(0.01)
            q = np.array(sim.state_message()["q"])
            pin.framesForwardKinematics(model.model, data, q)
            T = data.oMf[model.ee_frame_id].homogeneous
            assert sim.state_message()["pose"] == se3.pose_from_flat(se3.flat_from_transform(T))


def test_simulation_ignores_invalid_targets():
    with Simulation(EmptyScene()) as sim:
        sim.step()
        sim.set_target([float("nan")] * 7)
        sim.set_target([0.0] * 7)
        sim.set_target([1.0, 2.0])
        assert sim.arm.controller.holding


def test_simulation_follows_targets_and_opens_the_drawer():
    with Simulation(find_task("drawer")) as sim:
        p0 = np.array(sim.state_message()["pose"])
        handle = np.array(sim.objects()["drawer_handle"])
        T_handle_ee = (se3.invert_transform(se3.transform_from_pose(handle))
                       @ se3.transform_from_pose(p0))
        np.testing.assert_allclose(T_handle_ee[:3, :3], np.eye(3), atol=1e-3)
        axis = sim.scene.poses["drawer_handle"][:3, 0]
        for k in range(700):  # reach for the handle
            a = min(1.0, k / 500)
            target = p0.copy()
            target[:3] = (1 - a) * p0[:3] + a * handle[:3]
            sim.set_target(target, stamp=sim.t)
            sim.step()
        assert sim.scene_outcome()["attached"]
        for k in range(1500):  # pull 0.25 m in 1.2 s
            a = min(1.0, k / 1200)
            target = p0.copy()
            target[:3] = handle[:3] + a * 0.25 * axis
            sim.set_target(target, stamp=sim.t)
            sim.step()
        out = sim.scene_outcome()
        assert out["success"] and out["opening"] > 0.2
        assert np.array(sim.state_message()["wrench"])[:3] @ axis < 0.0
        # the published handle frame stays at the closed position (as in the demos)
        np.testing.assert_allclose(sim.objects()["drawer_handle"], handle)


# -- cabinet: a door on a revolute joint ------------------------------------------------
def cabinet_scene(**joint) -> TaskScene:
    scene = make_scene(find_task("cabinet"))
    if joint:  # the same task with other joint parameters
        task = scene.task
        door = dataclasses.replace(task.scene.joints["door"], **joint)
        sc = dataclasses.replace(task.scene, sections={**task.scene.sections, "joints": {"door": door}})
        scene = make_scene(dataclasses.replace(task, scene=sc))
    assert isinstance(scene, TaskScene)
    return scene


def swing(scene, q_of_t, seconds):
    """The hand on the handle's arc at the angle ``q_of_t(t)`` (its twist the arc's);
    returns the forces on the hand."""
    joint, T0 = scene.task.scene.joints["door"], scene.poses["door_handle"]
    forces = []
    for k in range(round(seconds / DT)):
        q, q_next = q_of_t(k * DT), q_of_t((k + 1) * DT)
        v = handle_jacobian(joint, T0, q) * (q_next - q) / DT
        w = scene.step(ee_at(handle_pose(joint, T0, q)[:3, 3]), np.concatenate([v, np.zeros(3)]), DT)
        forces.append(w[:3])
    return forces


def test_the_door_is_grasped_where_its_handle_is_now():
    scene = cabinet_scene()
    door = scene.handles[0]
    door.position = 0.8
    T0 = scene.poses["door_handle"]
    scene.step(ee_at(T0[:3, 3]), np.zeros(6), DT)  # where the handle is with the door closed
    assert not door.attached
    now = door.handle_transform(T0)
    np.testing.assert_allclose(now, handle_pose(scene.task.scene.joints["door"], T0, door.position))
    scene.step(ee_at(now[:3, 3] + [0.0, 0.0, 0.01]), np.zeros(6), DT)
    assert door.attached and scene.outcome()["grasps"] == 1 and scene.readings()["door.held"] is True


def test_pulling_the_handle_along_its_arc_opens_the_door():
    """At 0.5 rad/s along the arc for 2.4 s: 1.2 rad open, done; the torque about the
    hinge of the force the hand puts on the handle is the door's resistance."""
    scene = cabinet_scene()
    joint, T0 = scene.task.scene.joints["door"], scene.poses["door_handle"]
    forces = swing(scene, lambda t: 0.5 * t, 2.4)
    out = scene.outcome()
    assert out["attached"] and out["done"] and out["success"]
    assert out["opening"] == pytest.approx(1.2, abs=0.01)
    assert out["readings"]["door.position"] == out["opening"]  # (rad)
    assert out["target_opening"] == math.radians(65.0) and out["open_fraction"] < 1.0
    hinge, axis = (T0 @ [*joint.hinge.point, 1.0])[:3], T0[:3, :3] @ joint.hinge.axis
    p = handle_pose(joint, T0, scene.handles[0].position)[:3, 3]
    torque = float(np.cross(p - hinge, -forces[-1]) @ axis)  # on the door, about its hinge
    assert torque == pytest.approx(-joint_force(scene.handles[0].position, 0.5, joint), rel=0.05)
    tangent = handle_jacobian(joint, T0, scene.handles[0].position)
    assert all(f @ tangent < 0.0 for f in forces[100:])  # the door holds the hand back
    np.testing.assert_array_equal(scene.objects(np.eye(4))["door_handle"], T0)  # published at 0


def test_pulling_straight_out_opens_the_door_only_partly():
    """The hand pulled straight out of the closed door (along the handle's x) takes the
    handle some 25 deg round its arc, then loses it: the task's failure."""
    scene = cabinet_scene()
    T0 = scene.poses["door_handle"]
    for k in range(4000):
        v = 0.1 * T0[:3, 0]
        scene.step(ee_at(T0[:3, 3] + v * k * DT), np.concatenate([v, np.zeros(3)]), DT)
    out = scene.outcome()
    assert not out["attached"] and out["grasps"] == 1 and not out["done"]
    assert math.radians(15.0) < out["max_opening"] < math.radians(35.0), math.degrees(out["max_opening"])
    lost = scene.task.outcome.fail[0]
    assert lost.reason == "handle lost while opening" and holds(lost.when, out["readings"], {})


def push(scene, force, seconds):
    """A constant force (N) on the handle along its arc: the hand held ``force / k`` ahead
    of it, moving with it."""
    joint, T0, door = scene.task.scene.joints["door"], scene.poses["door_handle"], scene.handles[0]
    door.attached = True
    lead = force / joint.grasp.stiffness
    for _ in range(round(seconds / DT)):
        J = handle_jacobian(joint, T0, door.position)
        p = handle_pose(joint, T0, door.position)[:3, 3] + lead * J / np.linalg.norm(J)
        scene.step(ee_at(p), np.concatenate([door.speed * J, np.zeros(3)]), DT)
    return door.position


def test_friction_holds_the_door_below_its_breakaway_force():
    """Friction 0.3 N m at a 0.321 m lever: 0.93 N at the handle. Half of it turns the
    door by less than 2 deg in 2 s (the tanh friction's creep); three times it swings
    the door open."""
    joint = make_scene(find_task("cabinet")).task.scene.joints["door"]
    breakaway = joint.friction / joint.hinge.lever
    assert push(cabinet_scene(), 0.5 * breakaway, 2.0) < math.radians(2.0)
    assert push(cabinet_scene(spring=0.0), 0.5 * breakaway, 2.0) < math.radians(2.0)
    assert push(cabinet_scene(), 3.0 * breakaway, 2.0) > math.radians(40.0)


def test_the_door_stops_at_its_end_stop_and_the_grasp_slips():
    scene = cabinet_scene()
    travel = scene.task.scene.joints["door"].travel
    swing(scene, lambda t: 0.5 * t, 5.0)  # 2.5 rad along the arc: 0.8 rad past the stop
    out = scene.outcome()
    assert out["max_opening"] == travel and not out["attached"]
    assert scene.handles[0].position < travel  # let go: its soft-close spring turns it back


@pytest.mark.parametrize("task", ["drawer", "cabinet"])
def test_a_handle_steps_as_its_equations_say(task):
    """The scene's float arithmetic against the equations on 3-vectors (tests/oracles.py),
    along a hand path that grasps, pulls, wobbles and lets go: a prismatic joint's numbers
    to the bit (as before the revolute joint came), a revolute joint's to rounding."""
    scene = make_scene(find_task(task))
    joint = next(iter(scene.task.scene.joints.values()))
    T0 = scene.poses[joint.handle]
    element, ref = scene.handles[0], HandleState()
    rng = np.random.default_rng(7)
    p = T0[:3, 3] + [0.0, 0.0, 0.05]
    for k in range(5000):
        v = (0.1 * T0[:3, 0] if k > 500 else np.array([0.0, 0.0, -0.1])) + rng.normal(0.0, 0.02, 3)
        p = p + v * DT
        T, twist = ee_at(p), np.concatenate([v, rng.normal(0.0, 0.1, 3)])
        f_ref = reference_handle_step(joint, ref, T, twist, T0, DT)
        f = element.step(World(T, twist, {joint.handle: T0}), DT)[:3]
        if task == "drawer":
            assert (element.position, element.speed) == (ref.position, ref.speed)
            assert element.attached == ref.attached
            np.testing.assert_array_equal(f, f_ref)
        else:
            assert element.attached == ref.attached
            assert element.position == pytest.approx(ref.position, abs=1e-9)
            np.testing.assert_allclose(f, f_ref, atol=1e-6)
    assert ref.grasps == element.grasps == 1 and not ref.attached and ref.position > 0.0
