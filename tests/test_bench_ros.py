"""``sctd bench ros`` runs and reports what it measured (never judged by its figures:
they are the bench's to print)."""

from __future__ import annotations

import json

import pytest

from sctd.deploy.netns import last_json
from tests.conftest import require_namespaces, run_sctd
from tests.tiers import needs

# processes in a network namespace, at the wall clock's pace: beside another heavy test the
# daemon holds on stale state and the pushes measure its re-seeds
pytestmark = [pytest.mark.slow, pytest.mark.realtime]


def test_bench_ros_reports_the_round_trip_the_push_and_the_nodes_cpu_with_its_floor(tmp_path):
    require_namespaces()
    needs("rclpy")
    r = run_sctd("bench", "ros", "--steps", "3", "--rates", "100", "--json", "--logs", str(tmp_path),
                 timeout=400)
    assert r.returncode == 0, r.stderr[-3000:]
    got = json.loads(r.stdout)
    bare = got["bare_rclpy"]
    assert bare["round_trip_ms"]["n"] + bare["lost"] == 500 and bare["round_trip_ms"]["n"] > 400
    push = got["rates"]["100"]
    assert push["joy_to_target_ms"]["n"] == 3 and push["joy_to_target_ms"]["p50"] > 0  # every push moved it
    assert 0.0 < push["node_cpu"] < 2.0 and 0.0 <= push["floor_cpu"] < 2.0  # the idle rclpy node's, beside it
    assert 0.0 < push["follow_floor_cpu"] < 2.0 and push["cpu_seconds"] > 0  # the one that takes the target
    # the node saw the Joys and sent the targets (its own counts)
    counts = last_json((tmp_path / "ros-100.log").read_text())
    assert counts is not None
    assert counts["received"]["joy"] > 30 and counts["sent"]["target"] > 100, counts
    assert run_sctd("bench", "ros", "--rates", "0").returncode == 2
