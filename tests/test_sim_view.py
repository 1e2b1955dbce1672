"""`sctd sim --view`: the Viser view follows the simulator and serves on 127.0.0.1 only.

Checked the way a browser sees it: the page over HTTP, and the scene a websocket
client receives on connecting (Viser's wire format: zstd-compressed msgpack). The
listening sockets are read from /proc/net, so a server bound to any other address
fails the test. viser is in the ``view`` extra that ``make setup`` installs; these
tests import it and fail, not skip, without it.
"""

from __future__ import annotations

import http.client
import math
import re
import signal
import socket
import threading
import time
from pathlib import Path

import msgspec
import numpy as np
import pytest
import viser
import zstandard
from websockets.sync.client import connect
from websockets.typing import Subprotocol

from sctd import se3
from sctd.task import find_task
from sctd.wire import Keys, codec
from sctd.wire.session import open_session
from sctd_sim import service
from sctd_sim.simulation import Simulation
from sctd_sim.view import ViewerUnavailable, ViserView, open_viewer, wxyz_from_pose
from tests.conftest import Proc, free_port, port_is_free, sctd, wait_for

URL = re.compile(r"view at (http://127\.0\.0\.1:(\d+))")


# -- a browser's view of the server ------------------------------------------------------
def listeners(port: int) -> list[str]:
    """Addresses with a TCP socket listening on ``port`` (IPv4 and IPv6, all processes)."""
    out = []
    for path, family in (("/proc/net/tcp", socket.AF_INET), ("/proc/net/tcp6", socket.AF_INET6)):
        if not Path(path).exists():
            continue
        for line in Path(path).read_text().splitlines()[1:]:
            local, state = line.split()[1], line.split()[3]
            addr, hex_port = local.split(":")
            if state == "0A" and int(hex_port, 16) == port:  # 0A: LISTEN
                raw = bytes.fromhex(addr)  # 32-bit words in host (little-endian) order
                raw = b"".join(raw[i:i + 4][::-1] for i in range(0, len(raw), 4))
                out.append(socket.inet_ntop(family, raw))
    return out


def get_page(port: int) -> tuple[int, bytes]:
    conn = http.client.HTTPConnection("127.0.0.1", port, timeout=10)
    try:
        conn.request("GET", "/")
        r = conn.getresponse()
        return r.status, r.read()
    finally:
        conn.close()


def _messages(frame: bytes) -> list[dict]:
    """Viser's frame: [u64 msgpack size][u64 compressed size][zstd(msgpack)][binary buffers]."""
    n_inner = int.from_bytes(frame[:8], "little")
    n_compressed = int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16:16 + n_compressed], max_output_size=n_inner)
    return msgspec.msgpack.decode(inner)["messages"]


def client_scene(port: int, timeout: float = 15.0) -> dict[str, dict]:
    """The scene a browser gets on connecting (Viser replays it): node name ->
    ``{"type", "position", "wxyz"}`` (newest values)."""
    nodes: dict[str, dict] = {}
    with connect(f"ws://127.0.0.1:{port}", subprotocols=[Subprotocol(f"viser-v{viser.__version__}")],
                 open_timeout=timeout, max_size=None, proxy=None) as ws:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            for m in _messages(ws.recv(timeout=max(0.1, end - time.monotonic()))):
                kind, name = m["type"], m.get("name")
                if kind == "ReplayDoneMessage":
                    return nodes
                if kind == "SetPositionMessage":
                    nodes.setdefault(name, {})["position"] = m["position"]
                elif kind == "SetOrientationMessage":
                    nodes.setdefault(name, {})["wxyz"] = m["wxyz"]
                elif name is not None and kind.endswith("Message"):
                    nodes.setdefault(name, {}).setdefault("type", kind)
    raise AssertionError(f"no end of the scene replay within {timeout} s")


def same_rotation(wxyz_a, wxyz_b, tol: float = 1e-6) -> bool:
    return abs(abs(float(np.dot(wxyz_a, wxyz_b))) - 1.0) < tol


@pytest.fixture(autouse=True)
def no_leaked_threads():
    before = set(threading.enumerate())
    yield
    assert wait_for(lambda: not (set(threading.enumerate()) - before), 10), \
        f"threads left running: {set(threading.enumerate()) - before}"


