"""Another arm's URDF in the simulator (``sctd sim --urdf FILE --ee-frame NAME``): the
loader's checks, its forward kinematics against MuJoCo on franky-sim's own model of the
Franka FR3, and a simulation of a task on that arm (``docs/sim-urdf.md``)."""

from __future__ import annotations

import argparse
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from sctd import se3
from sctd.task import find_task
from sctd_sim import service
from sctd_sim.canbus import joint_bus_ranges
from sctd_sim.options import add_service_arguments
from sctd_sim.robot import (
    ARMATURE,
    EE_FRAME,
    FORWARD_POSTURE,
    REST_POSTURE,
    UP_POSTURE,
    URDF_PATH,
    ArmModelError,
    load_arm_model,
)
from sctd_sim.scenes import make_scene
from sctd_sim.simulation import Simulation, start_posture

FR3_TCP = "fr3_hand_tcp"  # the URDF's tool centre point: 0.1034 m along the hand's z
FK_SAMPLES = 200


@pytest.fixture(scope="module")
def assets() -> Path:
    """franky-sim's assets folder: fr3.urdf (with hand), fr3_clean.urdf, fr3.xml."""
    franky_sim = pytest.importorskip("franky_sim")
    return Path(franky_sim.__file__).parent / "assets"


@pytest.fixture(scope="module")
def fr3(assets):
    return load_arm_model(assets / "fr3.urdf", FR3_TCP)


def urdf_masses(path: Path) -> float:
    return sum(float(m.get("value")) for m in ET.parse(path).getroot().iter("mass"))


# -- loading -----------------------------------------------------------------------------


def test_the_fr3_loads_as_its_seven_arm_joints_with_the_fingers_locked(assets, fr3):
    root = ET.parse(assets / "fr3.urdf").getroot()
    limits = {j.get("name"): j.find("limit") for j in root.iter("joint")}
    assert fr3.joint_names == [f"fr3_joint{i}" for i in range(1, 8)]
    assert fr3.ee_frame == FR3_TCP and fr3.urdf_path == assets / "fr3.urdf"
    for i, name in enumerate(fr3.joint_names):
        lim = limits[name]
        assert (fr3.q_lower[i], fr3.q_upper[i]) == (float(lim.get("lower")), float(lim.get("upper")))
        assert (fr3.dq_max[i], fr3.tau_max[i]) == (float(lim.get("velocity")), float(lim.get("effort")))
    # the fingers' (and every other link's) mass stays on the arm: about 18.6 kg
    assert sum(i.mass for i in fr3.model.inertias) == pytest.approx(urdf_masses(assets / "fr3.urdf"))
    np.testing.assert_array_equal(fr3.model.armature, ARMATURE)
    np.testing.assert_allclose(fr3.rest, 0.5 * (fr3.q_lower + fr3.q_upper))
    assert not fr3.seeds_tuned and len(fr3.seeds) == 1


def test_the_fr3_without_a_hand_loads_to_its_flange(assets):
    arm = load_arm_model(assets / "fr3_clean.urdf", "link8")
    assert arm.joint_names == [f"joint{i}" for i in range(1, 8)]


def test_the_shipped_arm_keeps_its_tuned_postures():
    arm = load_arm_model()
    assert arm.urdf_path == URDF_PATH and arm.ee_frame == EE_FRAME and arm.seeds_tuned
    for seed, posture in zip(arm.seeds, (UP_POSTURE, REST_POSTURE, FORWARD_POSTURE), strict=True):
        np.testing.assert_array_equal(seed, posture)
    assert load_arm_model(URDF_PATH, "flange").nq == 7  # another frame of the same chain


# -- forward kinematics against MuJoCo on franky-sim's own model -------------------------


