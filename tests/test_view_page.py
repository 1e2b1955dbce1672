"""The skill's view as one HTML file (sctd_services.view.page), kept with the learner's
report: what is recorded in it (decoded as Viser's player reads it), and, in a real
headless Chromium opened from the disk, that it plays the states in turn and asks
nothing of any server."""

from __future__ import annotations

import base64
import json
import os
import re
from pathlib import Path

import pytest

from sctd.learn.demos import read_demos
from sctd.skill import load_skill
from sctd.skill.catalog import shipped_folder

viser = pytest.importorskip("viser")

from sctd_services.view.page import STATE_SECONDS, skill_page  # noqa: E402

SKILLS = shipped_folder()


def recording(html: str) -> tuple[float, list[tuple[float, dict]]]:
    """The scene recorded in a page: (its duration, [(time, message)])."""
    import msgspec
    import zstandard

    data = re.search(r'window\.__VISER_EMBED_DATA__="([^"]+)"', html)
    assert data is not None, "no scene in the page"
    raw = base64.b64decode(data.group(1))
    size = int.from_bytes(raw[:8], "little")
    inner = zstandard.ZstdDecompressor().decompress(raw[8:], max_output_size=size)
    n = int.from_bytes(inner[:8], "little")
    decoded = msgspec.msgpack.decode(inner[8:8 + n])
    return decoded["durationSeconds"], [(t, m) for t, m in decoded["messages"]]


def shown(messages: list[tuple[float, dict]], at: float) -> dict[str, bool]:
    """Each state's visibility at time ``at`` on the page's timeline."""
    out: dict[str, bool] = {}
    for t, m in messages:
        name = m.get("name") or ""
        state = re.fullmatch(r"/skill/states/\w+", name)
        if t <= at and m["type"] == "SetSceneNodeVisibilityMessage" and state:
            out[name.rsplit("/", 1)[1]] = m["visible"]
    return out


def test_the_page_plays_each_state_in_turn_with_the_demonstrations():
    skill = load_skill(SKILLS / "pour.yaml")
    duration, messages = recording(skill_page(skill, read_demos(SKILLS / "demos" / "pour")))
    names = [s.name for s in skill.states]
    assert duration == STATE_SECONDS * len(names)
    titles = [(t, m["updates"]["text"]) for t, m in messages
              if m.get("name") == "/skill/shown" and m["type"] == "SceneNodeUpdateMessage"]
    assert titles == [(STATE_SECONDS * k, f"pour: state {n} ({k + 1} of {len(names)})")
                      for k, n in enumerate(names)]
    for k, n in enumerate(names):  # one state at a time, the one the title names
        assert shown(messages, STATE_SECONDS * k + 0.5) == {m: m == n for m in names}
    drawn = {m.get("name") for _, m in messages}
    assert {f"/skill/demos/{k}/spikes" for k in range(10)} <= drawn  # the learner's outliers, apart
    assert {"/skill/states/pour/constraint0", "/skill/states/pour/constraint1"} <= drawn  # cone, box


def test_sctd_learn_report_has_the_page(tmp_path, capsys):
    from sctd.cli.main import main

    out, rep = tmp_path / "pour-linear.yaml", tmp_path / "report"
    assert main(["learn", str(SKILLS / "demos" / "pour"), "--method", "linear", "--out", str(out),
                 "--object", "mug", "--frame", "tip=0,0,0.12,0,0,0,1", "--report", str(rep), "--quiet"]) == 0
    summary = json.loads((rep / "summary.json").read_text())
    assert summary["view"] == "skill.html"
    _, messages = recording((rep / "skill.html").read_text())
    titles = [m["updates"]["text"] for _, m in messages if m.get("name") == "/skill/shown"
              and m["type"] == "SceneNodeUpdateMessage"]
    assert titles == ["pour-linear: state s0 (1 of 2)", "pour-linear: state s1 (2 of 2)"]
    assert "HTTP" not in capsys.readouterr().err  # nothing was served to anyone


@pytest.mark.slow
def test_the_page_opens_from_the_disk_and_asks_no_server(tmp_path):
    """Headless Chromium opens the file and plays it; paused in the first state and
    scrubbed by a click on the timeline into the second, it draws another scene; every
    request the page makes is for the file itself or data inside it."""
    import numpy as np

    from tests import browser
    from tests.conftest import wait_for

    path = tmp_path / "pour.html"
    path.write_text(skill_page(load_skill(SKILLS / "pour.yaml"), read_demos(SKILLS / "demos" / "pour")))
    requests: list[str] = []
    with browser.open_page(path.as_uri(), 900, 650) as page:
        p = page.page
        p.on("request", lambda r: requests.append(r.url))
        p.reload()
        browser._dismiss_notifications(p)  # software WebGL's, over the scene
        slider = p.locator("[role=slider]").first

        def now() -> float:
            return float(slider.get_attribute("aria-valuenow") or "nan")
        assert wait_for(lambda: 0.5 < now() < STATE_SECONDS - 1.0, 60), now()
        p.keyboard.press("Space")  # pause in the first state
        paused = now()
        first = page.screenshot()
        if os.environ.get("SCTD_VIEW_SHOTS"):  # docs/view.md's figure
            p.screenshot(path=str(Path(os.environ["SCTD_VIEW_SHOTS"]) / "view-report-page.png"))
        assert now() == paused and paused < STATE_SECONDS
        assert (first.min(axis=2) < 200).mean() > 0.01  # something is drawn
        box = p.locator(".mantine-Slider-trackContainer").first.bounding_box()  # the thumb has no size
        assert box is not None
        at = (STATE_SECONDS + 2.0) / (3 * STATE_SECONDS)  # in the second state
        p.mouse.click(box["x"] + box["width"] * at, box["y"] + box["height"] / 2)
        assert wait_for(lambda: STATE_SECONDS < now() < 2 * STATE_SECONDS, 30), now()
        changed = page.wait_for_image(
            lambda img: (np.abs(img.astype(int) - first.astype(int)).max(axis=2) > 40).mean() > 0.002)
        assert changed is not None
    assert requests and all(u.split(":", 1)[0] in ("file", "data", "blob") for u in requests), requests
