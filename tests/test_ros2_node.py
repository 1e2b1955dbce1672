"""``sctd ros`` against real ROS 2 software: rclpy nodes (tests/ros2_side.py) play a ROS 2
arm, its perception and a joystick, on Fast DDS, inside a network namespace the test
makes (loopback and one link to nowhere: no discovery traffic leaves it).

Needs root (``ip netns add``) and the ``ros2`` extra; without them the tests skip and
say why, except in CI (``$CI`` set), where they fail instead.
"""

from __future__ import annotations

import json

import pytest

from sctd.deploy.netns import Hosts, last_json, namespaces
from tests.conftest import require_namespaces, wait_for
from tests.tiers import needs

pytestmark = [pytest.mark.slow, pytest.mark.realtime]  # processes in a namespace, at the wall clock's pace

EP = "tcp/127.0.0.1:7447"  # inside the test's own namespace: nothing else is there
# The Joy of the test's joystick: axes are u, buttons [mode, enable, escape] (docs/input.md)
JOY_MAP = {"version": 1, "device": "test-joy",
           "axes": [{"source": 0}, {"source": 1}, {"source": 2}],
           "buttons": {"mode": 0, "enable": 1, "escape": 2}}


@pytest.fixture
def host(tmp_path):
    require_namespaces()
    needs("rclpy")  # the ros2 extra (tests/tiers.py)
    hosts = Hosts(["ros"], tmp_path)
    with hosts:
        yield hosts
    assert namespaces(hosts.run_id) == []


def _joy_map(tmp_path):
    import yaml

    path = tmp_path / "joy.yaml"
    path.write_text(yaml.safe_dump(JOY_MAP))
    return str(path)


def _logs(hosts: Hosts) -> str:
    return "\n".join(f"--- {p.log_path.name}\n{p.output()[-3000:]}" for p in hosts._procs)


def _hand(kind: str) -> tuple[list[str], list[str]]:
    """``sctd ros``'s flags for the hand, and the side's (the arm's joints)."""
    if kind == "pose":
        return ["--pose-topic", "ee_pose"], []
    from sctd_sim.robot import EE_FRAME, URDF_PATH, load_arm_model

    joints = load_arm_model().joint_names
    return (["--joint-states-topic", "joint_states", "--urdf", str(URDF_PATH), "--ee-frame", EE_FRAME],
            [a for j in joints for a in ("--joint", j)])


def _start(h: Hosts, tmp_path, hand: str, *extra: str):
    """The simulator behind the ROS arm, the daemon, ``sctd ros`` and the ROS side."""
    ros_flags, side_flags = _hand(hand)
    h.python("ros", "sctd_sim.service", "--task", "pour", "--robot", "arm", "--listen", EP, log="sim.log")
    h.python("ros", "sctd.cli.main", "run", "--skill", "pour", "--device", "ros", "--connect", EP,
             log="run.log")
    bridge = h.python("ros", "sctd.cli.main", "ros", *ros_flags, "--object", "mug=mug_pose",
                      "--object", "bottle_tip=bottle_tip_pose", "--joy-map", _joy_map(tmp_path),
                      *(a for a in extra if a != "--twist"), "--connect", EP, "--stats-json", log="ros.log")
    side = h.python("ros", "tests.ros2_side", "--connect", EP, "--frame", "mug", "--frame", "bottle_tip",
                    *side_flags, *(a for a in extra if a == "--twist"), log="side.log")
    assert wait_for(lambda: '"ready"' in side.output(), 60), _logs(h)
    return bridge, side


