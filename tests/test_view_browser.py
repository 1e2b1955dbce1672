"""`sctd inspect SKILL --view` in a real headless Chromium (tests/browser.py): the skill's
elements, the task's bodies and the demonstrations are drawn where they project, and the
state picker, worked by clicks, shows one state at a time.

"Drawn where it projects" is checked by difference: hiding one node from the server
changes the screenshot around the pixel its points project to, and nowhere far from
them; so the check holds whatever else overlaps it (translucent regions tint what is
behind them).
"""

from __future__ import annotations

import os
import re
import signal
from pathlib import Path

import numpy as np
import pytest

from sctd import se3
from sctd.learn.demos import read_demos
from sctd.skill import load_skill
from sctd.skill.catalog import shipped_folder
from sctd.task import find_task
from tests import browser
from tests.browser import Camera
from tests.conftest import free_port, port_is_free, run_sctd, sctd, wait_for
from tests.test_sim_view import get_page, listeners

SKILLS = shipped_folder()
W, H = 800, 600
SHOTS = os.environ.get("SCTD_VIEW_SHOTS")  # a folder: save the screenshots there (docs/view.md's)
URL = re.compile(r"view of \S+ at (http://127\.0\.0\.1:(\d+))")


@pytest.fixture
def skill_view():
    """Makes (server, view) for a shipped skill's file name; stops every server after."""
    from sctd_services.view.draw import SkillView
    from sctd_services.view.skill_scene import skill_scene
    from sctd_sim.view import stop_server, viser_server

    servers = []

    def make(name: str, task: str | None = None, demos: str | None = None):
        skill = load_skill(SKILLS / name)
        scene = skill_scene(skill, read_demos(SKILLS / "demos" / demos) if demos else None)
        server = viser_server(0)
        servers.append(server)
        return server, SkillView(server, scene, task=find_task(task) if task else None)

    yield make
    for s in servers:
        stop_server(s)


def save(view, name: str) -> None:
    if SHOTS:
        Path(SHOTS).mkdir(parents=True, exist_ok=True)
        view.page.screenshot(path=str(Path(SHOTS) / name))


def changed(a: np.ndarray, b: np.ndarray, tol: int = 25) -> np.ndarray:
    """Pixels that differ by more than ``tol`` in a channel (H, W bool)."""
    return np.any(np.abs(a.astype(int) - b.astype(int)) > tol, axis=-1)


def near(mask: np.ndarray, rc, radius: int = 6) -> bool:
    r, c = (int(x) for x in rc)
    return bool(mask[max(r - radius, 0):r + radius + 1, max(c - radius, 0):c + radius + 1].any())


def drawn_where_projected(view, handle, points: np.ndarray, radius: int = 6) -> None:
    """Hiding ``handle`` changes pixels near the projection of ``points`` (n, 3; world)
    and the changed pixels all lie near some projected point (within the box around
    them, widened by the shape's size on screen). The GUI panel is not the scene: its
    pixels are left out."""
    view.settle()
    shown = view.screenshot()
    handle.visible = False
    view.settle()
    hidden = view.screenshot()
    handle.visible = True
    diff = changed(shown, hidden)
    panel = view.panel_box()
    if panel is not None:
        left, top, width, height = (round(v) for v in panel)
        diff[max(top, 0):top + height + 1, max(left, 0):left + width + 1] = False
    px = view.pixels(points)
    inside = (px[:, 0] >= 0) & (px[:, 0] < H) & (px[:, 1] >= 0) & (px[:, 1] < W)
    assert inside.any(), "none of its points is in the view"
    assert diff.any(), "hiding it changed nothing"
    assert any(near(diff, p, radius) for p in px[inside]), "nothing changed where it projects"
    rows, cols = np.nonzero(diff)
    lo, hi = px.min(axis=0) - 4 * radius, px.max(axis=0) + 4 * radius  # (a part may leave the view)
    assert lo[0] <= rows.min() and rows.max() <= hi[0] and lo[1] <= cols.min() and cols.max() <= hi[1], \
        f"changed rows {rows.min()}-{rows.max()}, columns {cols.min()}-{cols.max()}; projected {lo}-{hi}"


