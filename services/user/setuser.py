"""A person in a room of several tasks, with a skill set that guesses which one they
are going for (:mod:`sctd.runtime.goals`).

The person does not know about the inference: they do their task as they would with
teleoperation (:class:`~.agent.SimulatedUser`), and the display shows them which skill
is engaged and for which object. When it shows a skill for another object than the one
they are after, they notice it a reaction delay later, let go of the stick, and press
escape (button 2) until the display shows teleoperation again; then they carry on.
A skill for their own object they simply use, as they would a mode they did not ask
for (the user relearns what the stick does in it).

A person may also **change their mind** (``detour``): they first go for another task,
and when they have reached its first step and let go (its ``step_pause``), decide for
their goal instead. Until then the other task's object is the one they are after (its
skill, engaged, they use); from then on it is their goal's, and a skill still engaged
for the other object is one to escape. It is one person: what they learned of the
device on the way (:class:`~.device.DeviceModel` per mode) they keep.
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

    Parameters
    ----------
    user : SimulatedUser
        The person going for their goal.
    goal_object : str
        The goal task's object.
    detour : SimulatedUser, optional
        The same person going for another task first (module doc); it takes ``user``'s
        models of the device.
    detour_object : str, optional
        That task's object.

    Attributes
    ----------
    escapes : list of (float, float)
        Per wrong engagement escaped: when it was shown and when the user pressed.
    changed_at : float or None
        When the person changed their mind (None: no detour, or not yet).
    """

    def __init__(self, user: SimulatedUser, goal_object: str, detour: SimulatedUser | None = None,
                 detour_object: str | None = None):
        if (detour is None) != (detour_object is None):
            raise ValueError("a detour needs both the other task's user and its object")
        self.user = user
        self.goal_object = goal_object
        self.detour = detour
        self.detour_object = detour_object
        if detour is not None:
            detour.models = user.models  # one person: one knowledge of the device
        self.profile = user.profile
        self.escapes: list[tuple[float, float]] = []
        self.changed_at: float | None = None
        self._reached: float | None = None  # when the detour's first step was reached
        self._wrong_since: float | None = None
        self._pressed_at: float | None = None

    @property
    def done(self) -> bool:
        return self.user.done

    @property
    def wanted(self) -> str:
        """The object of the task the person is going for now."""
        if self.detour_object is not None and self.changed_at is None:
            return self.detour_object
        return self.goal_object

    def step(self, t: float, obs: Observation, engaged: str | None
             ) -> tuple[tuple[float, ...], tuple[int, ...]]:
        """The stick and buttons at ``t``; ``engaged`` is the task object of the skill the
        display shows engaged (None: teleoperation)."""
        u, buttons = self._own_step(t, obs)  # (the person keeps seeing, and planning)
        if engaged is None or engaged == self.wanted:
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

    def _own_step(self, t: float, obs: Observation) -> tuple[tuple[float, ...], tuple[int, ...]]:
        """The person's stick and buttons for the task they are going for now; the change
        of mind once the detour's first step was reached and let go of."""
        d = self.detour
        if d is None or self.changed_at is not None:
            return self.user.step(t, obs)
        out = d.step(t, obs)
        if self._reached is None and d.intent.index > 0:  # past the first step
            self._reached = t
        if self._reached is not None and t - self._reached >= self.profile.step_pause:
            self.changed_at = t
        return out
