"""What a person wants the hand to do next, per task, from the scene alone.

Written once per task and independent of any skill: an intent looks at what a person in
the chair sees (the hand, the objects, the task's progress: how full the mug is, how
far the drawer is open) and says how the hand should move next, as a desired twist of
the end-effector in the world frame, with a weight matrix saying which components
matter. It never looks at the skill, its states or its mappings.

pour: bring the bottle opening over the mug at a safe height with the bottle upright,
tilt until the mug holds the scene's fill target, bring the bottle upright again.
drawer: reach the handle, then pull until the drawer is open to the scene's target.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sctd import se3

Array = NDArray[np.float64]
UP = np.array([0.0, 0.0, 1.0])


@dataclass
class Observation:
    """What the user sees at time ``t``: the hand and the objects in the world (4x4),
    the task's progress (the scene's outcome fields) and the mode the display shows
    (the skill's active state name)."""

    t: float
    T_world_ee: Array
    objects: dict[str, Array]
    scene: dict[str, Any]
    mode: str = ""


@dataclass
class Desire:
    """How the hand should move: ``twist`` [v, w] (world axes, at the ee origin; m/s,
    rad/s), ``W`` (6, 6) the weight of each component's error (so m/s and rad/s
    compare), ``error`` a distance to the current sub-goal (progress), ``phase`` the
    intent's own step, ``done`` the task is achieved as far as the user can tell,
    ``close_enough`` the hand is short of the sub-goal but within what the task
    tolerates (a user who cannot get any closer moves on: :meth:`PourIntent.settle`)."""

    twist: Array
    W: Array
    error: float
    phase: str
    done: bool = False
    close_enough: bool = False  # the sub-goal is not reached, but within what the task tolerates


NO_TWIST = np.zeros(6)  # what an observer's desire() holds instead of a twist and weights
NO_WEIGHTS = np.zeros((6, 6))
NO_TWIST.flags.writeable = NO_WEIGHTS.flags.writeable = False


def _saturate(v: Array, limit: float) -> Array:
    n = float(np.linalg.norm(v))
    return v if n <= limit else v * (limit / n)


@dataclass
class PourIntent:
    """Bring the opening over the mug, pour to the fill target, upright again.

    Attributes
    ----------
    height : float
        Opening above the mug's opening while pouring, m (the stream lands in the mug
        from up to 0.15 m).
    centred : float
        Horizontal distance from the mug's axis within which the user starts tilting, m.
    acceptable : float
        Distance within which a user who cannot centre the opening any better (the mode
        does not move it there) tilts anyway, m: inside the mug's 4 cm opening with a
        margin for the stream (the scene counts 3.5 cm as over the opening).
    acceptable_heights : tuple of float
        Heights of the opening above the mug's within which such a user tilts, m (the
        stream lands in the mug from up to 0.15 m).
    off_centre : float
        Distance at which a pouring user stops and re-centres, m.
    pour_tilt : float
        Tilt the user aims for while pouring, rad (the bottle flows past about 1.3).
    upright_tilt : float
        Tilt below which the bottle counts as upright again, rad.
    carry_tilt : float
        Tilt the user tolerates while bringing the bottle over the mug (well below the
        angle at which it flows), rad.
    """

    height: float = 0.05
    centred: float = 0.025
    acceptable: float = 0.03
    acceptable_heights: tuple[float, float] = (0.02, 0.10)
    off_centre: float = 0.033
    pour_tilt: float = 1.65
    upright_tilt: float = 0.3
    carry_tilt: float = 0.5  # rad of tilt that does not worry a user carrying the bottle
    lean: float = 0.25  # rad: a bottle leaning further than this is poured the way it leans
    gain: float = 2.0  # 1/s: desired speed per unit error
    v_max: float = 0.10  # m/s: the fastest the user wants the opening to move
    w_max: float = 0.6  # rad/s
    phase: str = "bring"
    _axis: Array | None = field(default=None, repr=False)
    _inverse: tuple[bytes, Array] | None = field(default=None, repr=False, compare=False)  # mug's

    def desire(self, obs: Observation, steer: bool = True) -> Desire:
        """What the hand should do now; with ``steer`` False (an observer judging
        progress, which never steers) the twist and the weights are left zero."""
        T_mug = obs.objects["mug"]
        T_tip = obs.objects["bottle_tip"]
        (_, _, _, tx), (_, _, _, ty), (_, _, zz, tz), _ = T_tip.tolist()  # the opening, the axis' z
        mx, my, height, _ = (self._mug_inverse(T_mug) @ np.array((tx, ty, tz, 1.0))).tolist()
        radial = math.hypot(mx, my)
        tilt = math.acos(max(-1.0, min(1.0, zz)))  # (the bottle axis . UP)
        poured = float(obs.scene.get("poured", 0.0))
        fill = float(obs.scene.get("fill_target", 0.5))
        if self.phase == "bring" and radial < self.centred and abs(height - self.height) < 0.02:
            self.phase = "pour"
        if self.phase == "pour" and poured >= fill:
            self.phase = "upright"
        if self.phase == "pour" and radial > self.off_centre:
            self.phase = "bring"
        if self.phase == "upright" and tilt < self.upright_tilt:
            self.phase = "done"

        # the opening's goal: over the mug's axis, higher while still far from it
        lift = 0.04 * min(1.0, max(0.0, (radial - 0.02) / 0.05))
        goal = T_mug[:3, :3] @ np.array([0.0, 0.0, self.height + lift]) + T_mug[:3, 3]
        gx, gy, gz = goal.tolist()
        ex, ey, ez = gx - tx, gy - ty, gz - tz
        to_goal = math.sqrt(ex * ex + ey * ey + ez * ez)
        if self.phase == "pour":
            err_rot = abs(self.pour_tilt - tilt)
        else:
            # bringing: only a tilt beyond carry_tilt needs undoing; upright: all of it
            err_rot = tilt if self.phase in ("upright", "done") else max(0.0, tilt - self.carry_tilt)
        err = to_goal + 0.05 * err_rot
        if self.phase == "pour":  # progress: tilting far enough, then the mug filling
            err = to_goal + 0.05 * max(0.0, self.pour_tilt - tilt) + 0.5 * max(0.0, fill - poured)
        done = self.phase == "done"
        close = (self.phase == "bring" and radial < self.acceptable
                 and self.acceptable_heights[0] < height < self.acceptable_heights[1]
                 and tilt < self.carry_tilt)
        if not steer:
            return Desire(NO_TWIST, NO_WEIGHTS, err, self.phase, done, close)
        twist, W = self._motion(obs.T_world_ee, T_tip[:3, 3], T_tip[:3, 2], goal, tilt, err_rot)
        return Desire(twist, W, err, self.phase, done, close)

    def _motion(self, T_world_ee: Array, p_tip: Array, z_b: Array, goal: Array, tilt: float,
                excess: float) -> tuple[Array, Array]:
        """The hand's twist towards ``goal`` for the opening and the weights of its
        components (``excess``: the tilt to undo outside pouring)."""
        v_tip = _saturate(self.gain * (goal - p_tip), self.v_max)
        if self.phase == "pour":
            axis = self._tilt_axis(T_world_ee, z_b, tilt)  # further over, one way
            w = axis * self.gain * (self.pour_tilt - tilt)
        else:
            self._axis = None
            back = np.cross(z_b, UP)  # rotating about it brings the bottle upright
            n = float(np.linalg.norm(back))
            w = back / n * self.gain * excess if n > 1e-9 else np.zeros(3)
        w = _saturate(w, self.w_max)
        # the hand's twist that moves the opening so: v_ee = v_tip - w x (p_tip - p_ee)
        v_ee = v_tip - np.cross(w, p_tip - T_world_ee[:3, 3])
        W = np.zeros((6, 6))
        W[:3, :3] = np.eye(3) / self.v_max
        # spinning the bottle about its own axis does not matter
        W[3:, 3:] = (np.eye(3) - np.outer(z_b, z_b)) / self.w_max
        if self.phase == "done":
            v_ee, w = np.zeros(3), np.zeros(3)
        return np.concatenate([v_ee, w]), W

    def _mug_inverse(self, T_mug: Array) -> Array:
        """``T_mug_world``, worked out again only when the mug moved."""
        key = T_mug.tobytes()
        if self._inverse is None or self._inverse[0] != key:
            self._inverse = (key, se3.invert_transform(T_mug))
        return self._inverse[1]

    def settle(self) -> None:
        """Take the bottle as brought (it is close enough, see ``acceptable``): pour."""
        if self.phase == "bring":
            self.phase = "pour"

    def _tilt_axis(self, T_world_ee: Array, z_b: Array, tilt: float) -> Array:
        """The horizontal axis to tilt about, kept once chosen: the way the bottle
        already leans when it leans clearly (``lean``), else the hand's y axis (tipping
        its top forwards; a lean of a few degrees left over from carrying it is no
        decision to pour sideways)."""
        if self._axis is None:
            a = np.cross(UP, z_b) if tilt > self.lean else T_world_ee[:3, 1].copy()
            a[2] = 0.0
            n = float(np.linalg.norm(a))
            self._axis = a / n if n > 1e-9 else np.array([0.0, 1.0, 0.0])
        return self._axis


@dataclass
class DrawerIntent:
    """Reach and grasp the handle, pull to the target opening.

    Attributes
    ----------
    overshoot : float
        How much further than the target the user pulls, m.
    """

    overshoot: float = 0.03
    gain: float = 2.0
    v_max: float = 0.10
    phase: str = "reach"

    def desire(self, obs: Observation, steer: bool = True) -> Desire:
        """What the hand should do now; with ``steer`` False (an observer judging
        progress, which never steers) the twist and the weights are left zero."""
        H = obs.objects["drawer_handle"]  # the closed handle; x opens the drawer
        opening = float(obs.scene.get("opening", 0.0))
        target = float(obs.scene.get("target_opening", 0.2)) + self.overshoot
        attached = bool(obs.scene.get("attached", False))
        (a0, _, _, h0), (a1, _, _, h1), (a2, _, _, h2), _ = H.tolist()  # the axis, the handle
        (_, _, _, x), (_, _, _, y), (_, _, _, z), _ = obs.T_world_ee.tolist()
        d0, d1, d2 = h0 + opening * a0 - x, h1 + opening * a1 - y, h2 + opening * a2 - z  # to the handle
        if attached and self.phase == "reach":
            self.phase = "pull"
        if self.phase == "pull" and not attached:
            self.phase = "reach"  # lost the grip
        if opening >= target - self.overshoot + 1e-3 and self.phase == "pull":
            self.phase = "done"
        if self.phase == "reach":
            err = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        else:
            da = 0.0 + d0 * a0 + d1 * a1 + d2 * a2  # (summed as numpy's dot)
            l0, l1, l2 = d0 - da * a0, d1 - da * a1, d2 - da * a2  # lateral
            err = max(0.0, target - opening) + math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
        done = self.phase == "done"
        if not steer:
            return Desire(NO_TWIST, NO_WEIGHTS, err, self.phase, done)
        return Desire(self._twist(H, opening, target, obs.T_world_ee[:3, 3], done), self._weights(),
                      err, self.phase, done)

    def _twist(self, H: Array, opening: float, target: float, p: Array, done: bool) -> Array:
        """The hand's twist: to the handle, or along its axis while pulling."""
        if done:
            return np.zeros(6)
        axis = H[:3, 0]
        handle = H[:3, 3] + opening * axis
        if self.phase == "reach":
            v = _saturate(self.gain * (handle - p), self.v_max)
        else:
            lateral = handle - p - float((handle - p) @ axis) * axis
            along = max(0.0, target - opening)
            v = _saturate(self.gain * (lateral + min(along, 0.05) * axis), self.v_max)
        return np.concatenate([v, np.zeros(3)])

    def _weights(self) -> Array:
        W = np.zeros((6, 6))
        W[:3, :3] = np.eye(3) / self.v_max
        W[3:, 3:] = np.eye(3) * 0.1  # the hand's orientation hardly matters
        return W

    def settle(self) -> None:
        """Nothing is tolerated short of the goal: the handle is grasped or not."""


INTENTS = {"pour": PourIntent, "drawer": DrawerIntent}


def make_intent(task: str) -> PourIntent | DrawerIntent:
    try:
        return INTENTS[task]()
    except KeyError:
        raise ValueError(f"unknown task {task!r} (known: {', '.join(INTENTS)})") from None
