"""Pressing a push button: the ``press`` intent step.

``press`` (a ``frame`` among the surface's ``touch``, a ``button``, ``until`` a
predicate, a ``force`` bound) brings the frame in front of the button's face, onto its
axis (the body's x through the face's centre), and pushes it in along -x, never harder
than the bound, until the predicate holds (the light on). A press names its own frame,
so it may come first. A demonstration comes onto the axis :data:`PRESS_STANDOFF` in
front of the face (through a via point, the hand keeping its orientation), pushes in to
a depth past the button's click, holds until the predicate holds and pulls back out.

What a simulated person does (:class:`PressMind`) is part of the kind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from sctd import se3

from ..judge import holds
from ..model import PRESS_MARGIN, Outcome, Predicate, Scene, Step
from .base import Floor, Run, Sight, StepKind, StepMind, Want
from .reach import HAND, Look, frame_want, frame_weights, saturate
from .teaching import Draft, StepPlan

if TYPE_CHECKING:  # (typing only)
    from ..model import Task

PRESS_STANDOFF = 0.03
"""m in front of a button's face where a demonstration comes onto its axis, before it
pushes in along it (and where it pulls back out to)."""


@dataclass(frozen=True)
class Press(StepKind):
    """Press ``button`` (a body with a button) with ``frame_name`` (``hand`` or a held
    frame): bring the frame in front of the button's face, onto its axis, and push it in
    along its inward normal (the body's -x), never harder than ``force`` (N), until
    ``until`` holds (the light on)."""

    key = "press"
    teaches = ("margin", "miss")

    frame_name: str
    button: str
    until: Predicate
    force: float

    @classmethod
    def read(cls, r: Any, v: Any, path: str, scene: Scene, outcome: Outcome,
             before: tuple[Step, ...]) -> Press:
        """``{frame, button, until, force}``: a frame that touches the button's surface, a
        body with a button, what completes the step, and a push bound the button can be
        switched under."""
        from ..reader import predicate  # (the reader imports the registry)

        d = r.fields(v, path, {"frame", "button", "until", "force"})
        name = r.string(d["button"], f"{path}.button")
        body = scene.bodies.get(name)
        if body is None or body.button is None or body.surface is None:
            buttons = [n for n, b in scene.bodies.items() if b.button is not None]
            raise r.fail(f"{path}.button", f"expected a body with a button, got {name!r} (buttons: "
                                           f"{', '.join(buttons) or 'none'})")
        frame = r.string(d["frame"], f"{path}.frame")
        if frame not in body.surface.touch:
            raise r.fail(f"{path}.frame", f"expected a frame that touches the surface of {name!r}, got "
                                          f"{frame!r} (its touch: {', '.join(body.surface.touch)})")
        force = r.positive(d["force"], f"{path}.force")
        needs = body.button.click_force
        if not force > needs:
            raise r.fail(f"{path}.force", f"the button takes {needs:g} N to push to its click depth: a "
                                          f"push of at most {force:g} N never switches it")
        return cls(frame, name, predicate(r, d["until"], f"{path}.until", scene), force)

    def to_yaml(self, scene: Scene) -> dict[str, Any]:
        from ..writer import _predicate  # (the writer imports the reader)

        return {"frame": self.frame_name, "button": self.button, "until": _predicate(self.until, scene),
                "force": float(self.force)}

    def frame(self) -> str:
        return self.frame_name

    def mind(self, run: Run, index: int) -> StepMind:
        return PressMind(self, run, index)

    def floor_path(self, task: Task, before: tuple[Floor, ...]) -> Floor:
        """Its frame to the button's face, when it is the first step that goes anywhere
        (the floor counts the first way to a goal only)."""
        if any(f.points for f in before):
            return Floor()
        return Floor((task.scene.bodies[self.button].T_world[:3, 3],), frame=self.frame_name, clock="goal")

    def plan(self, draft: Draft, rng: np.random.Generator) -> StepPlan:
        """Onto the button's axis in front of its face (the hand's orientation kept; a
        mistake's beside it by the step's ``miss`` along the body's y) and in past its
        click depth by a margin drawn from the step's. Draws the margin, then the
        mistake's side."""
        g, var = draft.geometry, draft.vary
        button = g.task.scene.bodies[self.button].button
        assert button is not None  # (the reader checks a press names a button)
        depth = button.click + float(rng.uniform(*(var.margin or PRESS_MARGIN)))
        side = var.miss * float(rng.choice([-1.0, 1.0]))  # drawn always: a mistake changes nothing else
        T_obj_button = g.body(self.button)
        x, y = T_obj_button[:3, 0], T_obj_button[:3, 1]
        p = T_obj_button[:3, 3] + PRESS_STANDOFF * x + (side if draft.mistake else 0.0) * y
        R = draft.here[:3, :3]
        T_goal = se3.transform_from_rt(R, p - R @ g.frame(self.frame_name)[:3, 3])
        return StepPlan(draft.name, "press", self.frame_name, T_goal, value=depth, button=self.button,
                        until=self.until, note=f"{self.button} {depth * 1000:.1f} mm in")


class PressMind(StepMind):
    """A person pressing a button with a frame (the module doc): onto the button's axis,
    the person's ``clearance`` in front of its face while off the axis; on it, in
    towards the face (at the person's ``press_speed`` within ``slow`` of it) and, once
    the scene reports a push, at ``press_speed`` slowed as the force grows past half the
    step's bound, backing off beyond it. Its orientation is free."""

    def __init__(self, step: Press, run: Run, index: int):
        self.step, self.run, self.index = step, run, index
        button = run.scene.bodies[step.button].button
        assert button is not None  # (the reader checks the press names a button)
        self.button = button

    def look(self, sight: Sight) -> Look:
        """The frame against the button: its goal the face's centre pushed in to the
        button's travel; its height and radial in the button's frame, the radial its
        distance from the button's axis (the body's x). Worked out once a sight."""
        key = ("press", self.index)
        if key not in sight.memo:
            a = self.step
            T_f = sight.T_world_ee if a.frame_name == HAND else sight.objects[a.frame_name]
            T_B = sight.objects[a.button]
            _, y, z, _ = (self.run.inverse(a.button, T_B) @ np.append(T_f[:3, 3], 1.0)).tolist()
            goal = T_B[:3, 3] - self.button.travel * T_B[:3, 0]
            tilt = math.acos(max(-1.0, min(1.0, float(T_f[2, 2]))))
            sight.memo[key] = Look(T_f[:3, 3], T_f[:3, 2], tilt, z, 0.0, math.hypot(y, z),
                                   tuple(goal.tolist()), float(np.linalg.norm(goal - T_f[:3, 3])))
        return sight.memo[key]

    def move(self, sight: Sight) -> int:
        return 1 if holds(self.step.until, sight.readings, sight.positions) else 0

    def error(self, sight: Sight) -> float:
        """To the face's centre pushed in to its travel."""
        return self.look(sight).to_goal

    def want(self, sight: Sight) -> Want:
        a, person, seen = self.step, self.run.person, self.look(sight)
        T_B = sight.objects[a.button]
        x, y, z, _ = (self.run.inverse(a.button, T_B) @ np.append(seen.p, 1.0)).tolist()
        face = -float(sight.readings.get(f"{a.button}.position", 0.0))  # where the face is now
        force = float(sight.readings.get(f"{a.button}.force", 0.0))
        radius = self.button.radius
        on_axis = seen.radial < person.aim * radius or (force > 0.0 and seen.radial < radius)
        if not on_axis:
            along = person.gain * (face + person.clearance - x)
        elif force > 0.0:
            along = -person.press_speed * max(-1.0, min(1.0, 2.0 * (1.0 - force / a.force)))
        else:
            along = -(person.gain * max(0.0, x - face - person.slow) + person.press_speed)
        v = T_B[:3, :3] @ np.array([along, -person.gain * y, -person.gain * z])
        return frame_want(person, seen, sight.T_world_ee, saturate(v, person.v_max), None)

    def rest(self, sight: Sight) -> Want:
        return Want(np.zeros(6), frame_weights(self.run.person, self.look(sight), sight.T_world_ee, False))
