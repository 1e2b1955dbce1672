"""A real headless Chromium for the tests of what the browser view (Viser) draws.

A helper module, not a test file. :func:`open_page` starts Debian's Chromium
(``apt-get install chromium``) under Playwright, on a fresh profile, and opens a page;
:func:`open_viser` opens a Viser server's page on top of it and hands back a
:class:`ViserPage`, which takes screenshots as arrays, sets the camera of its client
from the server, projects world points to the pixels they are drawn at (:func:`project`)
and works Viser's GUI by real clicks. Every test that uses it is ``slow`` (it starts
processes, ``docs/testing.md``).

Why Playwright rather than the DevTools protocol over a websocket of our own: it
starts Chromium on a pipe (no port to find, no ``DevToolsActivePort`` to poll), its
clicks wait until the element is visible, stable and the one that receives the
pointer (Mantine's option list fades in, in a portal, after the input is clicked), and
its screenshots wait for a fresh compositor frame. Its bundled driver drives Debian's
Chromium (``executable_path``); ``playwright install`` (a browser download) is not used.

Chromium runs as root in a container, so: ``--no-sandbox``; no GPU (``--disable-gpu``),
WebGL from SwiftShader (``--use-angle=swiftshader --enable-unsafe-swiftshader``:
Chromium 150 picks SwiftShader without them, they keep it so on a machine with a GPU);
no traffic of its own (``--disable-background-networking``, ``--disable-component-update``,
``--disable-sync``, ``--disable-quic``, ``--no-first-run``), which otherwise floods
refused connections on a closed network. ``HOME`` and ``TMPDIR`` are the browser's own
temporary folder, which also holds the profile: Chromium writes its caches, crash
database and temporary files there, not in the user's home or the system's temp folder,
and every process it starts names that folder on its command line, which is how
:func:`processes_of` finds them. That includes the crash handler, which Chromium starts
detached (parent pid 1) and which can outlive the browser by a moment (``--disable-
crashpad-for-testing`` would spare it, but with it Chromium 150 aborts every
navigation).
"""

from __future__ import annotations

import contextlib
import io
import os
import shutil
import signal
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tests import tiers

STARTED: list[Path] = []  # the folders of the browsers this process started
CHROMIUM = Path("/usr/bin/chromium")  # Debian's launcher script
FLAGS = (
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
)

# Viser's page at a fixed pixel ratio: its adaptive one lowers the resolution of a
# slowly drawn canvas (SwiftShader is slow), so screenshots would change over time.
VISER_QUERY = "?fixedDpr=1"

_WEBGL_PROBE = """() => {
  const gl = document.createElement("canvas").getContext("webgl2");
  if (!gl) return null;
  const info = gl.getExtension("WEBGL_debug_renderer_info");
  return info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
}"""

# Two animation frames: a frame that was asked for before this call has been drawn.
_TWO_FRAMES = "() => new Promise(r => requestAnimationFrame(() => requestAnimationFrame(r)))"


def unavailable(reason: str) -> None:
    """Skip the test for ``reason``, or fail it under CI (``CI`` set), where everything
    the browser tests need is installed (``.ci/run``)."""
    if os.environ.get("CI"):
        pytest.fail(reason, pytrace=False)
    pytest.skip(reason)


def require_chromium() -> Path:
    """The Chromium executable; skips (fails under CI) when it is not installed."""
    if not os.access(CHROMIUM, os.X_OK):
        unavailable(f"needs Chromium at {CHROMIUM}: apt-get install chromium")
    return CHROMIUM


def _sync_playwright() -> Any:
    try:
        from playwright.sync_api import sync_playwright
    except ModuleNotFoundError as exc:
        unavailable(tiers.skip_reason("dev", exc))
    return sync_playwright


def processes_of(folder: Path) -> list[int]:
    """The pids of the processes whose command line names ``folder`` (a browser's own
    temporary folder: every Chromium process it started)."""
    needle = os.fsencode(folder)
    pids = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            if needle in (entry / "cmdline").read_bytes():
                pids.append(int(entry.name))
        except OSError:  # it ended meanwhile
            pass
    return pids