@pytest.fixture(scope="module")
def mujoco(assets):
    """MuJoCo, imported without an OpenGL context: the kinematics need none, and looking
    for GLFW's library starts a process (which the fast tier refuses)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("MUJOCO_GL", "disable")
        return pytest.importorskip("mujoco")


@pytest.fixture(scope="module")
def mujoco_fr3(mujoco):
    """franky-sim's MuJoCo model of the FR3 as its simulator builds it (``fr3.xml`` under
    the prefix ``robot0_``, base at the world origin, meshes from its folder), with a
    site at franky-sim's tool centre point in the ``hand`` body; its arm joints' qpos
    addresses by name, in franky-sim's order (``fr3_joint1`` .. ``fr3_joint7``), and
    their ranges."""
    from franky_sim import RobotParameters
    from franky_sim.mujoco_simulator import MujocoSimulator

    sim = MujocoSimulator()
    sim.add_robot()  # position (0, 0, 0)
    hand = next(b for b in sim.worldbody.iter("body") if b.get("name") == "robot0_hand")
    tcp = RobotParameters().ee_tcp_xyz  # (0, 0, 0.1034): the URDF's fr3_hand_tcp_joint
    ET.SubElement(hand, "site", name="robot0_tcp", pos=" ".join(map(repr, tcp)))
    model = mujoco.MjModel.from_xml_string(ET.tostring(sim.scene, encoding="unicode"))
    names = [f"robot0_fr3_joint{i}" for i in range(1, 8)]
    joints = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, n) for n in names]
    return model, [int(model.jnt_qposadr[j]) for j in joints], [model.jnt_range[j] for j in joints]


def test_the_hand_pose_from_pinocchio_is_mujocos_on_franky_sims_model(fr3, mujoco, mujoco_fr3):
    model, qpos, ranges = mujoco_fr3
    data = mujoco.MjData(model)
    hand = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "robot0_hand")
    tcp = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, "robot0_tcp")
    pdata = fr3.model.createData()
    hand_frame = fr3.model.getFrameId("fr3_hand")
    # within both models' limits (fr3.xml's are the narrower ones)
    low = np.maximum(fr3.q_lower, [r[0] for r in ranges])
    high = np.minimum(fr3.q_upper, [r[1] for r in ranges])
    rng = np.random.default_rng(20240607)
    worst = {"hand": [0.0, 0.0], "tcp": [0.0, 0.0]}
    for _ in range(FK_SAMPLES):
        q = rng.uniform(low, high)
        data.qpos[qpos] = q
        mujoco.mj_kinematics(model, data)
        pin.framesForwardKinematics(fr3.model, pdata, q)
        pairs = {"hand": (pdata.oMf[hand_frame], data.xpos[hand], data.xmat[hand]),
                 "tcp": (pdata.oMf[fr3.ee_frame_id], data.site_xpos[tcp], data.site_xmat[tcp])}
        for name, (oMf, p, R) in pairs.items():
            worst[name][0] = max(worst[name][0], float(np.linalg.norm(oMf.translation - p)))
            angle = np.linalg.norm(pin.log3(oMf.rotation.T @ np.reshape(R, (3, 3))))
            worst[name][1] = max(worst[name][1], float(angle))
    print(f"\nFR3 forward kinematics over {FK_SAMPLES} postures, Pinocchio (sctd_sim) - MuJoCo (franky-sim): "
          + "; ".join(f"{k} max {p:.1e} m, {a:.1e} rad" for k, (p, a) in worst.items()))
    for name, (position, angle) in worst.items():
        assert position < 1e-6, (name, position)
        assert angle < 1e-6, (name, angle)  # fr3.xml's hand quaternion has 7 digits: ~1e-7 rad


def test_the_tool_centre_point_is_franky_sims_own(fr3, mujoco):
    """franky-sim reports O_T_EE from fr3_clean.urdf's flange and its RobotParameters' TCP
    (rpy 0 0 -pi/4, xyz 0 0 0.1034): the same frame as fr3.urdf's fr3_hand_tcp."""
    from franky_sim.mujoco_simulator import FrankaMujocoRobot  # (it imports mujoco)

    robot = FrankaMujocoRobot()
    data = fr3.model.createData()
    rng = np.random.default_rng(7)
    for _ in range(50):
        q = rng.uniform(fr3.q_lower, fr3.q_upper)
        pin.framesForwardKinematics(fr3.model, data, q)
        theirs = robot.kinematics(q)
        np.testing.assert_allclose(data.oMf[fr3.ee_frame_id].homogeneous, theirs.homogeneous, atol=1e-12)


# -- a task on the FR3 -------------------------------------------------------------------


