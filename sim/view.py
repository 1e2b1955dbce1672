"""Optional live view of the simulator in the browser (``sctd sim --view``), with Viser.

Viser (``pip install 'sctd[view]'``) is not a dependency of sctd. The view draws the
arm as spheres at its joint origins and the ee, linked by lines (the URDF carries no
meshes), and each scene object as a coordinate frame with a small box, at its full
pose (position and orientation).

Networking: the page and its websocket are served on ``127.0.0.1`` only, on the port
asked for, or on one the OS picks when the port is 0; :attr:`ViserView.url` says which.

Timing: drawing one frame (forward kinematics and three to five Viser messages) costs
about 0.5 ms of Python, and Viser's own thread then encodes and sends it. Done in the
1 kHz loop, that put the 99th percentile of the cycle at 1.0-1.4 ms (0.5-0.6 ms without
the view) and skipped cycles while a browser was connected. So :meth:`ViserView.update`,
called from the loop at about 30 Hz, only takes a snapshot (joint positions and object
poses, ~35 us) and wakes a drawing thread, which computes the joint origins in its own
Pinocchio workspace and sends the newest snapshot; the ones it had no time for are
dropped (newest wins). With it the cycle's percentiles stay those of the loop alone.

Meshcat is not supported: meshcat 0.3.2 (2021, its last release) serves its page with
tornado's ``app.listen(port)``, which binds every interface (0.0.0.0 and ::) and
takes no address, so it cannot be held to loopback.
"""

from __future__ import annotations

import contextlib
import importlib.util
import sys
import threading
from typing import Any

import numpy as np
import pinocchio as pin

from sctd import se3

HOST = "127.0.0.1"

_JOINT_RGB = (200, 200, 200)
_EE_RGB = (255, 140, 0)
_LINK_RGB = (90, 90, 90)
_OBJECT_RGB = (51, 102, 204)


class ViewerUnavailable(RuntimeError):
    """The view cannot be opened: viser is not installed, or the port is taken."""


def open_viewer(port: int = 0) -> ViserView:
    """A :class:`ViserView` serving on ``127.0.0.1:port`` (0: a free port).

    Raises
    ------
    ViewerUnavailable
        ``viser`` cannot be imported, or ``port`` is taken.
    """
    return ViserView(port)


def viser_server(port: int = 0) -> Any:
    """A ``viser.ViserServer`` on ``127.0.0.1:port`` (0: a free port), its banner on
    stderr (stdout stays for ``--json``).

    Raises
    ------
    ViewerUnavailable
        ``viser`` cannot be imported, or ``port`` is taken (viser would silently move
        on to the next free one).
    """
    if importlib.util.find_spec("viser") is None:
        raise ViewerUnavailable("needs the viser package: pip install 'sctd[view]' (or pip install viser)")
    import viser

    # Viser prints a banner (and "Server stopped") on stdout; its "Connection
    # opened/closed" lines are off (verbose=False).
    with contextlib.redirect_stdout(sys.stderr):
        server = viser.ViserServer(host=HOST, port=port, verbose=False)
    if port and server.get_port() != port:
        stop_server(server)
        raise ViewerUnavailable(f"port {port} on {HOST} is in use")
    return server


def stop_server(server: Any) -> None:
    """Stop a server of :func:`viser_server` (its port is free afterwards)."""
    with contextlib.redirect_stdout(sys.stderr):
        server.stop()


def wxyz_from_pose(pose) -> tuple[float, float, float, float]:
    """Viser's ``(w, x, y, z)`` from a pose ``[x, y, z, qx, qy, qz, qw]``."""
    return (float(pose[6]), float(pose[3]), float(pose[4]), float(pose[5]))


