"""sctd bench hostile's own measurement: a command's exit code, first line, whether it
quoted the file, and its own peak memory (not the bench's)."""

import pytest

from sctd.bench.hostile import MAX_RSS_MB, SECRET, map_files, run_command

pytestmark = pytest.mark.slow  # runs sctd commands as processes


def test_a_hostile_map_is_refused_by_the_command_without_quoting_it(tmp_path):
    files = dict(map_files(tmp_path))
    dup = run_command(["input", "keyboard", "--map", files["duplicate key (enable: 10, enable: null)"]])
    assert dup["exit"] == 2 and "duplicate key 'enable'" in dup["said"] and not dup["traceback"]
    assert 20 < dup["rss_mb"] <= MAX_RSS_MB
    shown = run_command(["input", "keyboard", "--map", files["a symlink to a file it should not show"]])
    assert shown["exit"] == 2 and not shown["quotes_content"] and SECRET not in shown["said"]