def reddish(rgb) -> bool:
    r, g, b = (int(x) for x in rgb)
    return r > 140 and r - max(g, b) > 60


def has_colour(image: np.ndarray, rc, rgb, radius: int = 4, tol: int = 60) -> bool:
    r, c = (int(x) for x in rc)
    patch = image[max(r - radius, 0):r + radius + 1, max(c - radius, 0):c + radius + 1].astype(int)
    return bool((np.abs(patch - np.asarray(rgb)).max(axis=-1) < tol).any())


POUR_CAMERA = Camera(position=(0.55, -0.65, 0.45), look_at=(0.0, 0.0, 0.08), fov=0.8)


@pytest.mark.slow
def test_the_skill_and_the_task_are_drawn_where_they_project(skill_view):
    server, view = skill_view("pour.yaml", task="pour")
    with browser.open_viser(server, W, H) as page:
        page.set_camera(POUR_CAMERA)
        save(page, "view-pour-carry.png")
        nodes, handles = view.nodes, view.handles
        _, a, b = nodes["/skill/states/carry/axis1"]
        image = page.screenshot()
        mid = page.pixels(np.array([(a + b) / 2]))[0]
        assert any(reddish(image[r, c]) for r in range(mid[0] - 3, mid[0] + 4)
                   for c in range(mid[1] - 3, mid[1] + 4)), "axis 1 is a red arrow along its motion"
        for name in ("/skill/states/carry/axis1", "/skill/states/carry/axis3",
                     "/skill/task/mug/container", "/skill/states/carry/held/bottle/held"):
            kind, *vals = nodes[name]
            points = np.array([vals[0], vals[1]]) if kind == "arrow" else vals[0]
            drawn_where_projected(page, handles[name], points)
        kind, centre, radius = nodes["/skill/states/carry/transition3"]
        assert kind == "sphere" and radius == 0.15
        drawn_where_projected(page, handles["/skill/states/carry/transition3"],
                              centre + radius * np.array([[1, 0, 0], [-1, 0, 0], [0, 0, 1], [0, 0, -1],
                                                          [0, 1, 0], [0, -1, 0]]), radius=12)


@pytest.mark.slow
def test_the_state_picker_shows_one_state_at_a_time(skill_view):
    server, view = skill_view("pour.yaml", task="pour")
    with browser.open_viser(server, W, H) as page:
        page.set_camera(POUR_CAMERA)
        assert page.value_of("state") == "carry"
        assert "axis 1: moves tip along mug +x at 0.10 m/s" in page.text()
        before = page.screenshot()
        _, a, b = view.nodes["/skill/states/carry/axis1"]
        carry_arrow = page.pixels(np.array([(a + b) / 2]))[0]
        _, lower, upper = view.nodes["/skill/states/pour/constraint1"]  # the pour's box
        pour_box = page.pixels(np.array([(lower + upper) / 2]))[0]

        page.choose("state", "pour")
        page.wait_for_text("turns about mug +y at 0.35 rad/s")
        assert "moves tip along mug +x" not in page.text()
        page.settle()
        after = page.screenshot()
        save(page, "view-pour-pour.png")
        assert view.picker.value == "pour"
        assert not view.handles["/skill/states/carry"].visible and view.handles["/skill/states/pour"].visible
        diff = changed(before, after)
        assert near(diff, carry_arrow) and near(diff, pour_box)
        assert not any(reddish(after[r, c]) for r in range(carry_arrow[0] - 2, carry_arrow[0] + 3)
                       for c in range(carry_arrow[1] - 2, carry_arrow[1] + 3))

        page.choose("state", "every state")
        page.wait_for_text("carry (start)")  # (the pour's own text names approach already)
        assert wait_for(lambda: all(view.handles[f"/skill/states/{s}"].visible
                                    for s in ("carry", "approach", "pour")), 10)


