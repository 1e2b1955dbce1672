"""The simulated user: a task's intent, a learned model of the device, human limits.

The user knows the task (its file's intent, :mod:`.intent`) and what a person in the
chair is shown of the skill: the name of the active mode (state) and the number of
input axes. It knows nothing of mappings, fields or constraints. It learns how the
stick moves the hand in each mode from the robot's response to its own inputs
(:mod:`.device`): trying each axis in a mode it has not seen, then choosing at every
correction the input whose predicted motion comes closest to what the intent wants,
and updating the model from what the hand then did; when that stops bringing it closer
for a while, it tries the stick out again, or, when it is as close as the task needs
(within the step's ``accept`` region: the bottle's opening inside the mug's rim), goes
on to the next step; so it does at once when the display shows a mode it did not
press for while it is that close (within MOVED_ON_WINDOW of the change: the template
has moved on, a pour state; an earlier change, far from the sub-goal, is no such cue). Where the
current mode cannot produce the wanted motion, or nothing of its most wanted part, for
a while it lets go and tries the mode switch (button 0), as a person who knows the
device has modes, unless the display says the button changes nothing in this mode
(``status.mode_button``); if pressing it changes nothing, it stops trying. While the hand
presses against a surface (a wall, a button) the hand's motion shows the surface, not
the stick: the user neither learns from it nor tries the stick out there. Nor does it
learn from a push held on against a stop of the skill's (the hand not going the way it
wishes though its model promised it would: :meth:`SimulatedUser._stopped`).
Its limits (:mod:`.human`): it acts on what it saw a reaction delay ago, changes the
stick only every update period, its deflections are noisy and never smaller than its
dead zone, and a mode switch costs it time with the stick released.

A *practised* user (``known``) starts with what it learned of the device in earlier
runs, a model per mode it has used, as the participants of a user study who are
trained on every condition before they are measured. It needs no trial pushes in a
mode it knows, and keeps learning from the hand's motion as before.
"""

from __future__ import annotations

import copy
import math
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sctd import se3
from sctd.task import Task
from sctd.task.kinds import StepKind

from .device import DelayedDeviceModel, DeviceModel
from .grasping import GraspButton
from .human import DEFAULT_MODEL, PROFILES, USER_MODELS, HumanProfile, UserModel
from .intent import Desire, Observation, TaskIntent

Array = NDArray[np.float64]
Device = DeviceModel | DelayedDeviceModel  # what the person learns of one mode
PROBE = 0.6  # deflection of a trial push
PROGRESS = 0.003  # decrease of the intent's error that counts as getting closer
LACKING = 0.9  # a mode that leaves this much of the most wanted part undone cannot give it
SMALL_WISH = 0.2  # a wish this small (a share of full speed) is no reason to switch modes
REPROBE_AFTER = 2.0  # s without getting closer before the user tries the stick out again
TRY_AT_ONCE = 1.0  # s into a sub-goal within which a mode that cannot give it is tried out at once
MOVED_ON_WINDOW = 0.5  # s after an unasked mode change in which being close enough ends the sub-goal
STOPPED = 0.2  # the motion along the wish this small a share of what the model promised: a stop
HELD_ON = 0.9  # cosine between two pairs' pushes that counts as the same push held on
NOTICEABLE = 0.05  # a promised motion a person expects to see (as the intent weighs it: 5 mm/s, 0.03 rad/s)


def twist_between(T_a: Array, T_b: Array, dt: float) -> Array:
    """World-frame twist [v, w] that takes pose T_a to T_b in ``dt`` seconds."""
    v = (T_b[:3, 3] - T_a[:3, 3]) / dt
    w = se3.rotvec_from_matrix(T_b[:3, :3] @ T_a[:3, :3].T) / dt
    return np.concatenate([v, w])


@dataclass
class _Switch:
    start: float
    mode: str  # the mode shown when the switch was pressed