def test_the_fr3_starts_at_the_pour_start_away_from_its_limits_and_holds_still(fr3):
    task = find_task("pour")
    start = make_scene(task).start_pose()
    with Simulation(task, arm=fr3) as sim:
        np.testing.assert_allclose(sim.arm.T_world_ee, start, atol=1e-5)
        q = sim.arm.q
        margin = np.minimum(q - fr3.q_lower, fr3.q_upper - q) / (fr3.q_upper - fr3.q_lower)
        assert margin.min() > 0.05, margin  # the posture furthest from the limits (0.15)
        T0 = sim.arm.T_world_ee.copy()
        sim.run(1.0)  # no target: the controller holds where the arm is, the bottle full
        T1 = sim.arm.T_world_ee
        assert np.linalg.norm(T1[:3, 3] - T0[:3, 3]) < 2e-5  # measured 3e-6 m
        assert np.linalg.norm(pin.log3(T0[:3, :3].T @ T1[:3, :3])) < 1e-4
        assert sim.scene_outcome()["holding"]
        assert len(sim.state_message()["q"]) == 7


def test_the_fr3_follows_a_target_in_the_pour_scene(fr3):
    with Simulation(find_task("pour"), arm=fr3) as sim:
        T = sim.arm.T_world_ee.copy()
        T[:3, 3] += [0.03, -0.02, 0.03]
        T[:3, :3] = T[:3, :3] @ pin.exp3(np.array([0.3, 0.0, 0.0]))  # tilt the bottle
        for k in range(1500):
            if k % 10 == 0:  # a target at 100 Hz
                sim.set_target(se3.pose_from_transform(T).tolist(), sim.t)
            sim.step()
        reached = sim.arm.T_world_ee
        assert np.linalg.norm(reached[:3, 3] - T[:3, 3]) < 1e-3
        assert np.linalg.norm(pin.log3(T[:3, :3].T @ reached[:3, :3])) < 5e-3
        assert not sim.arm.dynamics.at_limit.any()
        assert sim.link_stats()["brake_events"] == 0


def test_a_start_the_arm_cannot_reach_says_so(fr3):
    far = np.eye(4)
    far[:3, 3] = [2.0, 0.0, 0.5]
    with pytest.raises(RuntimeError, match=r"out of reach of the arm of fr3\.urdf \(frame 'fr3_hand_tcp'\)"):
        start_posture(fr3, far)


# -- the flags and the loader's errors ---------------------------------------------------


def sim_args(*argv: str) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_service_arguments(p)
    return p.parse_args(["--task", "pour", *argv])


def edan_variant(tmp_path: Path, name: str, *edits: tuple[str, str]) -> Path:
    """The shipped URDF with each ``(pattern, replacement)`` applied once."""
    text = URDF_PATH.read_text()
    for pattern, replacement in edits:
        text, n = re.subn(pattern, replacement, text, count=1)
        assert n == 1, pattern
    path = tmp_path / f"{name}.urdf"
    path.write_text(text)
    return path


VARIANTS = {  # name: (edits, the error's end)
    "continuous": ([(r'name="joint_7" type="revolute"', 'name="joint_7" type="continuous"')],
                   r"joint 'joint_7' is continuous \(no position limits\); the simulator drives 7 revolute"),
    "prismatic": ([(r'name="joint_7" type="revolute"', 'name="joint_7" type="prismatic"')],
                  r"joint 'joint_7' is prismatic"),
    "effort": ([(r'velocity="1.710423" effort="176"', 'velocity="1.710423" effort="300"')],
               r"joint 'joint_1': effort limits \[-300, 300\] N m exceed what the joint bus carries "
               r"\(\[-204.8, 204.7\]"),
    "position": ([(r'lower="-2.967060" upper="2.967060"', 'lower="-6" upper="6"')],
                 r"joint 'joint_1': position limits \[-6, 6\] rad exceed what the joint bus carries"),
    "no-velocity": ([(r'velocity="1.710423" effort="176"', 'velocity="0" effort="176"')],
                    r"joint 'joint_1': <limit> velocity missing or empty"),
    "damping": ([(r'damping="0.5"', 'damping="-1"')],
                r"joint 'joint_1': <dynamics damping> must not be negative, got -1"),
}


@pytest.mark.parametrize("name", sorted(VARIANTS))
def test_a_urdf_the_simulator_cannot_drive_is_refused_naming_file_and_joint(tmp_path, name):
    edits, message = VARIANTS[name]
    path = edan_variant(tmp_path, name, *edits)
    with pytest.raises(ValueError, match=f"^--urdf: {re.escape(str(path))}: {message}"):
        service._settings_from_args(sim_args("--urdf", str(path)))


def test_a_urdf_without_masses_is_refused(tmp_path):
    path = tmp_path / "massless.urdf"
    path.write_text(re.sub(r"<inertial>.*?</inertial>", "", URDF_PATH.read_text(), flags=re.S))
    with pytest.raises(ArmModelError, match=r"massless\.urdf: the links the joints move have no mass"):
        load_arm_model(path)