# -- in process --------------------------------------------------------------------------
def test_view_follows_the_sim_and_serves_on_loopback_only():
    with Simulation(scene=find_task("pour")) as sim:
        view = open_viewer(0)  # 0: the OS picks a free port
        port = view.port
        with view:
            assert view.url == f"http://127.0.0.1:{port}"
            assert listeners(port) == ["127.0.0.1"]  # neither 0.0.0.0 nor ::
            view.setup(sim)
            h = view.handles
            assert {"/arm/spheres", "/arm/links", "/arm/ee", "/objects/mug", "/objects/bottle_tip"} <= set(h)

            # tilt the bottle and lift it 10 cm; redraw every 33 cycles (30 Hz at 1 kHz)
            T = sim.arm.T_world_ee.copy()
            T_start = T.copy()
            T = T @ se3.transform_from_rt(se3.matrix_from_rotvec([0.6, 0.0, 0.0]), [0.0, 0.0, 0.0])
            T[2, 3] += 0.10
            sim.set_target(se3.pose_from_flat(se3.flat_from_transform(T)))
            for _ in range(30):
                sim.run(0.033)
                view.update(sim)
                assert view.wait_drawn(5), view.error
                T_world_ee = sim.arm.T_world_ee
                ee_pose = se3.pose_from_flat(se3.flat_from_transform(T_world_ee))
                np.testing.assert_allclose(h["/arm/ee"].position, T_world_ee[:3, 3], atol=1e-9)
                assert same_rotation(h["/arm/ee"].wxyz, wxyz_from_pose(ee_pose))
                spheres = h["/arm/spheres"].batched_positions  # float32: joints, then the ee
                np.testing.assert_allclose(spheres[-1], T_world_ee[:3, 3], atol=1e-6)
                np.testing.assert_allclose(h["/arm/links"].points[-1, 1], T_world_ee[:3, 3], atol=1e-6)
                for name, pose in sim.objects().items():
                    node = h[f"/objects/{name}"]
                    # viser keeps a position within np.allclose (rtol 1e-5) of the one it has:
                    # as the arm settles, the bottle tip moves less than that per frame
                    np.testing.assert_allclose(node.position, pose[:3], rtol=2e-5, atol=1e-8)
                    assert same_rotation(node.wxyz, wxyz_from_pose(pose)), name
            # the arm did move and turn, and the view with it
            T_now = sim.arm.T_world_ee
            assert np.linalg.norm(T_now[:3, 3] - T_start[:3, 3]) > 0.03
            turn = np.arccos(np.clip((np.trace(T_start[:3, :3].T @ T_now[:3, :3]) - 1.0) / 2.0, -1.0, 1.0))
            assert turn > 0.2, turn

            # what a browser gets: the page, and the scene as it is now
            status, body = get_page(port)
            assert status == 200 and b"<title>Viser</title>" in body
            seen = client_scene(port)
            ee = sim.arm.T_world_ee
            assert math.dist(seen["/arm/ee"]["position"], ee[:3, 3]) < 1e-9
            ee_pose = se3.pose_from_flat(se3.flat_from_transform(ee))
            assert same_rotation(seen["/arm/ee"]["wxyz"], wxyz_from_pose(ee_pose))
            tip = sim.objects()["bottle_tip"]
            assert math.dist(seen["/objects/bottle_tip"]["position"], tip[:3]) < 1e-5  # viser's allclose
            assert same_rotation(seen["/objects/bottle_tip"]["wxyz"], wxyz_from_pose(tip))
            assert seen["/arm/spheres"]["type"] == "BatchedMeshesMessage"
        assert wait_for(lambda: port_is_free(port), 5) and listeners(port) == []