@pytest.mark.slow
def test_demonstrations_are_coloured_by_the_state_the_fsm_gives_them(skill_view):
    from sctd_services.view.draw import state_rgb

    server, view = skill_view("pour-linear.yaml", task="pour", demos="pour")
    path = view.scene.demos[0]
    with browser.open_viser(server, W, H) as page:
        page.set_camera(Camera(position=(0.45, -0.55, 0.35), look_at=(0.15, 0.0, 0.0), fov=0.8))
        page.choose("state", "every state")
        page.settle()
        image = page.screenshot()
        save(page, "view-pour-linear-demos.png")
        for state in (0, 1):
            idx = np.flatnonzero(path.states == state)
            assert len(idx) > 20
            # well inside the stretch, away from a dropped outlier's gap (the shipped
            # pour's demonstrations have 5 % gross outliers, drawn apart as grey dots)
            steps = np.linalg.norm(np.diff(path.points, axis=0), axis=1)
            calm = [i for i in idx[len(idx) // 4: 3 * len(idx) // 4]
                    if 0 < i < len(steps) and steps[i - 1] < 0.01 and steps[i] < 0.01]
            samples = path.points[calm[::5]]
            px = page.pixels(samples)
            hits = sum(has_colour(image, p, state_rgb(state)) for p in px)
            assert hits >= 0.6 * len(px), (state, hits, len(px))
        drawn_where_projected(page, view.handles["/skill/demos/0"], np.vstack([path.points, path.spikes]),
                              radius=4)
        # the outliers are grey dots where they are, apart from the path
        drawn_where_projected(page, view.handles["/skill/demos/0/spikes"], path.spikes, radius=4)


@pytest.mark.slow
def test_a_vector_field_skill_shows_its_fields_where_they_are(skill_view):
    server, view = skill_view("drawer-vf.yaml", task="drawer", demos="drawer")
    with browser.open_viser(server, W, H) as page:
        page.set_camera(Camera(position=(0.45, -0.45, 0.3), look_at=(0.12, 0.0, 0.02), fov=0.8))
        save(page, "view-drawer-vf.png")
        assert "field" in " ".join(view.nodes) and "axis 1: moves ee along drawer_handle +x" in page.text()
        for name, node in view.nodes.items():
            if node[0] == "arrows":
                drawn_where_projected(page, view.handles[name], node[1], radius=6)
        drawer = "/skill/task/drawer/moving"
        drawn_where_projected(page, view.handles[drawer], view.nodes[drawer][1], radius=8)


# -- the command -----------------------------------------------------------------------
def test_view_flags_need_the_view(capsys):
    from sctd.cli.main import main

    assert main(["inspect", str(SKILLS / "pour.yaml"), "--demos", str(SKILLS / "demos" / "pour")]) == 2
    assert "need --view" in capsys.readouterr().err
    assert main(["inspect", str(SKILLS / "pour.yaml"), "--view", "--view-port", "70000"]) == 2
    assert "not a TCP port: 70000" in capsys.readouterr().err
    assert main(["inspect", str(SKILLS / "pour.yaml"), "--view", "--view-for", "0"]) == 2
    assert "--view-for: must be > 0" in capsys.readouterr().err


@pytest.mark.slow
def test_sctd_inspect_view_serves_on_loopback_until_stopped(tmp_path):
    port = free_port()
    proc = sctd("inspect", str(SKILLS / "drawer.yaml"), "--view", "--view-port", str(port),
                log=tmp_path / "inspect.log")
    try:
        assert wait_for(lambda: URL.search(proc.output()) is not None, 60), proc.output()
        assert URL.search(proc.output()).group(2) == str(port)
        assert listeners(port) == ["127.0.0.1"]
        assert get_page(port)[0] == 200
        second = run_sctd("inspect", str(SKILLS / "drawer.yaml"), "--view", "--view-port", str(port))
        assert second.returncode == 2 and f"port {port} on 127.0.0.1 is in use" in second.stderr
        proc.p.send_signal(signal.SIGINT)
        assert proc.p.wait(20) == 0, proc.output()
    finally:
        proc.stop()
    assert "view stopped" in proc.output()
    assert port_is_free(port) and listeners(port) == []


# -- live: next to a running simulator and daemon -----------------------------------------
class Recording:
    """A Zenoh session that records what is declared on it (kind, key), forwarding the
    rest: the view must only subscribe, and query ``skill/bundle``."""

    def __init__(self, session):
        self._session = session
        self.declared: list[tuple[str, str]] = []

    def __getattr__(self, name):
        attr = getattr(self._session, name)
        if name.startswith("declare_") or name in ("put", "get", "delete"):
            def recorded(key, *args, **kwargs):
                self.declared.append((name, str(key)))
                return attr(key, *args, **kwargs)
            return recorded
        return attr


def _drive(session, keys, stop, u=(-0.6, 0.0, 0.0)):
    """Push the stick with the deadman held at 50 Hz until ``stop`` (a person's input),
    centring it while the daemon's status says this device must send a zero first (as a
    person reading the display does: on a busy machine this thread can fall silent for
    longer than the daemon lets a push go stale, and the daemon then ignores the push
    until it sees a zero)."""
    import time

    from sctd.wire import codec

    rearm: dict = {}

    def on_status(sample):
        status = codec.unpack_map(sample.payload.to_bytes())
        inp = status.get("input")
        rearm["test"] = isinstance(inp, dict) and "test" in (inp.get("rearm") or {})

    sub = session.declare_subscriber(keys.status, on_status)
    pub = session.declare_publisher(keys.input("test"))
    seq = 0
    while not stop.is_set():
        seq += 1
        pub.put(codec.encode_input(seq, time.time(), [0.0] * 3 if rearm.get("test") else list(u), [0, 1, 0]))
        stop.wait(0.02)
    sub.undeclare()
    for _ in range(3):
        seq += 1
        pub.put(codec.encode_input(seq, time.time(), [0.0, 0.0, 0.0], [0, 0, 0]))
    pub.undeclare()


@pytest.mark.slow
def test_the_live_view_draws_the_running_arm_and_skill_and_only_observes(tmp_path):
    import threading

    from sctd.wire import Keys
    from sctd.wire.session import close_session, open_session
    from sctd_services.view.arm import ArmGeometry
    from sctd_services.view.live import LiveView
    from sctd_services.view.service import run_view
    from sctd_sim.robot import URDF_PATH
    from sctd_sim.view import stop_server, viser_server

    keys, ep = Keys("edan"), f"tcp/127.0.0.1:{free_port()}"
    sim = sctd("sim", "--task", "pour", "--listen", ep, log=tmp_path / "sim.log")
    run = sctd("run", "--skill", str(SKILLS / "pour.yaml"), "--connect", ep, log=tmp_path / "run.log")
    logger = sctd("log", "--mcap", str(tmp_path / "pour.mcap"), "--connect", ep, log=tmp_path / "log.log")
    ours, driver = open_session(connect=[ep]), open_session(connect=[ep])
    recording = Recording(ours)
    server = viser_server(0)
    view = LiveView(server, ArmGeometry(URDF_PATH), find_task("pour"))
    stop, pushed = threading.Event(), threading.Event()
    threads = [threading.Thread(target=run_view, args=(recording, keys, view, stop), daemon=True),
               threading.Thread(target=_drive, args=(driver, keys, pushed), daemon=True)]
    try:
        threads[0].start()
        assert wait_for(lambda: view.skill_view is not None and view.handles["/arm/0"].visible, 60), \
            sim.output() + run.output()
        threads[1].start()  # towards the mug: carry -> approach
        assert wait_for(lambda: view.skill_view.active == "approach", 60), run.output()
        pushed.set()
        threads[1].join(10)
        assert wait_for(lambda: "stopped" in view.person.content, 20), view.person.content
        # the daemon's constraint activity is plotted: approach's cone and band, numbers
        _, c1, c2, c3, _ = view.constraint_plot.data
        assert np.isfinite(c1[-1]) and np.isfinite(c2[-1]) and np.isnan(c3[-1])
        drawn = view.redraws
        assert wait_for(lambda: view.redraws > drawn + 1, 10)  # the hand at rest, drawn at it
        stop.set()  # the scene as it was last drawn stays: the pixels are checked on it
        threads[0].join(10)
        with browser.open_viser(server, W, H) as page:
            page.wait_for_text("mode: approach")
            # the scene left of the GUI's panel (the right 40 % of the page)
            page.set_camera(Camera(position=(1.0, -1.2, 1.0), look_at=(0.95, 0.0, 0.55), fov=0.8))
            save(page, "view-live-pour.png")
            assert view.arm is not None
            wrist = len(view.arm.links) - 4  # the last link before the hand's three parts
            meshes = {f"/arm/{wrist}": view.arm.links[wrist].vertices,
                      "mug/container": next(p.vertices for p in view.parts if p.name == "mug/container"),
                      "/hand": np.zeros((1, 3)), "/target": np.zeros((1, 3))}
            for name, vertices in meshes.items():
                h = view.handles[name]
                T = se3.transform_from_pose(np.r_[h.position, np.asarray(h.wxyz)[[1, 2, 3, 0]]])
                # at rest the target is where the hand is, inside the hand's larger frame
                view.handles["/hand"].visible = name != "/target"
                drawn_where_projected(page, h, (T[:3, :3] @ vertices.T).T + T[:3, 3], radius=12)
            sv = view.skill_view
            states = sv.handles
            assert states["/skill/states/approach"].visible and not states["/skill/states/carry"].visible
            _, a, b = sv.nodes["/skill/states/approach/axis1"]  # object frame: placed at the mug
            T_mug = se3.transform_from_pose(
                np.r_[sv.root.position, np.asarray(sv.root.wxyz)[[1, 2, 3, 0]]])
            ends = (T_mug[:3, :3] @ np.array([a, b]).T).T + T_mug[:3, 3]
            # the active state is drawn with the hand where it is
            hand = T_mug[:3, :3] @ sv.nodes["/skill/states/approach/hand"][1] + T_mug[:3, 3]
            assert np.allclose(hand, view.handles["/hand"].position, atol=2e-3)
            drawn_where_projected(page, sv.handles["/skill/states/approach/axis1"], ends, radius=8)
    finally:
        stop.set()
        pushed.set()
        for t in threads:
            t.join(10)
        stop_server(server)
        close_session(ours)
        close_session(driver)
        assert logger.stop() == 0, logger.output()
        run.stop()
        sim.stop()
    # the same run from its log: the pour in approach, where the log's state puts the hand
    replayed(tmp_path / "pour.mcap", "pour", load_skill(SKILLS / "pour.yaml"), "approach",
             "view-log-pour.png",
             Camera(position=(1.0, -1.2, 1.0), look_at=(0.95, 0.0, 0.55), fov=0.8))
    # an observer: subscriptions, and queries on skill/bundle alone
    kinds = {k for k, _ in recording.declared}
    assert kinds <= {"declare_subscriber", "declare_querier"}, recording.declared
    assert {key for k, key in recording.declared if k == "declare_querier"} == {keys.skill_bundle}
    subscribed = {key for k, key in recording.declared if k == "declare_subscriber"}
    assert {keys.state, keys.target, keys.status, keys.scene, keys.objects("mug")} <= subscribed
    assert not any(key.startswith(keys.skill_swap) for _, key in recording.declared)


def replayed(mcap: Path, task: str, skill, state: str, shot: str, camera: Camera) -> None:
    """``sctd view --log`` of a run's log: at the last time the log's status says
    ``state``, the view shows that state, the arm and the hand where the log's state puts
    them, drawn there in the page (screenshot ``shot``)."""
    import threading

    from sctd.cli.log import read_log
    from sctd_services.view.arm import ArmGeometry
    from sctd_services.view.live import LiveView
    from sctd_services.view.timeline import Timeline, run_replay
    from sctd_sim.robot import URDF_PATH
    from sctd_sim.view import stop_server, viser_server

    timeline = Timeline(read_log(mcap), "sctd/edan")
    assert timeline.skill_ids() == [skill.id]
    times = [t / 100 for t in range(int(timeline.duration * 100))]
    when = max(t for t in times if (timeline.at(t).status or {}).get("state") == state)
    server = viser_server(0)
    view = LiveView(server, ArmGeometry(URDF_PATH), find_task(task))
    view.set_skill(skill)
    stop = threading.Event()
    thread = threading.Thread(target=run_replay, args=(view, timeline, stop), daemon=True)
    thread.start()
    try:
        assert wait_for(lambda: view.replay_slider is not None, 10)
        view.replay_slider.value = when
        assert wait_for(lambda: view.drawn_at == when, 10)
        snap = timeline.at(when)
        assert np.allclose(view.handles["/hand"].position, snap.pose[:3])
        assert view.skill_view is not None and view.skill_view.handles[f"/skill/states/{state}"].visible
        with browser.open_viser(server, W, H) as page:
            page.wait_for_text(f"mode: {state}")
            page.set_camera(camera)
            save(page, shot)
            assert view.arm is not None
            wrist = len(view.arm.links) - 4
            h = view.handles[f"/arm/{wrist}"]
            T = se3.transform_from_pose(np.r_[h.position, np.asarray(h.wxyz)[[1, 2, 3, 0]]])
            drawn_where_projected(page, h, (T[:3, :3] @ view.arm.links[wrist].vertices.T).T + T[:3, 3],
                                  radius=12)
    finally:
        stop.set()
        thread.join(10)
        stop_server(server)


@pytest.mark.slow
def test_the_live_view_and_the_log_of_a_vector_field_drawer(tmp_path):
    """The learned drawer (`drawer-vf`) on the simulated arm: pushed along the drawer's
    axis for 3 s, the live view draws the arm, the drawer's moving part at the reading
    the scene reports, the hand and the target, and the active state's field arrows at
    the drawer; then the same run from its `sctd log` file."""
    import threading

    from sctd.wire import Keys
    from sctd.wire.session import close_session, open_session
    from sctd_services.view.arm import ArmGeometry
    from sctd_services.view.live import LiveView
    from sctd_services.view.service import run_view
    from sctd_sim.robot import URDF_PATH
    from sctd_sim.view import stop_server, viser_server

    keys, ep = Keys("edan"), f"tcp/127.0.0.1:{free_port()}"
    skill = load_skill(SKILLS / "drawer-vf.yaml")
    sim = sctd("sim", "--task", "drawer", "--listen", ep, log=tmp_path / "sim.log")
    run = sctd("run", "--skill", str(SKILLS / "drawer-vf.yaml"), "--connect", ep, log=tmp_path / "run.log")
    logger = sctd("log", "--mcap", str(tmp_path / "drawer.mcap"), "--connect", ep, log=tmp_path / "log.log")
    ours, driver = open_session(connect=[ep]), open_session(connect=[ep])
    server = viser_server(0)
    view = LiveView(server, ArmGeometry(URDF_PATH), find_task("drawer"))
    stop, pushed = threading.Event(), threading.Event()
    threads = [threading.Thread(target=run_view, args=(ours, keys, view, stop), daemon=True),
               threading.Thread(target=_drive, args=(driver, keys, pushed, (0.6, 0.0, 0.0)), daemon=True)]
    state = skill.start
    try:
        threads[0].start()
        assert wait_for(lambda: view.skill_view is not None and view.handles["/arm/0"].visible, 60), \
            sim.output() + run.output()
        start = np.array(view.handles["/hand"].position)
        threads[1].start()
        assert wait_for(lambda: np.linalg.norm(view.handles["/hand"].position - start) > 0.05, 30), \
            run.output()
        pushed.set()
        threads[1].join(10)
        assert wait_for(lambda: "stopped" in view.person.content, 20), view.person.content
        stop.set()
        threads[0].join(10)
        with browser.open_viser(server, W, H) as page:
            page.wait_for_text(f"mode: {state}")
            page.set_camera(Camera(position=(1.0, -1.1, 0.9), look_at=(0.85, 0.0, 0.45), fov=0.8))
            save(page, "view-live-drawer-vf.png")
            assert view.arm is not None
            wrist = len(view.arm.links) - 4
            moving = next(p for p in view.parts if p.name.endswith("/moving"))
            meshes = {f"/arm/{wrist}": view.arm.links[wrist].vertices, moving.name: moving.vertices,
                      "/target": np.zeros((1, 3))}
            for name, vertices in meshes.items():
                h = view.handles[name]
                T = se3.transform_from_pose(np.r_[h.position, np.asarray(h.wxyz)[[1, 2, 3, 0]]])
                view.handles["/hand"].visible = name != "/target"
                drawn_where_projected(page, h, (T[:3, :3] @ vertices.T).T + T[:3, 3], radius=12)
            sv = view.skill_view
            T_obj = se3.transform_from_pose(np.r_[sv.root.position, np.asarray(sv.root.wxyz)[[1, 2, 3, 0]]])
            arrows = [n for n, node in sv.nodes.items() if node[0] == "arrows" and n.startswith(
                f"/skill/states/{state}/")]
            assert arrows, sorted(sv.nodes)
            origins = sv.nodes[arrows[0]][1]
            drawn_where_projected(page, sv.handles[arrows[0]], (T_obj[:3, :3] @ origins.T).T + T_obj[:3, 3])
    finally:
        stop.set()
        pushed.set()
        for t in threads:
            t.join(10)
        stop_server(server)
        close_session(ours)
        close_session(driver)
        assert logger.stop() == 0, logger.output()
        run.stop()
        sim.stop()
    replayed(tmp_path / "drawer.mcap", "drawer", skill, state, "view-log-drawer-vf.png",
             Camera(position=(1.0, -1.1, 0.9), look_at=(0.85, 0.0, 0.45), fov=0.8))


# -- from a log: the timeline scrubbed in the page -------------------------------------------
@pytest.mark.slow
def test_a_logs_slider_dragged_in_the_page_scrubs_the_view():
    """`sctd view --log`'s time slider, clicked in the page at three quarters of its
    track: the view draws the log at that time (the server's slider and what was drawn
    agree), with the hand where the log's state says, drawn there."""
    import threading

    from sctd_services.view.live import LiveView
    from sctd_services.view.timeline import Timeline, run_replay
    from sctd_sim.view import stop_server, viser_server
    from tests.test_view_live import _log

    skill = load_skill(SKILLS / "pour.yaml")
    timeline = Timeline(_log(skill.id), "sctd/edan")
    server = viser_server(0)
    view = LiveView(server, None, find_task("pour"))
    view.set_skill(skill)
    stop = threading.Event()
    thread = threading.Thread(target=run_replay, args=(view, timeline, stop), daemon=True)
    thread.start()
    try:
        assert wait_for(lambda: view.replay_slider is not None and view.drawn_at == 0.0, 10)
        with browser.open_viser(server, W, H) as page:
            track = page.page.locator(".mantine-Slider-trackContainer").first  # the Log folder's
            box = track.bounding_box()
            assert box is not None
            page.page.mouse.click(box["x"] + 0.75 * box["width"], box["y"] + box["height"] / 2)
            # off the slider, and not focused: its value label is not the scene's
            page.page.mouse.move(5, H - 5)
            page.page.evaluate("document.activeElement && document.activeElement.blur()")
            assert wait_for(lambda: abs(view.drawn_at - 0.75 * timeline.duration) < 0.1, 10), view.drawn_at
            assert view.replay_slider.value == view.drawn_at
            hand = np.asarray(timeline.at(view.drawn_at).pose[:3])
            assert np.allclose(view.handles["/hand"].position, hand)
            assert "mode: <b>approach</b>" in view.person.content  # the log's state after 1 s
            for part in view.parts:  # the bottle in the hand would change with the hand
                view.handles[part.name].visible = False
            page.set_camera(Camera(position=(0.75, -0.7, 0.95), look_at=(0.75, 0.0, 0.7), fov=0.8))
            axes = hand + np.vstack([np.zeros(3), 0.06 * np.eye(3)])  # the frame's origin and axes' ends
            drawn_where_projected(page, view.handles["/hand"], axes, radius=10)
    finally:
        stop.set()
        thread.join(10)
        stop_server(server)
