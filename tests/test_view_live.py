"""The live view (sctd_services.view.live) draws what the robot's keys say: the arm's
links at forward kinematics of ``q``, the hand and the target, the task's bodies at the
published poses and a joint's part at its reading, the active skill at its object and
state with its elements at the hand, a panel that says the mode, what each axis does,
what holds the hand and why the runtime holds, and plots of the owner's input.

Checked on the server's side of a Viser scene (no browser: tests/test_view_browser.py
looks at the pixels)."""

from __future__ import annotations

import numpy as np
import pytest

from sctd import se3
from sctd.skill import load_skill
from sctd.skill.catalog import shipped_folder
from sctd.task import find_task

viser = pytest.importorskip("viser")
pin = pytest.importorskip("pinocchio")

from sctd_services.view.arm import ArmGeometry  # noqa: E402
from sctd_services.view.live import LiveView, Snapshot  # noqa: E402
from sctd_sim.robot import FORWARD_POSTURE, URDF_PATH  # noqa: E402
from sctd_sim.view import stop_server, viser_server  # noqa: E402

SKILLS = shipped_folder()


@pytest.fixture
def server():
    s = viser_server(0)
    yield s
    stop_server(s)


def pose_of(T) -> list[float]:
    return se3.pose_from_transform(T).tolist()


def test_the_arm_the_hand_and_the_target_are_where_the_state_says(server):
    arm = ArmGeometry(URDF_PATH)
    view = LiveView(server, arm, None)
    q = np.asarray(FORWARD_POSTURE, dtype=float) + 0.1
    arm.poses(q)
    T_ee = arm.data.oMf[arm.model.getFrameId("ee")].homogeneous
    target = T_ee.copy()
    target[:3, 3] += [0.01, 0.0, 0.02]
    view.draw(Snapshot(t=1.0, pose=pose_of(T_ee), q=q.tolist(),
                       target={"pose": pose_of(target), "state": "x"}))
    for k, T in enumerate(arm.poses(q)):
        h = view.handles[f"/arm/{k}"]
        assert h.visible and np.allclose(h.position, T[:3, 3], atol=1e-6)
    assert np.allclose(view.handles["/hand"].position, T_ee[:3, 3], atol=1e-6)
    assert np.allclose(view.handles["/target"].position, target[:3, 3], atol=1e-6)
    assert [link.name for link in arm.links][-3:] == ["hand_0", "hand_1", "hand_2"] and not arm.skipped


def test_the_task_moves_with_what_the_robot_publishes(server):
    task = find_task("drawer")
    view = LiveView(server, None, task)
    T0 = task.scene.bodies["drawer_handle"].T_world.copy()
    T0[:3, 3] += [0.02, -0.03, 0.0]  # the trial put it elsewhere
    view.draw(Snapshot(t=1.0, objects={"drawer_handle": pose_of(T0)},
                       scene={"readings": {"drawer.position": 0.1}}))
    moving = view.handles["drawer/moving"]
    assert np.allclose(moving.position, T0[:3, 3] + 0.1 * T0[:3, 0], atol=1e-9)  # opened 10 cm along x


def test_the_skill_follows_its_object_and_the_daemons_state(server):
    task = find_task("pour")
    view = LiveView(server, None, task)
    view.set_skill(load_skill(SKILLS / "pour.yaml"))
    T_mug = task.scene.bodies["mug"].T_world.copy()
    T_mug[:3, 3] += [0.03, 0.01, 0.0]
    T_obj_ee = se3.transform_from_pose([0.0, 0.02, -0.02, 0.0, 0.0, 0.0, 1.0])  # the tip 10 cm over it
    T_ee = T_mug @ T_obj_ee
    view.draw(Snapshot(t=1.0, pose=pose_of(T_ee), objects={"mug": pose_of(T_mug)},
                       target={"pose": pose_of(T_ee), "state": "approach"}))
    sv = view.skill_view
    assert sv is not None and np.allclose(sv.root.position, T_mug[:3, 3])
    assert sv.handles["/skill/states/approach"].visible and not sv.handles["/skill/states/carry"].visible
    # the active state is drawn with the hand where it is (object frame)
    assert np.allclose(sv.nodes["/skill/states/approach/hand"][1], T_obj_ee[:3, 3], atol=1e-9)
    _, a, _ = sv.nodes["/skill/states/approach/axis1"]
    assert np.allclose(a, T_obj_ee[:3, 3] + [0.0, 0.0, 0.12], atol=1e-9)  # at the tip