def _end(folder: Path, seen: list[int], timeout: float = 10.0) -> None:
    """SIGKILL every process of ``folder`` that outlived its browser and wait until none
    runs (an ended process's command line is empty); then wait, ``timeout`` at most, until
    the processes ``seen`` are gone from the process table too.

    Those whose parent ended first (the crash handler, Chromium's zygotes) are ended but
    left to PID 1 to reap, which this machine's does within ~1.5 s; until then
    ``pgrep chromium`` lists them as ``<defunct>``.
    """
    end = time.monotonic() + timeout
    while pids := processes_of(folder):
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        if time.monotonic() > end:
            raise RuntimeError(f"Chromium processes {pids} of {folder} do not end")
        time.sleep(0.05)
    while any(os.path.exists(f"/proc/{pid}") for pid in seen) and time.monotonic() < end:
        time.sleep(0.05)


def chromium_pids() -> set[int]:
    """The live processes of the browsers this process started (:data:`STARTED`): those
    whose command line names one of their folders. Not every Chromium on the machine:
    another test process (a pytest-xdist worker) may be running its own meanwhile."""
    return {pid for folder in STARTED for pid in processes_of(folder)}


def rgb_from_png(png: bytes) -> np.ndarray:
    """An (H, W, 3) uint8 array from PNG bytes."""
    from PIL import Image  # pillow comes with matplotlib and viser (imageio)

    with Image.open(io.BytesIO(png)) as image:
        return np.asarray(image.convert("RGB"))


@dataclass
class BrowserPage:
    """A page of a headless Chromium (from :func:`open_page`).

    Attributes
    ----------
    page : playwright.sync_api.Page
        For anything this class does not do.
    folder : pathlib.Path
        The browser's temporary folder (its ``HOME`` and profile); removed on exit.
    renderer : str
        The WebGL renderer (SwiftShader).
    """

    page: Any
    folder: Path
    renderer: str

    def screenshot(self) -> np.ndarray:
        """The viewport as an (H, W, 3) uint8 RGB array."""
        return rgb_from_png(self.page.screenshot(type="png"))

    def wait_for_image(self, predicate: Callable[[np.ndarray], bool],
                       timeout: float = 20.0) -> np.ndarray:
        """The first screenshot that ``predicate`` accepts; AssertionError after
        ``timeout`` seconds, with the last one saved to a file it names."""
        end = time.monotonic() + timeout
        while True:
            image = self.screenshot()
            if predicate(image):
                return image
            if time.monotonic() > end:
                path = Path(tempfile.mkdtemp(prefix="sctd-screenshot-")) / "last.png"
                self.page.screenshot(path=str(path))
                raise AssertionError(f"no screenshot matched in {timeout} s; the last: {path}")

    def text(self) -> str:
        """The text the page shows."""
        return str(self.page.inner_text("body"))

    def wait_for_text(self, text: str, timeout: float = 10.0) -> None:
        """Wait until ``text`` is shown (a part of an element's text)."""
        self.page.get_by_text(text).first.wait_for(state="visible", timeout=timeout * 1000)


@contextlib.contextmanager
def open_page(url: str, width: int = 800, height: int = 600,
              timeout: float = 30.0, client_certificates: list[dict] | None = None,
              load: bool = True) -> Iterator[BrowserPage]:
    """Start headless Chromium on a fresh profile and open ``url`` in a viewport of
    ``width`` x ``height`` CSS pixels (one device pixel each). With
    ``client_certificates`` (Playwright's: origin, certPath, keyPath) the browser presents
    them and takes the server's certificate from a private CA (sctd certs'); ``load``
    False: the caller opens the page.

    On exit (an exception included) the browser is closed, any process of it that is
    left is killed, and its temporary folder removed. Skips the test (fails it under
    CI) when Chromium or Playwright is not installed; RuntimeError when the browser
    has no WebGL.
    """
    chromium = require_chromium()
    sync_playwright = _sync_playwright()
    folder = Path(tempfile.mkdtemp(prefix="sctd-chromium-"))
    STARTED.append(folder)
    seen: list[int] = []
    try:
        with sync_playwright() as pw:
            context = pw.chromium.launch_persistent_context(
                folder / "profile", executable_path=str(chromium), headless=True,
                args=list(FLAGS), env={**os.environ, "HOME": str(folder), "TMPDIR": str(folder)},
                viewport={"width": width, "height": height}, device_scale_factor=1,
                timeout=timeout * 1000,
                **({} if client_certificates is None else
                   {"client_certificates": client_certificates, "ignore_https_errors": True}))
            try:
                page = context.pages[0] if context.pages else context.new_page()
                page.set_default_timeout(timeout * 1000)
                renderer = page.evaluate(_WEBGL_PROBE)
                if renderer is None:
                    raise RuntimeError(f"Chromium ({chromium} {' '.join(FLAGS)}) has no WebGL")
                if load:
                    page.goto(url)
                yield BrowserPage(page, folder, renderer)
            finally:
                seen = processes_of(folder)
                context.close()
    finally:
        _end(folder, seen)
        shutil.rmtree(folder, ignore_errors=True)