def test_joints_off_the_chain_are_locked(tmp_path):
    finger = ('<joint name="finger" type="prismatic"><parent link="hand"/><child link="finger"/>'
              '<origin xyz="0 0 0.1"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04" velocity="0.2" '
              'effort="20"/></joint><link name="finger"><inertial><mass value="0.1"/>'
              '<inertia ixx="1e-5" ixy="0" ixz="0" iyy="1e-5" iyz="0" izz="1e-5"/></inertial></link></robot>')
    path = edan_variant(tmp_path, "gripper", (r"</robot>", finger))
    arm, shipped = load_arm_model(path), load_arm_model()
    assert arm.joint_names == shipped.joint_names
    total = sum(i.mass for i in arm.model.inertias)
    assert total == pytest.approx(sum(i.mass for i in shipped.model.inertias) + 0.1)
    assert not arm.seeds_tuned  # not the shipped file: its postures are not assumed


@pytest.mark.parametrize(("argv", "message"), [
    (("--urdf", "{missing}"), r"^--urdf: {missing}: no such file$"),
    (("--urdf", "{text}"), r"^--urdf: {text}: not a URDF Pinocchio reads"),
    (("--ee-frame", "link_4"), r"^--urdf: .*edan_arm\.urdf: the chain from the root to 'link_4' has 4 "
                               r"joints \(joint_1, joint_2, joint_3, joint_4\); the simulator drives 7 "
                               r"revolute joints"),
    (("--ee-frame", "palm"), r"^--ee-frame: .*edan_arm\.urdf: no frame 'palm' \(its links furthest from the "
                             r"root: ee, hand, flange, link_7, .*frames in all\)$"),
])
def test_bad_urdf_and_frame_flags_are_reported(tmp_path, argv, message):
    files = {"missing": str(tmp_path / "nowhere.urdf"), "text": str(tmp_path / "notes.txt")}
    Path(files["text"]).write_text("not xml\n")
    argv = tuple(a.format(**files) for a in argv)
    with pytest.raises(ValueError, match=message.format(**{k: re.escape(v) for k, v in files.items()})):
        service._settings_from_args(sim_args(*argv))


def test_the_fr3_without_ee_frame_lists_its_hand_frames(assets):
    with pytest.raises(ValueError, match=r"^--ee-frame: .*fr3\.urdf: no frame 'ee' \(its links furthest "
                                         r"from the root: .*fr3_hand_tcp, fr3_hand.*; name the hand's frame "
                                         r"with --ee-frame$"):
        service._settings_from_args(sim_args("--urdf", str(assets / "fr3.urdf")))


def test_the_flags_put_the_fr3_into_the_simulation(assets):
    args = sim_args("--urdf", str(assets / "fr3.urdf"), "--ee-frame", FR3_TCP, "--trial-seed", "1")
    settings = service._settings_from_args(args)
    assert settings.arm.joint_names[0] == "fr3_joint1"
    scene, q0 = service._start(settings, args)
    with Simulation(scene, q0=q0, arm=settings.arm) as sim:
        np.testing.assert_allclose(sim.arm.T_world_ee, scene.start_pose(), atol=1e-5)


def test_an_arm_too_short_for_the_task_exits_2_naming_it(tmp_path, capsys):
    root = ET.parse(URDF_PATH).getroot()
    for origin in root.iter("origin"):  # every length a quarter: 0.35 m tall
        xyz = origin.get("xyz")
        if xyz is not None:
            origin.set("xyz", " ".join(repr(0.25 * float(v)) for v in xyz.split()))
    short = tmp_path / "short.urdf"
    ET.ElementTree(root).write(short)
    assert service.main(["--task", "pour", "--urdf", str(short)]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert re.fullmatch(rf"sctd sim: --urdf: {re.escape(str(short))}: task pour: the start pose "
                        r"\[0\.450, 0\.000, 0\.680, .*\] \(x, y, z, qx, qy, qz, qw in the world\) is out of "
                        r"reach of the arm of short\.urdf \(frame 'ee'\): inverse kinematics from 31 "
                        r"postures did not reach it", err), err


def test_the_joint_bus_carries_seven_joints():
    bus = joint_bus_ranges()
    assert bus.n_joints == 7
    assert bus.position == (-5.24288, 5.24287) and bus.torque == (-204.8, 204.7)