def test_the_persons_panel_says_the_mode_the_axes_and_why_it_holds(server):
    task = find_task("pour")
    view = LiveView(server, None, task)
    view.set_skill(load_skill(SKILLS / "pour.yaml"))
    T_mug = task.scene.bodies["mug"].T_world
    # the tip 3 cm beside the pour state's box (1.5 cm): the box holds it
    T_ee = T_mug @ se3.transform_from_pose([0.045, 0.0, -0.06, 0.0, 0.0, 0.0, 1.0])
    snap = Snapshot(t=1.0, pose=pose_of(T_ee), objects={"mug": pose_of(T_mug)},
                    target={"pose": pose_of(T_ee), "state": "pour"},
                    status={"mode": "hold", "state": "pour", "stuck": {"state": "pour", "since": 6.2},
                            "region": {"inside": False, "outside_by": 0.234, "frame": "mug"},
                            "mode_button": None})
    view.draw(snap)
    text = view.person.content
    assert "mode: <b>pour</b> (the mode button does nothing here)" in text
    assert "axis 1: turns about mug +y at 0.35 rad/s" in text and "axis 3: moves tip along mug +z" in text
    assert "held by: tip stays in this box" in text
    assert "the robot's state or the object's pose is stale" in text
    assert "stuck in pour for 6 s" in text
    assert "out of this skill's region: 23 cm from where it was taught (around mug)" in text
    snap.status = {"mode": "running", "state": "pour"}
    snap.pose = pose_of(T_mug @ se3.transform_from_pose([0.0, 0.0, -0.06, 0.0, 0.0, 0.0, 1.0]))
    view.draw(snap)
    assert "held by" not in view.person.content and "holding" not in view.person.content
    assert "mode button" not in view.person.content  # a status that does not say
    snap.status = {"mode": "running", "state": "pour", "mode_button": "approach"}
    view.draw(snap)
    assert "mode: <b>pour</b> (the mode button: to approach)" in view.person.content
    assert "region" not in view.person.content


def test_the_plots_show_the_input_of_the_device_that_owns_the_motion(server):
    view = LiveView(server, None, None)
    for k in range(12):
        view.draw(Snapshot(t=0.1 * k, pose=[0.01 * k, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0],
                           inputs={"a": ([0.5, 0.0, 0.0], 0.0), "b": ([0.0, -0.7, 0.2], 0.0)},
                           status={"input": {"owner": "b"}}))
    t, u1, u2, u3 = view.input_plot.data
    assert u1[-1] == 0.0 and u2[-1] == -0.7 and u3[-1] == 0.2 and t[-1] == 0.0 and t[0] < 0.0
    _, speed, _ = view.motion_plot.data
    assert np.allclose(speed[2:], 0.1)  # 1 cm per 0.1 s


