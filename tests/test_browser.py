"""The browser harness (tests/browser.py), proved on a Viser scene in a real headless
Chromium: boxes are drawn at the pixels their world points project to, a dropdown picked
by clicks in the page changes what is drawn, and nothing of the browser outlives a test.

The projection and the missing-browser rule are checked in the fast tier; the tests
that start Chromium are ``slow``.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from tests import browser, tiers
from tests.browser import Camera
from tests.conftest import wait_for

RED_AT = (0.25, -0.15, 0.05)
BLUE_AT = (-0.2, 0.25, 0.05)
EMPTY_AT = (0.0, 0.0, 0.4)  # nothing there: background
CAMERA = Camera(position=(1.1, -1.4, 0.9), look_at=(0.0, 0.0, 0.05), fov=0.7)
SIZE = 0.06  # m: ~20 px across, so a pixel off by more than ~10 misses the box


def is_red(rgb: np.ndarray) -> bool:
    return bool(rgb[0] > 150 and rgb[1] < 80 and rgb[2] < 80)


def is_blue(rgb: np.ndarray) -> bool:
    return bool(rgb[2] > 150 and rgb[0] < 80 and rgb[1] < 80)


def is_background(rgb: np.ndarray) -> bool:
    return bool(np.all(rgb > 200))  # Viser's is white


# -- the projection (fast) ----------------------------------------------------------------
def test_project_puts_the_look_at_point_in_the_middle_and_the_fov_at_the_edges():
    position, look_at, up, fov, w, h = (3.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0, 0, 1), 0.8, 640, 480
    d = 3.0 * np.tan(fov / 2)  # half the height of the view at the look-at point
    points = [look_at, (0, 0, d), (0, 0, -d), (0, -d * w / h, 0), (0, d * w / h, 0), (4.0, 0, 0)]
    uv = browser.project(points, position, look_at, up, fov, w, h)
    expected = [(320, 240), (320, 0), (320, 480), (0, 240), (640, 240)]  # +y is on the right
    np.testing.assert_allclose(uv[:5], expected, atol=1e-9)
    assert np.all(np.isnan(uv[5])), "a point behind the camera has no pixel"
    assert browser.project(np.zeros((2, 3, 3)), position, look_at, up, fov, w, h).shape == (2, 3, 2)
    with pytest.raises(ValueError, match="up not along the view"):
        browser.project(points, position, look_at, (1, 0, 0), fov, w, h)


def test_a_missing_chromium_skips_naming_apt_and_fails_under_ci(monkeypatch, tmp_path):
    monkeypatch.setattr(browser, "CHROMIUM", tmp_path / "chromium")
    monkeypatch.delenv("CI", raising=False)
    with pytest.raises(pytest.skip.Exception, match="apt-get install chromium"):
        browser.require_chromium()
    monkeypatch.setenv("CI", "1")
    with pytest.raises(pytest.fail.Exception, match="apt-get install chromium"):
        browser.require_chromium()


# -- in the browser (slow) ----------------------------------------------------------------
def _children() -> set[int]:
    """The pids of this process's children (Playwright's driver among them)."""
    me = str(os.getpid())
    out = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[1] == me and fields[0] != "Z":
            out.add(int(stat.parent.name))
    return out


@pytest.fixture
def nothing_left():
    """The test leaves no Chromium process, and no child of this process, running."""
    chromium, children = browser.chromium_pids(), _children()
    yield
    assert not browser.chromium_pids() - chromium, "Chromium processes left"
    assert not _children() - children, "child processes left running"


@pytest.fixture
def scene(nothing_left):
    """A Viser server on 127.0.0.1 with a small red box and a blue one; stopped after.

    Lit by an ambient light alone, so each box is one flat colour on every face; no
    environment map (SwiftShader takes ~7 s over one)."""
    viser = tiers.needs("viser")
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        server.scene.configure_environment_map(hdri=None)
        server.scene.configure_default_lights(enabled=False)
        server.scene.add_light_ambient("/ambient", intensity=2.0)
        red = server.scene.add_box("/red", color=(255, 0, 0), dimensions=(SIZE,) * 3, position=RED_AT)
        blue = server.scene.add_box("/blue", color=(0, 0, 255), dimensions=(SIZE,) * 3, position=BLUE_AT)
        yield server, red, blue
    finally:
        server.stop()


def _pinhole(points: np.ndarray, camera) -> np.ndarray:
    """(u, v) of ``points`` by the pose the page reports (OpenCV: +z ahead, +y down)."""
    from viser import transforms

    R_world_camera = transforms.SO3(np.asarray(camera.wxyz)).as_matrix()
    p = (points - camera.position) @ R_world_camera
    f = camera.image_height / 2 / np.tan(camera.fov / 2)
    return f * p[:, :2] / p[:, 2:] + (camera.image_width / 2, camera.image_height / 2)


@pytest.mark.slow
def test_boxes_are_drawn_where_their_points_project(scene):
    server, _, _ = scene
    points = np.array([RED_AT, BLUE_AT, EMPTY_AT])
    with browser.open_viser(server, 800, 600) as view:
        view.set_camera(CAMERA)
        red_px, blue_px, empty_px = (tuple(p) for p in view.pixels(points))
        image = view.wait_for_image(lambda im: is_red(im[red_px]) and is_blue(im[blue_px]))
        assert image.shape == (600, 800, 3) and image.dtype == np.uint8
        assert is_background(image[empty_px]), image[empty_px]
        # the red drawn near the point is centred on it (a small cube's outline is
        # symmetric about its centre's projection)
        r, c = red_px
        near = image[r - 40:r + 41, c - 40:c + 41].astype(int)
        rows, columns = np.nonzero(near[..., 0] - near[..., 1:].max(axis=-1) > 100)
        assert abs(rows.mean() - 40) < 1.5 and abs(columns.mean() - 40) < 1.5, (rows.mean(), columns.mean())
        assert 0 < rows.min() and rows.max() < 80 and 0 < columns.min() and columns.max() < 80
        # the page draws with the camera it reports: three.js' projection of the pose we
        # set is the pinhole of the pose it sends back
        reported = view.client.camera
        assert (reported.image_width, reported.image_height) == (800, 600)
        c = CAMERA
        np.testing.assert_allclose(browser.project(points, c.position, c.look_at, c.up, c.fov, 800, 600),
                                   _pinhole(points, reported), atol=0.05)


@pytest.mark.slow
def test_a_dropdown_picked_by_clicks_switches_the_box_drawn(scene):
    server, red, blue = scene
    blue.visible = False
    choice = server.gui.add_dropdown("Box", ("red", "blue"), initial_value="red")
    shown = server.gui.add_markdown("Showing red")

    @choice.on_update
    def _(_) -> None:
        red.visible = choice.value == "red"
        blue.visible = choice.value == "blue"
        shown.content = f"Showing {choice.value}"  # last: once it shows, the boxes are sent

    with browser.open_viser(server) as view:
        view.set_camera(CAMERA)
        red_px, blue_px = (tuple(p) for p in view.pixels([RED_AT, BLUE_AT]))
        image = view.screenshot()
        assert is_red(image[red_px]) and is_background(image[blue_px])
        assert view.value_of("Box") == "red" and "Showing red" in view.text()

        view.choose("Box", "blue")
        assert wait_for(lambda: choice.value == "blue", 10)
        view.wait_for_text("Showing blue")
        assert view.value_of("Box") == "blue"
        view.settle()
        image = view.screenshot()
        assert is_blue(image[blue_px]) and is_background(image[red_px]), (image[blue_px], image[red_px])


@pytest.mark.slow
def test_the_browser_leaves_nothing_behind_even_when_the_test_fails(nothing_left):
    with pytest.raises(RuntimeError, match="the test failed"):
        with browser.open_page("about:blank", 320, 240) as page:
            folder, pids = page.folder, browser.processes_of(page.folder)
            assert folder.is_dir() and len(pids) >= 3, pids  # browser, renderer, GPU at least
            assert page.screenshot().shape == (240, 320, 3)
            raise RuntimeError("the test failed")
    assert not folder.exists()
    assert not browser.processes_of(folder)
