"""Telling when the user is stuck in a state (thesis Ch. 6.2): detection only.

"The end-effector could be stuck, without the possibility to transition further": the
user pushes, but the measured pose comes no closer to any of the active state's
transitions (a wall, a mapping that cannot move across the plane, an offset bound).
:class:`StuckDetector` watches, tick by tick, whether the input is held and whether
any transition's :meth:`~sctd.skill.transitions.Transition.progress` has grown by its
kind's ``progress_step`` since its lowest value; after ``stuck_after`` seconds without
such a step it reports one stuck episode, which lasts until the input is released, a
step is made or the state changes. It never changes a command; the way out is the
escape button (:meth:`sctd.skill.SkillEngine.escape`). No clocks: time is passed in.
"""

from __future__ import annotations

import math
from collections.abc import Sequence


class StuckDetector:
    """Stuck episodes of one running skill.

    Parameters
    ----------
    stuck_after : float
        Seconds of held input without progress that make an episode; 0 (or inf) never
        does.

    Attributes
    ----------
    episodes : int
        Episodes so far (each counted once, when it starts).
    since : float or None
        When the running episode's last progress was (s); None when not stuck.
    """

    period = 0.01  # s between observations: progress is mm over tens of ms, not per tick

    def __init__(self, stuck_after: float):
        if not stuck_after >= 0.0:  # NaN fails too
            raise ValueError(f"stuck_after: expected a number >= 0, got {stuck_after!r}")
        self.stuck_after = stuck_after
        self.episodes = 0
        self.since: float | None = None
        self._state = -1  # the state index the watch is for
        self._start: float | None = None  # the last progress (or the start of the push)
        self._low: list[float | None] = []  # each transition's lowest progress since then
        self._due = -math.inf  # the next observation's time

    @property
    def stuck(self) -> bool:
        return self.since is not None

    def due(self, now: float) -> bool:
        """Whether a held tick at ``now`` is to be observed (at most one each
        :attr:`period`, the first of a push at once): the caller skips measuring the
        progress in between."""
        return self.stuck_after > 0.0 and now >= self._due

    def release(self) -> None:
        """The input is not held (or the pose is not known): no watch, no episode."""
        self._start = None
        self.since = None
        self._due = -math.inf

    def observe(self, now: float, state: int, progress: Sequence[float | None],
                steps: Sequence[float]) -> bool:
        """One tick with the input held. Returns whether the user is stuck now.

        Parameters
        ----------
        now : float
            Monotonic time (s).
        state : int
            The active state's index (a change restarts the watch).
        progress : sequence of float or None
            The active state's watched transitions' progress values (None: not
            measurable now); an empty sequence is a state with nothing to progress
            towards, never stuck.
        steps : sequence of float
            Each one's ``progress_step``, the growth that counts as progress.
        """
        if not progress or self.stuck_after == 0.0:
            self.release()
            return False
        self._due = now + self.period
        if state != self._state or self._start is None or len(progress) != len(self._low):
            self._state, self._start, self._low = state, now, list(progress)
            self.since = None
            return False
        moved = False
        low = self._low
        for i, (p, step) in enumerate(zip(progress, steps, strict=True)):
            if p is None:
                continue
            lo = low[i]
            if lo is None or p < lo:
                low[i] = p
            elif p > lo + step:
                moved = True
        if moved:
            self._start, self._low = now, list(progress)
            self.since = None
            return False
        if self.since is None and now - self._start >= self.stuck_after:
            self.since = self._start
            self.episodes += 1
        return self.since is not None