def test_the_constraints_plot_and_held_by_follow_the_runtimes_report(server):
    """``status.constraints`` (the share of the window's commands each constraint
    changed) is plotted per constraint of the active state, named under the plot, and
    says what holds the hand: the runtime's word, not the view's guess from the pose."""
    task = find_task("pour")
    view = LiveView(server, None, task)
    view.set_skill(load_skill(SKILLS / "pour.yaml"))
    T_mug = task.scene.bodies["mug"].T_world
    inside = T_mug @ se3.transform_from_pose([0.0, 0.0, -0.06, 0.0, 0.0, 0.0, 1.0])  # tip in the box
    for k in range(12):
        acted = [0, 40] if k >= 6 else [0, 0]
        view.draw(Snapshot(t=0.1 * k, pose=pose_of(inside), objects={"mug": pose_of(T_mug)},
                           target={"pose": pose_of(inside), "state": "pour"},
                           status={"mode": "running", "state": "pour",
                                   "constraints": {"state": "pour", "commands": 50, "acted": acted}}))
    _, c1, c2, c3, c4 = view.constraint_plot.data
    assert list(c1) == [0.0] * 12 and list(c2[:6]) == [0.0] * 6 and list(c2[6:]) == [0.8] * 6
    assert np.isnan(c3).all() and np.isnan(c4).all()  # pour's pour state has two constraints
    assert "held by: tip stays in this box" in view.person.content
    legend = view.constraint_legend.content
    assert "constraints of **pour**" in legend and "2: tip stays in this box" in legend
    # past the box by the pose, but the runtime says nothing acted: nothing holds
    beside = T_mug @ se3.transform_from_pose([0.045, 0.0, -0.06, 0.0, 0.0, 0.0, 1.0])
    view.draw(Snapshot(t=1.3, pose=pose_of(beside), objects={"mug": pose_of(T_mug)},
                       target={"pose": pose_of(beside), "state": "pour"},
                       status={"mode": "running", "state": "pour",
                               "constraints": {"state": "pour", "commands": 50, "acted": [0, 0]}}))
    assert "held by" not in view.person.content