def test_a_taken_port_is_refused_not_moved():
    """Viser silently takes the next port when the one asked for is busy; the view refuses."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(ViewerUnavailable, match=f"port {port} on 127.0.0.1 is in use"):
            ViserView(port)
    # the server viser had opened on another port is stopped: no_leaked_threads checks


def test_view_flags_are_checked(monkeypatch, capsys):
    assert service.main(["--view", "--view-port", "70000"]) == 2
    assert "--view-port: not a TCP port: 70000" in capsys.readouterr().err
    monkeypatch.setattr("importlib.util.find_spec", lambda name: None)
    with pytest.raises(ViewerUnavailable, match=r"pip install 'sctd\[view\]'"):
        open_viewer(0)


# -- as a real process -------------------------------------------------------------------
@pytest.mark.slow
def test_sctd_sim_view_prints_its_url_serves_the_moving_arm_and_stops_cleanly(tmp_path):
    """`sctd sim --scene pour --view`: the URL is printed, the page answers on 127.0.0.1
    only, the scene follows the arm driven over Zenoh, and SIGTERM stops it all."""
    zport = free_port()
    proc = sctd("sim", "--task", "pour", "--view", "--listen", f"tcp/127.0.0.1:{zport}",
                log=tmp_path / "sim.log")
    try:
        m = wait_for(lambda: URL.search(proc.output()), 60)
        assert m, proc.output()
        port = int(m.group(2))
        assert wait_for(lambda: "sctd sim: scene pour" in proc.output(), 30), proc.output()
        assert listeners(port) == ["127.0.0.1"]
        status, body = get_page(port)
        assert status == 200 and b"<title>Viser</title>" in body
        # the page can be served before the first frame draws the hand
        drawn = wait_for(lambda: client_scene(port).get("/arm/ee", {}).get("position"), 30)
        assert drawn, client_scene(port)
        z0 = drawn[2]

        with open_session(connect=[f"tcp/127.0.0.1:{zport}"]) as s:
            states: list[codec.StateMsg] = []
            sub = s.declare_subscriber(Keys("edan").state,
                                       lambda smp: states.append(codec.decode_state(smp.payload.to_bytes())))
            assert wait_for(lambda: states, 30), proc.output()
            p0 = list(states[-1].pose)
            goal = [p0[0], p0[1], p0[2] + 0.04, *p0[3:]]
            pub = s.declare_publisher(Keys("edan").target)
            for k in range(200):
                pub.put(codec.encode_target(k, time.time(), goal, "test", "test", -1))
                time.sleep(0.005)

            def drawn_where_reported():
                """The drawn hand where the simulator reports it (settled and holding;
                the view redraws at 30 Hz)."""
                seen = client_scene(port)["/arm/ee"]["position"]
                return seen if math.dist(seen, states[-1].pose[:3]) < 0.005 else None

            seen = wait_for(drawn_where_reported, 10) or client_scene(port)["/arm/ee"]["position"]
            pose = states[-1].pose
            sub.undeclare()
            pub.undeclare()
        assert math.dist(seen, pose[:3]) < 0.005, (seen, pose)  # the reported ee, drawn
        assert seen[2] - z0 > 0.02, (z0, seen, goal)  # it rose (to within ~1 cm of +4 cm)
    finally:
        rc = proc.stop()
    assert rc == 0, proc.output()
    assert "stopped after" in proc.output()
    assert port_is_free(port) and listeners(port) == []


@pytest.mark.slow
def test_view_port_option_and_sigint(tmp_path):
    """`--view-port P` serves on exactly 127.0.0.1:P; a second sim asking for P is refused
    (exit 2); SIGINT stops the first one cleanly and frees P."""
    port = free_port()
    args = ("--task", "pour", "--view", "--view-port", str(port))
    proc = Proc("sctd_sim.service", *args, "--listen", f"tcp/127.0.0.1:{free_port()}",
                log=tmp_path / "sim.log")
    try:
        assert wait_for(lambda: "sctd sim: scene pour" in proc.output(), 60), proc.output()
        assert f"view at http://127.0.0.1:{port}\n" in proc.output()
        assert listeners(port) == ["127.0.0.1"]
        assert get_page(port)[0] == 200

        second = Proc("sctd_sim.service", *args, "--listen", f"tcp/127.0.0.1:{free_port()}",
                      log=tmp_path / "second.log")
        try:
            assert second.p.wait(60) == 2, second.output()
        finally:
            second.stop()
        assert f"port {port} on 127.0.0.1 is in use" in second.output()
        assert proc.running()

        proc.p.send_signal(signal.SIGINT)
        assert proc.p.wait(20) == 0, proc.output()
    finally:
        proc.stop()
    assert "stopped after" in proc.output()
    assert port_is_free(port) and listeners(port) == []