# -- sctd's pages driven by the simulated user -----------------------------------------------
def keyboard_injector(page: Any) -> Callable[[Any, Any], None]:
    """``inject(u, buttons)`` for a page of ``sctd try`` or ``sctd study run``: holds the
    keys (``docs/try.md``) that say ``u`` (an axis past 0.3 is a full press), the deadman
    (Shift, ``buttons[1]``) and mode (``m``, ``buttons[0]``), releasing the others."""
    down: set[str] = set()
    keys = (("ArrowRight", "ArrowLeft"), ("ArrowUp", "ArrowDown"), ("w", "s"))

    def inject(u: Any, held: Any) -> None:
        want = {"Shift"} if held[1] else set()
        want |= {plus if x > 0 else minus for (plus, minus), x in zip(keys, u, strict=False) if abs(x) > 0.3}
        if held[0]:
            want.add("m")
        for key in sorted(down - want):
            page.keyboard.up(key)
        for key in sorted(want - down):
            page.keyboard.down(key)
        down.clear()
        down.update(want)

    return inject


def drive_as_user(hub: str, task: Any, seed: int, inject: Callable[[Any, Any], None],
                  ended: Callable[[], bool]) -> None:
    """Drive a trial of ``task`` from ``seed`` as the simulated user of ``sctd eval`` (the
    person it uses in real time), reading the arm over Zenoh at ``hub`` and handing its
    stick and buttons to the page by ``inject(u, buttons)`` at the person's 100 Hz, until
    ``ended()`` (asked every 25 steps: each ask is a round trip into the page); then
    everything released. When the daemon's status says the page's device must centre
    its stick (its input went stale: a page that missed its timer), it does."""
    from sctd.wire.session import session
    from sctd_services.simulated_user import UserClient
    from sctd_services.user import SimulatedUser

    user = SimulatedUser(task, 3, "steady", seed=seed)
    with session(connect=[hub]) as s, UserClient(s, user, device="test-unused") as client:
        period, due = 0.01, time.monotonic()
        step = 0
        while step % 25 != 0 or not ended():
            obs = client.observation()
            if obs is not None:
                u, buttons = user.step(obs.t, obs)
                inject((0.0, 0.0, 0.0) if client.told_to_centre("browser") else u, buttons)
            due += period
            time.sleep(max(0.0, due - time.monotonic()))
            step += 1
    inject((0.0, 0.0, 0.0), (0, 0, 0))


