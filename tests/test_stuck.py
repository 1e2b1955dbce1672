"""Stuck detection and escape, the pure parts (thesis Ch. 6.2): the detector's episodes,
each transition kind's progress, the engine's escape path."""

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sctd.skill import Bundle, SkillEngine, StuckDetector, load_skill, skill_from_bundle

ROOT = Path(__file__).resolve().parents[1]
STEP = 0.002  # m, the hyperplane's progress_step


def at(x, y=0.0, z=0.0):
    return (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, x, y, z)


def test_no_progress_for_stuck_after_is_one_episode_until_progress():
    d = StuckDetector(1.0)
    t = 0.0
    for _ in range(200):  # 2 s at the same value
        d.observe(t, 0, [0.0], [STEP])
        t += 0.01
    assert d.episodes == 1 and d.stuck and d.since == 0.0
    d.observe(t, 0, [0.5 * STEP], [STEP])  # noise-sized: still stuck
    assert d.stuck
    d.observe(t + 0.01, 0, [1.5 * STEP], [STEP])
    assert not d.stuck and d.episodes == 1


def test_moving_away_then_back_is_progress_from_the_lowest_point():
    d = StuckDetector(1.0)
    values = np.concatenate([np.linspace(0, -0.05, 80), np.linspace(-0.05, -0.04, 40)])
    for k, v in enumerate(values):
        d.observe(k * 0.01, 0, [float(v)], [STEP])
    assert d.episodes == 0  # 1.2 s, but it turned back towards the plane after 0.8 s


def test_release_state_change_and_no_watched_transition_restart_the_watch():
    d = StuckDetector(0.5)
    d.observe(0.0, 0, [0.0], [STEP])
    d.release()
    d.observe(0.4, 0, [0.0], [STEP])
    d.observe(0.8, 0, [0.0], [STEP])
    assert d.episodes == 0  # 0.4 s since the push resumed
    d.observe(0.9, 1, [0.0], [STEP])  # another state: a new watch
    d.observe(1.3, 1, [0.0], [STEP])
    assert d.episodes == 0
    assert not d.observe(5.0, 1, [], [])  # nothing to progress towards
    assert not d.observe(9.0, 1, [None], [STEP])  # a fresh watch after that
    # a guard not measurable now (a force without a sensor) shows no progress either
    assert d.observe(9.6, 1, [None], [STEP]) and d.episodes == 1
    assert StuckDetector(0.0).observe(0.0, 0, [0.0], [STEP]) is False
    with pytest.raises(ValueError, match="stuck_after"):
        StuckDetector(float("nan"))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-0.1, 0.1), min_size=2, max_size=300),
       st.floats(0.05, 1.0))
def test_an_episode_needs_stuck_after_without_any_step(values, stuck_after):
    """Invariant: when an episode starts at tick k, no value in the stuck_after window
    before it rose by more than the step above the lowest one before it; each episode
    counts once."""
    d = StuckDetector(stuck_after)
    dt = 0.01
    starts = []
    for k, v in enumerate(values):
        before = d.episodes
        d.observe(k * dt, 0, [v], [STEP])
        assert d.episodes - before in (0, 1)
        if d.episodes > before:
            starts.append(k)
            since = round(d.since / dt)
            window = values[since:k + 1]
            assert (k - since) * dt >= stuck_after - 1e-9
            low = window[0]
            for w in window[1:]:
                assert w <= low + STEP
                low = min(low, w)
    assert d.episodes == len(starts)


def test_progress_of_each_kind_grows_towards_firing():
    skill = load_skill(ROOT / "skills" / "pour.yaml")
    ws = SkillEngine(skill).workspace
    dist = skill.transitions[0]  # carry -> approach: tip below 0.15 of [0, 0, 0.08]
    far, near = at(0.3, 0, 0), at(0.1, 0, 0)
    assert dist.progress(near, 0, None, ws) > dist.progress(far, 0, None, ws)
    back = skill.transitions[1]  # approach -> carry: above
    assert back.progress(far, 0, None, ws) > back.progress(near, 0, None, ws)
    from sctd.skill import Button, Force, Hyperplane, Timeout

    h = Hyperplane(source="a", target="b", normal=np.array([0.0, 0.0, 1.0]), offset=-0.1)
    assert h.progress(at(0, 0, 0.05), 0, None, ws) == pytest.approx(-0.05)
    assert h.fires(at(0, 0, 0.11), 0, None, ws) and not h.fires(at(0, 0, 0.09), 0, None, ws)
    assert Timeout(source="a", target="b", after=1.0).progress(far, 0.5, None, ws) == 0.5
    f = Force(source="a", target="b", above=5.0, axis=np.array([0.0, 0.0, 1.0]))
    assert f.progress(far, 0, None, ws) is None and f.progress(far, 0, np.array([0, 0, 3.0]), ws) == 3.0
    b = Button(source="a", target="b", button=0)
    assert b.progress(far, 0, None, ws) is None and not np.isfinite(b.progress_step)


ESCAPE_YAML = """
sctd_skill: 1
name: chain
object: mug
fsm:
  start: a
  end: c
  min_dwell: 0.0
  transitions:
    - {from: a, to: b, type: hyperplane, normal: [1, 0, 0], offset: -0.1, margin: 0.0}
    - {from: b, to: a, type: hyperplane, normal: [-1, 0, 0], offset: 0.1, margin: 0.0}
    - {from: b, to: c, type: hyperplane, normal: [1, 0, 0], offset: -0.2, margin: 0.0}
    - {from: c, to: b, type: button, button: 2}
states:
  a: {input_mapping: [{type: linear, axes: [tx]}]}
  b: {input_mapping: [{type: linear, axes: [tx]}]}
  c: {input_mapping: [{type: linear, axes: [tx]}]}
"""


def test_escape_walks_the_path_back_and_a_button_transition_takes_precedence():
    e = SkillEngine(skill_from_bundle(Bundle("chain.yaml", ESCAPE_YAML, {})))
    assert not e.update(at(0.0), 0.0, pressed={2}, escape=2)  # start: nothing
    assert e.update(at(0.15), 0.1) and e.state == "b" and e.previous == "a"
    assert e.update(at(0.25), 0.2) and e.state == "c" and list(e.history) == [0, 1]
    # c has its own transition for button 2: that one acts (to b), not escape
    assert e.update(at(0.25), 0.3, pressed={2}, escape=2) and not e.escaped
    assert e.state == "b" and list(e.history) == [0]  # back the way it came
    assert e.update(at(0.25), 0.4, pressed={2}, escape=2) and e.escaped and e.state == "a"
    # a -> b is disarmed while the hand is still past it, re-armed once it is not
    assert not e.update(at(0.25), 0.5)
    assert not e.update(at(0.05), 0.6)
    assert e.update(at(0.15), 0.7) and e.state == "b"
    # the end state is not watched; b watches its two hyperplanes
    assert len(e.progress(at(0.15), 0.7)) == 2 and e.progress_steps == (STEP, STEP)
    e.reset(0.8, "c")
    assert e.progress(at(0.25), 0.8) == [] and e.previous is None
