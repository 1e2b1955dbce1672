"""Every Zenoh config shipped in deploy/ is accepted by Zenoh's own parser, and the
loopback file says what the built-in defaults do."""

from pathlib import Path

import pytest
import zenoh

from sctd.runtime.zsession import HUB

DEPLOY = Path(__file__).resolve().parents[1] / "deploy" / "zenoh"


@pytest.mark.parametrize("path", sorted(DEPLOY.glob("*.json5")), ids=lambda p: p.name)
def test_zenoh_accepts_config(path):
    conf = zenoh.Config.from_file(str(path))
    assert "multicast" in conf.get_json("scouting")
    assert conf.get_json("scouting/multicast/enabled") == "false"


def test_loopback_file_matches_defaults():
    conf = zenoh.Config.from_file(str(DEPLOY / "loopback.json5"))
    assert HUB in conf.get_json("listen/endpoints") and HUB in conf.get_json("connect/endpoints")