class SimulatedUser:
    """Steps a simulated person: observations in, stick deflections and buttons out.

    Parameters
    ----------
    task : Task
        The task (its file's intent is what the user wants).
    n_axes : int
        Input axes of the device (what the display says).
    profile : HumanProfile or str
    seed : int
        Noise seed.
    known : mapping of str to DeviceModel, optional
        What a practised user knows of the device (module doc): a model per displayed
        mode, copied, and learned further in this run.
    model : UserModel or str
        How they learn a mode (:data:`~.human.USER_MODELS`): ``plain`` pairs each motion
        with the stick held at the same moments, ``adaptive`` learns the delay too.
    """

    def __init__(self, task: Task, n_axes: int = 3, profile: HumanProfile | str = "steady",
                 seed: int = 0, known: Mapping[str, Device] | None = None,
                 model: UserModel | str = DEFAULT_MODEL):
        self.task = task
        self.intent = TaskIntent(task)
        self.n = n_axes
        self.profile = PROFILES[profile] if isinstance(profile, str) else profile
        self.model = USER_MODELS[model] if isinstance(model, str) else model
        self.rng = np.random.default_rng(seed)
        self.models: dict[str, Device] = {m: copy.deepcopy(d) for m, d in (known or {}).items()}
        self._seen: deque[Observation] = deque()
        self._history: deque[tuple[float, Array]] = deque()  # (time, output) as applied
        self._last_push = np.zeros(n_axes)  # the stick held over the last pair learned from
        self._perceived: Observation | None = None
        self._next = 0.0
        self._out = np.zeros(n_axes)
        self._buttons = (0, 1, 0)
        self._probes: dict[str, list[Array]] = {}
        self._switch: _Switch | None = None
        self._bad_since: float | None = None
        self._mode_since = 0.0
        self._mode = ""
        # the sub-goal during which the mode changed unasked, and when the user saw it
        self._moved_on: tuple[str, float] | None = None
        self.switch_works: bool | None = None  # unknown until tried
        self._best_error = np.inf  # the intent's error at its best since the last re-try
        self._improved = 0.0  # when it last got better
        self._phase = ""
        self._pause_phase: str | None = None  # the step the last pause was for
        self._pause_until = -math.inf
        self.reprobes = 0
        self._tried_for: str | None = None  # the sub-goal the stick was last tried out for, unable
        self._sub_goal: tuple[str, float] = ("", 0.0)  # the intent's step now, and since when
        self.settled = 0  # sub-goals taken as reached when close enough
        self.switches = 0
        self.switch_time = 0.0
        self.desire: Desire | None = None
        # a task whose steps take things in the hand: the grasp button (the wire's fifth)
        self.grasp = GraspButton() if any(isinstance(s.action, StepKind) and s.action.grips
                                          for s in task.intent) else None

    # -- the loop ----------------------------------------------------------------------

    def step(self, t: float, obs: Observation) -> tuple[tuple[float, ...], tuple[int, ...]]:
        """The stick's deflection (``n_axes``) and the buttons (mode, enable, escape; and
        choose, grasp for a task that takes things in the hand) at time ``t`` (s, any
        clock the observations share), given the newest observation."""
        u, buttons = self._step(t, obs)
        if self.grasp is None:
            return u, buttons
        perceived = self._perceived
        want = self.desire.grip if self.desire is not None and not self.desire.done else None
        down = perceived is not None and self.grasp.down(t, want, perceived.scene)
        if down:  # (the stick let go while the button is down)
            self._out = np.zeros(self.n)
            u = tuple(self._out.tolist())
        return u, (*buttons, 0, int(down))

    def _step(self, t: float, obs: Observation) -> tuple[tuple[float, ...], tuple[int, int, int]]:
        self._seen.append(obs)
        perceived = self._perceive(t)
        if perceived is None or t < self._next:
            return tuple(self._out.tolist()), self._buttons
        self._next = t + self.profile.update_period
        self._learn(perceived)
        if perceived.mode != self._mode:
            # a change of mode the user did not press for: the skill has moved on
            unasked = bool(self._mode) and self._switch is None
            self._moved_on = (self.desire.phase, t) if unasked and self.desire is not None else None
            self._mode, self._mode_since = perceived.mode, t
        u, buttons = self._decide(t, perceived)
        self._out = self._as_made(u)
        self._buttons = buttons
        self._history.append((t, self._out.copy()))
        while len(self._history) > 2 and self._history[1][0] < t - 5.0:
            self._history.popleft()
        return tuple(self._out.tolist()), buttons

    @property
    def done(self) -> bool:
        return self.desire is not None and self.desire.done

    # -- parts ---------------------------------------------------------------------------

    def _new_model(self) -> Device:
        """What the person learns of a mode new to them (:attr:`model`)."""
        lags = self.model.lags
        return DeviceModel(self.n) if lags == (0.0,) else DelayedDeviceModel(self.n, lags)

    def _perceive(self, t: float) -> Observation | None:
        """The newest observation at least a reaction delay old."""
        cutoff = t - self.profile.reaction_delay
        seen = self._seen
        while len(seen) > 1 and seen[1].t <= cutoff:
            seen.popleft()
        return seen[0] if seen and seen[0].t <= cutoff else None

    def _applied(self, t0: float, t1: float) -> Array:
        """The deflection the user held from ``t0`` to ``t1``, averaged over that time
        (the stick changes at the user's own corrections, which need not fall on the
        times of the observations it learns from)."""
        total = np.zeros(self.n)
        current = np.zeros(self.n)
        at = t0
        for ti, u in self._history:
            if ti >= t1:
                break
            if ti > at:
                total += current * (ti - at)
                at = ti
            current = u
        total += current * (t1 - at)
        return total / (t1 - t0)

    def _learn(self, now: Observation) -> None:
        """Update the current mode's model with how the hand moved since the last
        correction, and the input that was held meanwhile; not while something holds
        the hand (a surface it presses, a stop it is pushed against: :meth:`_stopped`)."""
        last, self._perceived = self._perceived, now
        if last is None or now.t - last.t < 1e-3:
            return
        held, before = self._applied(last.t, now.t), self._last_push
        self._last_push = held
        if last.mode != now.mode or self._switch is not None:
            self._last_push = np.zeros(self.n)
            return
        if self.intent.touching(last) or self.intent.touching(now):  # (the surface held the hand)
            return
        model = self.models.setdefault(now.mode, self._new_model())
        twist = twist_between(last.T_world_ee, now.T_world_ee, now.t - last.t)
        if self._stopped(model, now.mode, before, held, twist):
            return
        if isinstance(model, DelayedDeviceModel):
            model.update([self._applied(last.t - lag, now.t - lag) for lag in model.lags], twist)
        else:
            model.update(held, twist)

    def _stopped(self, model: Device, mode: str, before: Array, u: Array, twist: Array) -> bool:
        """Whether the hand did not go (almost) at all the way the person wished it to, though
        their model of the mode promised it would, under a push held on from the pair
        before (the same direction): the skill stops it there (the bottle tilted as far as
        it goes, while the stick's other axis slides it along that limit; a wall of its
        limits), which says nothing of what the stick does. Both are measured along the
        wish the push was chosen for, weighed as the intent weighs it (the motion of the
        frame of its step). A person pushing against a stop does not conclude the stick
        stopped working; learning from it would wear down what the model knows of that
        axis with every correction (its forgetting), until bringing the hand back from the
        stop is asked of an axis the model no longer trusts. A hand that went the other
        way is a model that is wrong, and is learned from. When the stick really stopped
        doing anything, the intent stops getting closer and the person tries the stick out
        again (:meth:`_no_progress`), and learns from those pushes: while a mode is being
        tried out, or not known, everything is learned from."""
        d = self.desire
        if d is None or not model.known or self._probes.get(mode):
            return False
        nu, nb = float(np.linalg.norm(u)), float(np.linalg.norm(before))
        if nu < 1e-9 or nb < 1e-9 or float(u @ before) < HELD_ON * nu * nb:
            return False
        wish = d.W @ d.twist
        size = float(np.linalg.norm(wish))
        if size < 1e-9:
            return False
        promised = float(wish @ (d.W @ model.predict(u))) / size
        return promised > NOTICEABLE and abs(float(wish @ (d.W @ twist)) / size) < STOPPED * promised

    def _decide(self, t: float, obs: Observation) -> tuple[Array, tuple[int, int, int]]:
        zero = np.zeros(self.n)
        if self._switch is not None:  # stick released while switching
            s = self._switch
            if t - s.start < self.profile.switch_time:
                return zero, (1, 1, 0) if t - s.start < self.profile.update_period else (0, 1, 0)
            if t - s.start >= self.profile.switch_time + self.profile.reaction_delay:
                self.switch_works = obs.mode != s.mode  # False: the switch does nothing with this skill
                self._switch = None
                self._bad_since = None
            return zero, (0, 1, 0)
        desire = self.desire = self.intent.desire(obs)
        if self._moved_on is not None and (desire.phase != self._moved_on[0]
                                           or t - self._moved_on[1] > MOVED_ON_WINDOW):
            self._moved_on = None  # that sub-goal is over, or the change was no cue for it
        if self._moved_on is not None and desire.close_enough:
            # The display shows a new mode the user did not ask for, and the hand is as
            # close to the sub-goal as the task needs: the template has taken it there
            # and moved on (a pour state once the bottle is over the mug), and so does
            # the user, instead of trying to finish the sub-goal in the new mode.
            self._moved_on = None
            self.intent.settle()
            self.settled += 1
            desire = self.desire = self.intent.desire(obs)
        if desire.done or self._pausing(t, desire.phase):
            return zero, (0, 1, 0)
        model = self.models.setdefault(obs.mode, self._new_model())
        if self._no_progress(t, desire) and model.known and obs.mode not in self._probes \
                and not self.intent.touching(obs):
            if desire.close_enough:
                # Not quite there, but as close as the task needs and no closer for a
                # while: on to the next step.
                self.intent.settle()
                self.settled += 1
                desire = self.desire = self.intent.desire(obs)
            else:
                # What used to work does not any more (the device behaves differently
                # here): wiggle the stick again to see what it does now.
                model.relearn()
                self.reprobes += 1
        if not model.known or self._probes.get(obs.mode):
            return self._probe(obs.mode, model), (0, 1, 0)
        self._probes.pop(obs.mode, None)
        u, residual = self._best_effort(model, desire)
        lacking = self._lacking(model, desire)
        trial = self._try_at_once(t, model, max(residual, lacking), desire, obs)
        if trial is not None:
            return trial, (0, 1, 0)
        if obs.switches and self._wants_switch(t, obs.mode, max(residual, lacking), desire):
            self._switch = _Switch(t, obs.mode)
            self.switches += 1
            self.switch_time += self.profile.switch_time
            return zero, (1, 1, 0)
        if lacking > LACKING and self.switch_works is not False and obs.switches:
            # This mode cannot give what is most wanted: rather than do the rest of the
            # wish (moving the opening off the mug while the bottle should tilt), the user
            # lets go and gets ready to switch.
            return zero, (0, 1, 0)
        return u, (0, 1, 0)

    def _try_at_once(self, t: float, model: Device, lacking: float, desire: Desire,
                     obs: Observation) -> Array | None:
        """A trial push if the sub-goal just begun cannot come from this mode as the user
        knows it and no switch can give another (:meth:`_unable`), else None.

        The device must then do something here the user has not seen (a template that
        turns the cup once it is at the lips), so they try the stick out at once rather
        than push where nothing is promised. Later in a sub-goal (the bottle pouring)
        they keep to what they know, and try it out only once it has stopped getting
        them closer (REPROBE_AFTER)."""
        if desire.phase != self._sub_goal[0]:
            self._sub_goal = (desire.phase, t)
        if t - self._sub_goal[1] > TRY_AT_ONCE or not self._unable(lacking, desire, obs):
            return None
        self._tried_for = desire.phase
        model.relearn()
        self.reprobes += 1
        return self._probe(obs.mode, model)

    def _unable(self, lacking: float, desire: Desire, obs: Observation) -> bool:
        """Whether the user, once in this sub-goal, finds that the mode as they know it
        gives next to nothing of the wish or of its most wanted part (``lacking``, the
        larger of the two residuals, over :data:`LACKING`), wants more than a little
        (:data:`SMALL_WISH`), and has no mode switch to turn to (the display says the
        button changes nothing here, or pressing it did nothing)."""
        if desire.phase == self._tried_for or lacking <= LACKING:
            return False
        if obs.switches and self.switch_works is not False:
            return False
        return float(np.linalg.norm(desire.W @ desire.twist)) >= SMALL_WISH

    def _pausing(self, t: float, phase: str) -> bool:
        """Whether the stick is let go after a step of the task was reached
        (``profile.step_pause``), or after holding it for ``profile.regrip_every``
        within a step (for ``profile.regrip_time``)."""
        p = self.profile
        if phase != self._pause_phase:
            self._pause_until = t + p.step_pause if self._pause_phase is not None else t
            self._pause_phase = phase
        elif p.regrip_every > 0 and t - self._pause_until >= p.regrip_every:
            self._pause_until = t + p.regrip_time
        return t < self._pause_until

    def _no_progress(self, t: float, desire: Desire) -> bool:
        """Whether the intent's error has not got better for ``REPROBE_AFTER`` seconds
        (a new sub-goal starts the clock again)."""
        if desire.phase != self._phase:
            self._phase, self._best_error, self._improved = desire.phase, desire.error, t
            return False
        if desire.error < self._best_error - PROGRESS:
            self._best_error, self._improved = desire.error, t
            return False
        if t - self._improved > REPROBE_AFTER:
            self._best_error, self._improved = desire.error, t
            return True
        return False

    @staticmethod
    def _best_effort(model: Device, desire: Desire) -> tuple[Array, float]:
        """The input for what is wanted; when the mode cannot give all of it (its axes
        couple what the user wants apart), one thing at a time: the position, or else
        the orientation, as a person would. The residual is of the whole wish."""
        u, residual = model.command(desire.twist, desire.W)
        if residual < 0.8:
            return u, residual
        for part in (slice(0, 3), slice(3, 6)):
            W = np.zeros_like(desire.W)
            W[part, :] = desire.W[part, :]  # the wish's rows for the position, or the orientation
            if not np.any(W @ desire.twist):
                continue
            u_part, r_part = model.command(desire.twist, W)
            if r_part < 0.8:
                b = desire.W @ desire.twist
                whole = float(np.linalg.norm(desire.W @ model.predict(u_part) - b) / np.linalg.norm(b))
                return u_part, whole
        return u, residual

    def _probe(self, mode: str, model: Device) -> Array:
        """Try each axis both ways, one correction each (a person wiggling the stick to
        see what it does); then wait for the response before using the model."""
        queue = self._probes.get(mode)
        if queue is None:
            queue = self._probes[mode] = []
            for i in range(self.n):
                e = np.zeros(self.n)
                e[i] = PROBE
                queue += [e, -e]
        if queue:
            return queue.pop(0)
        if not model.known:  # the last pushes were too small to count: again
            del self._probes[mode]
        return np.zeros(self.n)

    @staticmethod
    def _lacking(model: Device, desire: Desire) -> float:
        """How little of the most wanted part of the wish (the position, or the
        orientation: the one with the larger weighted share) this mode can give when it
        is asked for that part alone: 1 when pushing the stick does nothing for it (a
        translation mode when the bottle must tilt), 0 when it can give it all."""
        b = desire.W @ desire.twist
        parts = (slice(0, 3), slice(3, 6))
        shares = [float(np.linalg.norm(b[p])) for p in parts]
        if max(shares) < 1e-9:
            return 0.0
        p = parts[int(np.argmax(shares))]
        W = np.zeros_like(desire.W)
        W[p, :] = desire.W[p, :]
        return model.command(desire.twist, W)[1]

    def _wants_switch(self, t: float, mode: str, residual: float, desire: Desire) -> bool:
        """Switch when this mode has not been able to give the wanted motion for a while
        and another mode might (or one known to do better exists)."""
        if self.switch_works is False or t - self._mode_since < 1.0:
            return False
        if float(np.linalg.norm(desire.W @ desire.twist)) < SMALL_WISH:
            # Almost nothing wanted (the bottle held tilted while it pours): no mode
            # does better at that, and the next step may want the mode there is now.
            self._bad_since = None
            return False
        better = [m for name, m in self.models.items() if name != mode and m.known
                  and m.command(desire.twist, desire.W)[1] < residual - 0.3]
        if better:
            return True
        if residual > 0.85:
            if self._bad_since is None:
                self._bad_since = t
            return t - self._bad_since > 1.5
        self._bad_since = None
        return False

    def _as_made(self, u: Array) -> Array:
        """The deflection the person actually makes: noisy, nothing below the dead zone."""
        p = self.profile
        noisy = u + self.rng.normal(0.0, 1.0, self.n) * (p.noise_constant + p.noise_gain * np.abs(u))
        noisy[np.abs(u) < p.dead_zone] = 0.0  # no deliberate deflection that small
        return np.clip(noisy, -1.0, 1.0)