def test_held_by_names_bounds_only(server):
    """A neighbour orientation changes every command of a vector-field skill (it turns
    the hand as the demonstrations did): plotted, but it holds nothing."""
    task = find_task("drawer")
    view = LiveView(server, None, task)
    skill = load_skill(SKILLS / "drawer-vf.yaml")
    view.set_skill(skill)
    T = task.scene.bodies[skill.object].T_world
    hand = T @ se3.transform_from_pose([-0.1, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    state = skill.states[0]
    assert [c.bounds for c in state.active_constraints] == [False]
    for t in (1.0, 1.3):
        view.draw(Snapshot(t=t, pose=pose_of(hand), objects={skill.object: pose_of(T)},
                           target={"pose": pose_of(hand), "state": state.name},
                           status={"mode": "running", "state": state.name,
                                   "constraints": {"state": state.name, "commands": 50, "acted": [50]}}))
    assert "held by" not in view.person.content
    assert view.constraint_plot.data[1][-1] == 1.0


# -- from a log ----------------------------------------------------------------------------
def _log(skill_id: str) -> list:
    """Messages as ``read_log`` gives them: 2 s of a hand moving 10 cm along x."""
    out = []
    for k in range(201):
        t = int(1e9 * (100.0 + 0.01 * k))
        out.append(("sctd/edan/state", t, {"seq": k, "stamp": 0.0, "pose": [0.5 + 0.0005 * k, 0.0, 0.7,
                                                                         0.0, 0.0, 0.0, 1.0]}))
        if k % 10 == 0:
            state = "carry" if k < 100 else "approach"
            out.append(("sctd/edan/status", t, {"skill": skill_id, "state": state, "mode": "running",
                                               "input": {"owner": "pad"}}))
            out.append(("sctd/edan/objects/mug", t, {"seq": k, "stamp": 0.0,
                                                     "pose": [0.75, 0.0, 0.65, 0.0, 0.0, 1.0, 0.0]}))
            out.append(("sctd/edan/input/pad", t, {"seq": k, "stamp": 0.0, "u": [-0.5, 0.0, 0.0]}))
            out.append(("sctd/other/state", t, {"pose": [9.0] * 7}))  # another robot: left out
    return out


def test_a_log_is_a_timeline_of_what_the_view_would_have_shown():
    from sctd_services.view.timeline import Timeline

    tl = Timeline(reversed(_log("abc")), "sctd/edan")  # any order
    assert tl.duration == pytest.approx(2.0) and tl.keys("objects") == ["mug"] and tl.keys("input") == ["pad"]
    snap = tl.at(0.505)  # the newest at or before: the state of 0.50 s
    assert snap.pose[0] == pytest.approx(0.525) and snap.status["state"] == "carry"
    assert snap.objects["mug"][:3] == [0.75, 0.0, 0.65] and snap.inputs["pad"][0] == [-0.5, 0.0, 0.0]
    assert tl.at(1.5).status["state"] == "approach" and tl.at(-0.1).pose is None
    assert tl.skill_ids() == ["abc"]


def test_a_log_is_scrubbed_with_its_slider(server):
    import threading

    from sctd_services.view.timeline import Timeline, run_replay
    from tests.conftest import wait_for

    skill = load_skill(SKILLS / "pour.yaml")
    view = LiveView(server, None, find_task("pour"))
    view.set_skill(skill)
    stop = threading.Event()
    thread = threading.Thread(target=run_replay, args=(view, Timeline(_log(skill.id), "sctd/edan"), stop))
    thread.start()
    try:
        assert wait_for(lambda: view.replay_slider is not None, 10)
        for t in (1.5, 0.25):  # forwards, then back
            view.replay_slider.value = t
            assert wait_for(lambda t=t: view.drawn_at == t, 10)
            assert wait_for(lambda t=t: np.allclose(view.handles["/hand"].position,
                                                    [0.5 + 0.05 * t, 0.0, 0.7], atol=1e-9), 5)
        assert "mode: <b>carry</b>" in view.person.content  # 0.25 s: before the change at 1 s
    finally:
        stop.set()
        thread.join(10)


def test_sctd_view_replays_a_log_file(tmp_path, capsys):
    """`sctd view --log FILE`: an MCAP of `sctd log` opened on its timeline, its skill
    found by the id its status names; a damaged file is refused naming it."""
    from sctd.cli.log import McapLog
    from sctd.cli.main import main
    from sctd.wire import codec

    skill = load_skill(SKILLS / "pour.yaml")
    path = tmp_path / "run.mcap"
    with McapLog(path) as log:
        for key, t, value in _log(skill.id):
            if key.startswith("sctd/edan/"):
                log.add(key, key.split("/")[2], codec.pack(value), t * 1e-9)
    assert main(["view", "--log", str(path), "--view-for", "1"]) == 0
    err = capsys.readouterr().err
    assert f"{path} (2.0 s) at http://127.0.0.1:" in err and "not found" not in err
    path.write_bytes(path.read_bytes()[:200])
    assert main(["view", "--log", str(path)]) == 2
    assert f"--log: {path}" in capsys.readouterr().err


def test_sctd_view_reports_what_it_read(capsys):
    """`sctd view --stats-json`: on exit, the frames drawn, the messages read by key (the
    task's objects by name, each input device), the undecodable ones and the skill fetches
    (none can succeed here: no daemon answers ``skill/bundle``)."""
    import json
    import threading

    from sctd.cli.main import main
    from sctd.cli.procs import free_port
    from sctd.wire import Keys, codec
    from sctd.wire.session import close_session, open_session

    ep, keys = f"tcp/127.0.0.1:{free_port()}", Keys("edan")
    task = find_task("pour")
    stop = threading.Event()

    def publish():
        s = open_session(connect=[ep])
        try:
            seq = 0
            while not stop.wait(0.02):
                seq += 1
                if seq % 10 == 0:
                    s.put(keys.status, b"\xc1 not msgpack")
                s.put(keys.state, codec.encode_state(seq, 1.0, pose_of(np.eye(4)), q=list(FORWARD_POSTURE)))
                s.put(keys.objects(task.object), codec.encode_object(seq, 1.0, pose_of(np.eye(4))))
                s.put(keys.input("pad"), codec.encode_input(seq, 1.0, [0.1, 0.0, 0.0], [0, 1, 0]))
                s.put(keys.status, codec.pack({"v": 1, "skill": "0123abcd", "state": "carry"}))
        finally:
            close_session(s)

    thread = threading.Thread(target=publish, daemon=True)
    thread.start()
    try:
        assert main(["view", "--task", "pour", "--listen", ep, "--view-for", "4", "--stats-json"]) == 0
    finally:
        stop.set()
        thread.join(10)
    out, err = capsys.readouterr()
    report = json.loads(out.strip().splitlines()[-1])
    assert report["frames"] > 0 and report["skills"] == [] and report["fetch_failures"] >= 1, report
    read = report["read"]
    assert read["state"] > 0 and read[f"objects/{task.object}"] > 0 and read["input/pad"] > 0, read
    assert read["status"] > 0 and report["dropped"] >= 1, report
    assert f"sctd view: stopped after {report['frames']} frames; read " in err
    # --stats-json is the live view's: a log replay refuses it
    assert main(["view", "--log", "x.mcap", "--stats-json"]) == 2
    assert "--stats-json reports on the live view" in capsys.readouterr().err


def test_the_persons_panel_says_which_task_is_engaged_and_the_belief(server):
    """A skill set's status: the engaged member (or teleoperation), the belief most
    likely first, a change waiting for the release; a status off the wire that is not
    the contract's draws nothing of it, and names are escaped."""
    from sctd_services.view.live import goal_lines

    status = {"goals": {"engaged": "teleop", "belief": {"drawer": 0.15, "pour": 0.8, "door": 0.05},
                        "pending": {"kind": "choose", "member": "pour"}}}
    lines = goal_lines(status)
    assert lines == ["engaged: <b>teleoperation</b>", "going for: pour 80 %, drawer 15 %, door 5 %",
                     "choosing pour once the stick is let go"]
    assert goal_lines({"goals": {"engaged": "<i>x</i>", "belief": {"a": float("nan"), "b": "1"},
                                 "pending": {"kind": "escape"}}}) == \
        ["engaged: <b>&lt;i&gt;x&lt;/i&gt;</b>", "leaving the skill once the stick is let go"]
    assert goal_lines({}) == [] and goal_lines({"goals": [1, 2]}) == []
    view = LiveView(server, None, find_task("pour"))
    view.draw(Snapshot(t=1.0, pose=None, objects={}, target={"state": "translate"},
                       status={"mode": "running", "state": "translate", **status}))
    assert "going for: pour 80 %" in view.person.content


def test_the_persons_panel_tells_a_slow_link_and_nothing_on_a_quick_one(server):
    from sctd_services.view.live import SLOW_INPUT_MS, SLOW_STATE_MS, link_lines

    assert link_lines({"state_delay_ms": SLOW_STATE_MS, "input_delay_ms": SLOW_INPUT_MS}) == []
    slow = link_lines({"state_delay_ms": 52.4, "input_delay_ms": 80.0})
    assert slow == [
        "<b>the arm's link is slow: its state arrives 52 ms late, so the arm follows more slowly</b>",
        "<b>the input's link is slow: it arrives 80 ms late</b>"]
    assert link_lines({}) == [] and link_lines({"state_delay_ms": None}) == []
    assert link_lines({"state_delay_ms": "99", "input_delay_ms": float("nan")}) == []  # not the contract's
    assert link_lines({"state_delay_ms": True}) == []
    view = LiveView(server, None, find_task("pour"))
    view.draw(Snapshot(t=1.0, pose=None, objects={}, target={"state": "translate"},
                       status={"mode": "running", "state": "translate", "state_delay_ms": 52.4}))
    assert "its state arrives 52 ms late" in view.person.content


def test_the_persons_panel_says_which_device_must_centre_its_stick_and_why(server):
    """``status.input.rearm`` (a push that went stale, a stop...): the device is named
    with the reason in words, the stale one first; a ``rearm`` off the wire that is not
    the contract's draws nothing, and names are escaped."""
    from sctd_services.view.live import rearm_lines

    status = {"input": {"owner": None, "rearm": {"pad": "ignored", "<b>x": "stale"}}}
    lines = rearm_lines(status)
    assert len(lines) == 2 and lines[0].startswith("<b>&lt;b&gt;x: centre the stick") and \
        "stopped arriving" in lines[0] and "another device" in lines[1]
    assert rearm_lines({}) == [] and rearm_lines({"input": {"rearm": [1]}}) == [] and \
        rearm_lines({"input": {"rearm": {"a": "bogus"}}}) == []
    view = LiveView(server, None, find_task("pour"))
    view.draw(Snapshot(t=1.0, pose=None, objects={}, target={"state": "translate"},
                       status={"mode": "running", "state": "translate", **status}))
    assert "centre the stick to move again" in view.person.content