def test_the_pour_completes_with_a_ros2_arm_perception_and_joystick(host, tmp_path):
    """The daemon (following only the device ``ros``) gets its state from the arm's
    ``ee_pose``, the mug from the perception's ``mug_pose`` and the person's input from
    ``Joy``, all through ``sctd ros``; its target reaches the arm only as ROS's
    ``PoseStamped``. The simulated person pours until the simulator says it poured. (The
    hand from ``joint_states`` and the URDF: the twist test below.)"""
    h = host
    hand = "pose"
    bridge, side = _start(h, tmp_path, hand)
    report = h.call("ros", "sctd_services.simulated_user", "--task", "pour", "--duration", "150",
                    "--until-done", "--json", "--connect", EP, timeout=240)
    assert report["done"] and report["final_state"] == "pour", (report, _logs(h))
    side.stop()
    bridge.stop()
    seen = last_json(side.output())
    scene = seen["scene"]
    # The simulator's own verdict: a success by the task's rules, poured and stopped
    # pouring without a drop spilled and without emptying the bottle. (Through this loop
    # one run in ten or so once lost a few percent at the rim: the simulated arm's
    # controller swung the wrist at its singularity, sim/controller.py says how; the
    # loop was not the cause.)
    assert scene is not None and scene.get("success") and scene.get("spilled_amount") == 0.0, \
        {k: scene.get(k) for k in ("done", "success", "poured", "spilled_amount", "radial", "tilt",
                                   "skipped", "overruns", "behind_s", "target_rejected", "cycle_ms")}
    # what RViz shows: the pour's states, one array at a time, as the daemon went through them
    assert {"pour: carry", "pour: approach", "pour: pour"} <= set(seen["marker_labels"]), seen
    counts = last_json(bridge.output())
    got = counts["received"]
    assert got["pose"] > 1000 and got["objects/mug"] > 100 and got["joy"] > 100, counts
    assert counts["sent"]["target"] > 1000 and counts["sent"]["diagnostics"] > 10, counts
    assert counts["sent"]["markers"] >= 10, counts
    print(json.dumps({"user": {k: report[k] for k in ("elapsed_s", "mode_switches", "final_state")},
                      "bridge": counts}))


def test_the_twist_out_integrates_to_the_target_and_ends_with_a_zero(host, tmp_path):
    """``--twist-topic``: a consumer that integrates the TwistStamped (by header stamps)
    from the first target ends where the PoseStamped target ended (within 1 mm and 1
    mrad), and sees the motion end with a zero twist. The daemon's hand comes from the
    arm's ``joint_states`` over DDS and the shipped URDF (the forward kinematics are
    tested in-process in ``tests/test_ros2_bridge.py``; the pour above takes ``ee_pose``)."""
    import numpy as np

    from sctd import se3

    h = host
    # a history of 10: the test's consumer, in one process with the arm's and the perception's
    # relays, may lag a few twists behind, and it integrates every one (MoveIt Servo keeps
    # only the newest: the default of 1 is for it)
    bridge, side = _start(h, tmp_path, "joint_states", "--twist-topic", "sctd/twist", "--qos-depth", "10",
                          "--twist")
    report = h.call("ros", "sctd_services.simulated_user", "--task", "pour", "--duration", "8", "--json",
                    "--connect", EP, timeout=60)
    assert report["inputs_sent"] > 100 and len(report["state_changes"]) >= 1, report
    wait_for(lambda: False, 1.0)  # the daemon stops once the input is stale: the zero twist
    side.stop()
    bridge.stop()
    out = last_json(side.output())
    assert out["received"] > 300 and out["zeros"] >= 1, out
    T_int, T_tgt = se3.transform_from_pose(out["integrated"]), se3.transform_from_pose(out["target"])
    counts = last_json(bridge.output())
    off = np.linalg.norm(T_tgt[:3, 3] - T_int[:3, 3])
    assert off < 1e-3, (off, out["received"], counts["sent"], out["integrated"], out["target"])
    angle = np.linalg.norm(se3.rotvec_from_matrix(T_int[:3, :3] @ T_tgt[:3, :3].T))
    assert angle < 1e-3, angle
    assert counts["sent"]["twist"] > 300, counts
    assert counts["received"]["joint_state"] > 300 and not counts["received"].get("pose"), counts