class ViserView:
    """Viser (browser) view of a :class:`~sctd_sim.simulation.Simulation`.

    A context manager: :meth:`close` stops the drawing thread and the server.

    Parameters
    ----------
    port : int, optional
        TCP port on 127.0.0.1; 0 lets the OS pick a free one.

    Attributes
    ----------
    url : str
        ``http://127.0.0.1:PORT``.
    port : int
        The port served.
    server : viser.ViserServer
    handles : dict
        Scene node -> Viser handle, once :meth:`setup` ran: ``/arm/spheres`` (joint
        origins, base first, then the ee), ``/arm/links``, ``/arm/ee`` (the ee frame)
        and ``/objects/<name>`` (each object's frame).
    error : Exception or None
        Why the drawing thread stopped, if it failed.
    """

    def __init__(self, port: int = 0) -> None:
        self.server = viser_server(port)
        self.port = self.server.get_port()
        self.url = f"http://{HOST}:{self.port}"
        self.handles: dict[str, Any] = {}
        self._cond = threading.Condition()
        self._wake = threading.Event()
        self._snapshot: tuple[int, np.ndarray, dict[str, list[float]]] | None = None
        self._posted = 0
        self._drawn = 0
        self._closing = False
        self._thread: threading.Thread | None = None
        self.error: BaseException | None = None

    # -- scene -------------------------------------------------------------------------
    def setup(self, sim) -> None:
        """Add the arm and ``sim``'s objects to the scene and start the drawing thread."""
        import trimesh

        arm = sim.arm.arm
        model = arm.model
        self._model = model
        self._data = model.createData()  # the drawing thread's own workspace
        self._ee = arm.ee_frame_id
        n = model.njoints + 1  # joint origins (the first is the base), then the ee
        # segments between each joint and its parent, and from the ee's joint to the ee
        ends = [(model.parents[i], i) for i in range(1, model.njoints)]
        ends.append((model.frames[arm.ee_frame_id].parentJoint, n - 1))
        self._ends = np.array(ends, dtype=int)
        self._points = np.zeros((n, 3))
        self._drawn_objects: dict[str, list[float]] = {}
        points = self._joint_points(sim.arm.dynamics.q)
        T_world_ee = sim.arm.T_world_ee
        objects = sim.objects()

        server = self.server
        server.initial_camera.position = (1.4, -1.2, 1.0)
        server.initial_camera.look_at = (0.4, 0.0, 0.3)
        scene = server.scene
        scene.add_grid("/floor", width=2.0, height=2.0, cell_size=0.1, section_size=0.5)
        h = self.handles
        # one node for all spheres: one message a frame instead of one per joint
        ball = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
        radii = np.full(n, 0.04)
        radii[-1] = 0.025
        colors = np.tile(np.array(_JOINT_RGB, dtype=np.uint8), (n, 1))
        colors[-1] = _EE_RGB
        h["/arm/spheres"] = scene.add_batched_meshes_simple(
            "/arm/spheres", ball.vertices, ball.faces, batched_wxyzs=np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)),
            batched_positions=points, batched_scales=radii, batched_colors=colors)
        h["/arm/links"] = scene.add_line_segments("/arm/links", points[self._ends], _LINK_RGB,
                                                  thickness=0.025)
        ee_pose = se3.pose_from_flat(se3.flat_from_transform(T_world_ee))
        h["/arm/ee"] = scene.add_frame("/arm/ee", axes_length=0.06, axes_radius=0.003,
                                       position=np.asarray(ee_pose[:3]), wxyz=wxyz_from_pose(ee_pose))
        for name, pose in objects.items():
            node = f"/objects/{name}"
            h[node] = scene.add_frame(node, axes_length=0.08, axes_radius=0.004,
                                      position=np.asarray(pose[:3]), wxyz=wxyz_from_pose(pose))
            scene.add_box(f"{node}/body", color=_OBJECT_RGB, dimensions=(0.06, 0.06, 0.02))
            scene.add_label(f"{node}/label", name, position=(0.0, 0.0, 0.05))
            self._drawn_objects[name] = pose
        self._thread = threading.Thread(target=self._draw_loop, name="sctd-view", daemon=True)
        self._thread.start()

    def update(self, sim) -> None:
        """Snapshot ``sim`` for the drawing thread (in the caller's thread; ~35 us)."""
        seq = self._posted + 1
        self._snapshot = (seq, sim.arm.dynamics.q.copy(), sim.objects())
        self._posted = seq
        self._wake.set()

    def wait_drawn(self, timeout: float = 5.0) -> bool:
        """Wait until the newest snapshot was sent to the scene; False on timeout."""
        with self._cond:
            self._cond.wait_for(lambda: self._drawn >= self._posted or self.error is not None
                                or self._closing, timeout)
            return self._drawn >= self._posted

    # -- drawing thread ----------------------------------------------------------------
    def _joint_points(self, q: np.ndarray) -> np.ndarray:
        """Joint origins, base first, then the ee, in world, shape (njoints + 1, 3)."""
        model, data, pts = self._model, self._data, self._points
        pin.forwardKinematics(model, data, q)
        for i in range(model.njoints):
            pts[i] = data.oMi[i].translation
        pts[-1] = pin.updateFramePlacement(model, data, self._ee).translation
        return pts

    def _draw(self, q: np.ndarray, objects: dict[str, list[float]]) -> None:
        h = self.handles
        points = self._joint_points(q)
        T_world_ee = self._data.oMf[self._ee]
        drawn = self._drawn_objects
        with self.server.atomic():
            h["/arm/spheres"].batched_positions = points
            h["/arm/links"].points = points[self._ends]
            ee = h["/arm/ee"]
            ee.position = T_world_ee.translation
            ee.wxyz = wxyz_from_pose(
                se3.pose_from_flat(se3.flat_from_transform(T_world_ee.homogeneous)))
            for name, pose in objects.items():
                if drawn.get(name) == pose:  # fixed objects cost nothing (viser's check: ~40 us)
                    continue
                node = h[f"/objects/{name}"]
                node.position = np.asarray(pose[:3])
                node.wxyz = wxyz_from_pose(pose)
                drawn[name] = pose

    def _draw_loop(self) -> None:
        while True:
            self._wake.wait()
            self._wake.clear()
            if self._closing:
                return
            snap = self._snapshot
            if snap is None:
                continue
            seq, q, objects = snap
            try:
                self._draw(q, objects)
            except Exception as e:  # a broken view must not take the simulator down
                print(f"sctd sim: view: drawing failed, the view stops updating: {e!r}",
                      file=sys.stderr, flush=True)
                with self._cond:
                    self.error = e
                    self._cond.notify_all()
                return
            with self._cond:
                self._drawn = seq
                self._cond.notify_all()

    # -- lifetime ----------------------------------------------------------------------
    def _stop_server(self) -> None:
        stop_server(self.server)

    def close(self) -> None:
        """Stop the drawing thread, then the server (the port is free afterwards)."""
        if self._closing:
            return
        self._closing = True
        self._wake.set()
        if self._thread is not None:
            self._thread.join(5.0)
        self._stop_server()

    def __enter__(self) -> ViserView:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
