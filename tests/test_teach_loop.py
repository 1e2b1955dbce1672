"""`sctd teach --then-learn`: what the loop asks of the learner and which skill the daemon
starts on come from the task, not from a table of task names."""

from __future__ import annotations

from pathlib import Path

import pytest

from sctd.cli.teach_loop import LoopError, candidate_frames, start_skill
from sctd.task import find_task


def test_a_linear_request_names_the_held_outlet_as_the_tip_frame():
    """The bottle's tip where the pour's task file puts it, in the hand's frame, written
    as the learner's request reads it; a task whose hand holds nothing gives none."""
    assert candidate_frames(find_task("pour")) == ["tip=0,0,0.12,0,0,0,1"]
    assert candidate_frames(find_task("drawer")) == []


def test_the_daemon_starts_on_the_skill_named_as_the_task():
    """The hand-written skill named as the task; for a task nobody wrote one for, the
    first shipped skill on its object; none at all is an error naming the task."""
    assert start_skill("pour") == "pour" and start_skill("drawer") == "drawer"
    assert Path(start_skill("cabinet")).name == "cabinet-vf.yaml"
    with pytest.raises(LoopError, match="no skill named as the task 'juggle'"):
        start_skill("juggle")