# -- Viser --------------------------------------------------------------------------------
def project(points_world: Any, position: Any, look_at: Any, up: Any, fov: float,
            width: int, height: int) -> np.ndarray:
    """Where three.js draws world points: the pixel coordinates ``(u, v)`` of a
    ``PerspectiveCamera`` at ``position`` that ``lookAt``s ``look_at`` with ``up``.

    Parameters
    ----------
    points_world : array_like, shape (..., 3)
    position, look_at, up : array_like, shape (3,)
        The camera, as Viser's ``client.camera`` has them (world frame).
    fov : float
        Vertical field of view (rad), Viser's ``camera.fov``.
    width, height : int
        The canvas (px); the aspect ratio is ``width / height``.

    Returns
    -------
    numpy.ndarray, shape (..., 2)
        ``u`` from the canvas' left edge, ``v`` from its top edge, in pixels: the
        point is in pixel ``(floor(v), floor(u))``. NaN for a point not in front of
        the camera.

    Notes
    -----
    three.js' camera looks along its -z axis with +y up: ``z_c = (position -
    look_at) / |.|``, ``x_c = up x z_c / |.|``, ``y_c = z_c x x_c``. A point at ``p_c =
    R_world_camera^T (p - position)`` has normalised device coordinates ``x_n = f
    x_c / (a d)``, ``y_n = f y_c / d`` with depth ``d = -z_c``, ``f = 1 / tan(fov / 2)``
    and ``a = width / height``; the viewport maps them to ``u = (x_n + 1) width / 2``,
    ``v = (1 - y_n) height / 2``.
    """
    p = np.asarray(points_world, dtype=float)
    eye = np.asarray(position, dtype=float)
    z = eye - np.asarray(look_at, dtype=float)
    x = np.cross(np.asarray(up, dtype=float), z)
    if np.linalg.norm(z) == 0.0 or np.linalg.norm(x) == 0.0:
        raise ValueError("the camera needs look_at != position and up not along the view")
    z /= np.linalg.norm(z)
    x /= np.linalg.norm(x)
    R_world_camera = np.stack([x, np.cross(z, x), z], axis=1)
    p_camera = (p - eye) @ R_world_camera
    depth = -p_camera[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        f = 1.0 / np.tan(fov / 2.0)
        x_ndc = np.where(depth > 0, f * p_camera[..., 0] / depth / (width / height), np.nan)
        y_ndc = np.where(depth > 0, f * p_camera[..., 1] / depth, np.nan)
    return np.stack([(x_ndc + 1.0) * width / 2.0, (1.0 - y_ndc) * height / 2.0], axis=-1)


@dataclass(frozen=True)
class Camera:
    """A camera pose as Viser sets it (world frame; ``fov`` vertical, in rad)."""

    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    fov: float = np.pi / 4


def _same_direction(a: Any, b: Any) -> bool:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return bool(np.allclose(a / np.linalg.norm(a), b / np.linalg.norm(b), atol=1e-4))


def _reports(camera: Any, want: Camera) -> bool:
    """Whether a camera the client reported is ``want``."""
    return bool(np.allclose(camera.position, want.position, atol=1e-4)
                and np.allclose(camera.look_at, want.look_at, atol=1e-4)
                and _same_direction(camera.up_direction, want.up)
                and abs(camera.fov - want.fov) < 1e-4)


@dataclass
class ViserPage(BrowserPage):
    """A Viser server's page (from :func:`open_viser`), with its client on the server.

    Attributes
    ----------
    client : viser.ClientHandle
        The server's handle of this page.
    camera : Camera or None
        The pose :meth:`set_camera` set last.
    """

    client: Any
    camera: Camera | None = None

    def settle(self, timeout: float = 10.0) -> None:
        """Return once the page has applied every message the server queued before the
        call and drawn a frame since.

        The client handles messages in order, each frame; its answer to a request made
        now (a read of its local storage, which changes nothing) comes after all of
        them. The frame that shows them is asked for when they are applied and drawn
        within the next two animation frames.
        """
        self.client.local_storage.get_item("sctd-tests-settle", timeout=timeout)
        self.page.evaluate(_TWO_FRAMES)

    def set_camera(self, camera: Camera, timeout: float = 10.0) -> None:
        """Put the page's camera at ``camera`` and wait until the page reports it
        back (and drew a frame with it). Raises TimeoutError if it does not.

        Viser's setters move the page's orbit controls: ``up_direction``, then
        ``position`` (which moves ``look_at`` along), then ``look_at`` and ``fov``. The
        callback that waits for the report stays registered (Viser cannot remove one),
        idle once it saw it.
        """
        taken = threading.Event()

        def on_update(reported: Any) -> None:  # in viser's thread pool
            if not taken.is_set() and _reports(reported, camera):
                taken.set()

        self.client.camera.on_update(on_update)
        with self.client.atomic():
            cam = self.client.camera
            cam.up_direction = camera.up
            cam.position = camera.position
            cam.look_at = camera.look_at
            cam.fov = camera.fov
        if not taken.wait(timeout):
            cam = self.client.camera
            raise TimeoutError(f"the page did not take the camera {camera} in {timeout} s; it "
                               f"reports {cam.position}, {cam.look_at}, {cam.up_direction}, {cam.fov}")
        self.camera = camera
        self.settle(timeout)

    def canvas_box(self) -> tuple[float, float, float, float]:
        """Viser's 3D canvas in the viewport: ``(left, top, width, height)``, CSS px."""
        box = self.page.locator("canvas[data-engine^='three.js']").bounding_box()
        return box["x"], box["y"], box["width"], box["height"]

    def pixels(self, points_world: Any) -> np.ndarray:
        """Where the points are drawn in :meth:`screenshot`: integer ``(row, column)``
        pairs, shape (..., 2), with the camera of the last :meth:`set_camera`."""
        if self.camera is None:
            raise RuntimeError("set_camera first: the pixels depend on the camera")
        left, top, width, height = self.canvas_box()
        c = self.camera
        uv = project(points_world, c.position, c.look_at, c.up, c.fov, round(width), round(height))
        return np.floor(uv[..., ::-1] + (top, left)).astype(int)

    def panel_box(self) -> tuple[float, float, float, float] | None:
        """Viser's GUI panel over the scene, ``(left, top, width, height)`` CSS px, or
        None when there is none (its scroll bar and a focused input's label change
        the pixels there: not the scene's)."""
        panel = self.page.get_by_text("Connected", exact=True).locator(
            "xpath=ancestor::div[contains(@class, 'mantine-Paper-root')][1]")
        if panel.count() == 0:
            return None
        box = panel.first.bounding_box()
        return None if box is None else (box["x"], box["y"], box["width"], box["height"])

    def choose(self, label: str, option: str) -> None:
        """Pick ``option`` in the GUI dropdown labelled ``label`` with clicks: the
        input (a Mantine Select), then the option in the list it opens."""
        self.page.get_by_label(label, exact=True).click()
        self.page.get_by_role("option", name=option, exact=True).click()
        self.page.get_by_role("listbox").wait_for(state="hidden")

    def value_of(self, label: str) -> str:
        """What the GUI input labelled ``label`` shows."""
        return str(self.page.get_by_label(label, exact=True).input_value())


def _dismiss_notifications(page: Any) -> None:
    """Close Viser's notifications: it shows one for software WebGL, over the scene, when
    the page mounts (before its websocket connects)."""
    from playwright.sync_api import expect

    notes = page.locator(".mantine-Notification-root")
    while n := notes.count():
        notes.first.locator(".mantine-Notification-closeButton").click()
        expect(notes).to_have_count(n - 1)


@contextlib.contextmanager
def open_viser(server: Any, width: int = 800, height: int = 600,
               timeout: float = 30.0) -> Iterator[ViserPage]:
    """Open the page of a ``viser.ViserServer`` (on 127.0.0.1) in :func:`open_page`, wait
    until it connected and drew the scene, and close Viser's notifications.

    Viser counts a page as connected once it reported its camera, so the canvas exists
    by then. The browser is closed on exit; stopping the server is the caller's.

    Viser's default lighting includes an HDRI environment map, which SwiftShader takes
    about 7 s to prepare before the first frame that shows it: a test's scene turns it
    off (``server.scene.configure_environment_map(hdri=None)``) unless it is the subject.
    """
    before = set(server.get_clients())
    url = f"http://127.0.0.1:{server.get_port()}/{VISER_QUERY}"
    with open_page(url, width, height, timeout) as page:
        end = time.monotonic() + timeout
        while not (new := set(server.get_clients()) - before):
            if time.monotonic() > end:
                raise TimeoutError(f"{url} did not connect to the server in {timeout} s")
            time.sleep(0.05)
        view = ViserPage(page.page, page.folder, page.renderer, server.get_clients()[new.pop()])
        view.page.get_by_text("Connected", exact=True).wait_for()
        _dismiss_notifications(view.page)
        view.settle(timeout)
        yield view
