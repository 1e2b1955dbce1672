"""A person in a room of several tasks, with a skill set that guesses which one they
are going for (:mod:`sctd.runtime.goals`).

The person does not know about the inference: they do their task as they would with
teleoperation (:class:`~.agent.SimulatedUser`), and the display shows them which skill
is engaged and for which object. When it shows a skill for another object than the one
they are after, they notice it a reaction delay later, let go of the stick, and press
escape (button 2) until the display shows teleoperation again; then they carry on.
A skill for their own object they simply use, as they would a mode they did not ask
for (the user relearns what the stick does in it).
"""

from __future__ import annotations

import numpy as np

from .agent import SimulatedUser
from .intent import Observation

ZERO_BUTTONS = (0, 1, 0)
ESCAPE_BUTTONS = (0, 1, 1)


class SetUser:
    """:class:`~.agent.SimulatedUser` going for ``goal_object``'s task, escaping any other
    task's skill (module doc).

    Attributes
    ----------
    escapes : list of (float, float)
        Per wrong engagement escaped: when it was shown and when the user pressed.
    """

    def __init__(self, user: SimulatedUser, goal_object: str):
        self.user = user
        self.goal_object = goal_object
        self.profile = user.profile
        self.escapes: list[tuple[float, float]] = []
        self._wrong_since: float | None = None
        self._pressed_at: float | None = None

    @property
    def done(self) -> bool:
        return self.user.done

    def step(self, t: float, obs: Observation, engaged: str | None
             ) -> tuple[tuple[float, ...], tuple[int, int, int]]:
        """The stick and buttons at ``t``; ``engaged`` is the task object of the skill the
        display shows engaged (None: teleoperation)."""
        u, buttons = self.user.step(t, obs)  # (the person keeps seeing, and planning)
        if engaged is None or engaged == self.goal_object:
            self._wrong_since = self._pressed_at = None
            return u, buttons
        if self._wrong_since is None:
            self._wrong_since = t
        if t - self._wrong_since < self.profile.reaction_delay:
            return u, buttons  # not noticed yet
        zero = tuple(np.zeros(len(u)).tolist())
        if self._pressed_at is None:
            self._pressed_at = t
            self.escapes.append((self._wrong_since, t))
        # held for one of the user's update periods, released, pressed again if it did
        # not take (the display still shows the wrong skill)
        period = self.profile.update_period
        pressing = ((t - self._pressed_at) % (4 * period)) < period
        return zero, ESCAPE_BUTTONS if pressing else ZERO_BUTTONS
