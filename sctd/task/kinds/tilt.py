"""Tilting what the hand holds and bringing it upright again: the ``tilt`` and ``upright``
intent steps.

``tilt`` (``to`` an angle from the vertical, ``until`` a predicate) tilts the frame of
the reach before it about a horizontal axis, holding it at that reach's goal, until the
predicate holds (the mug full); back to the step before when the frame is further than
``off_by`` from the goal's vertical. ``upright`` (``below`` an angle) brings that frame's
axis up again, holding it there; done once it is tilted less than ``below``. A
demonstration turns the hand about the frame's point (about the hand's own y axis for a
tilt) and holds a tilt until its predicate holds; bringing the frame upright after the
task is a finish it does not record (:attr:`Upright.finish`).

What a simulated person does for each (:class:`TiltMind`, :class:`UprightMind`) is part
of the kind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..judge import holds, thresholds
from ..model import Outcome, Predicate, Scene, Step
from .base import Array, Floor, Run, Sight, StepKind, StepMind, Want
from .reach import UP, anchor_mind, anchor_of, frame_want, frame_weights, saturate, uprighting
from .teaching import Draft, StepPlan

if TYPE_CHECKING:  # (typing only)
    from ..model import Task, TeachStep


def _held_still(run: Run, index: int, sight: Sight) -> tuple[Any, Array]:
    """The look of the reach before step ``index`` and the frame's velocity holding it at
    that reach's goal."""
    seen = anchor_mind(run, index).look(sight)
    return seen, saturate(run.person.gain * (np.array(seen.goal) - seen.p), run.person.v_max)


@dataclass(frozen=True)
class Tilt(StepKind):
    """Tilt the frame of the reach before it about a horizontal axis to ``to`` (rad),
    holding it at that reach's goal, until ``until`` holds; back to the previous step
    when the frame is further than ``off_by`` (m) from the goal's vertical.

    ``weight``: m of progress per unit of the readings ``until`` requires still to go
    (its :func:`~sctd.task.judge.thresholds`). ``frame_name``: the frame of the reach
    before it (the reader fills it in)."""

    key = "tilt"
    teaches = ("to",)

    to: float
    until: Predicate
    weight: float = 1.0
    off_by: float | None = None
    frame_name: str = field(default="hand", compare=False)

    @classmethod
    def read(cls, r: Any, v: Any, path: str, scene: Scene, outcome: Outcome,
             before: tuple[Step, ...]) -> Tilt:
        from ..reader import predicate  # (the reader imports the registry)

        anchor = anchor_of(r, cls.key, path, before)
        d = r.fields(v, path, {"to", "until"}, {"weight", "off_by"})
        return cls(r.tilt(d["to"], f"{path}.to"), predicate(r, d["until"], f"{path}.until", scene),
                   r.nonneg(d.get("weight", 1.0), f"{path}.weight"),
                   r.positive(d["off_by"], f"{path}.off_by") if "off_by" in d else None, anchor.frame())

    def to_yaml(self, scene: Scene) -> dict[str, Any]:
        from ..writer import _angle, _predicate  # (the writer imports the reader)

        out: dict[str, Any] = {"to": _angle(self.to), "until": _predicate(self.until, scene)}
        if self.weight != 1.0:
            out["weight"] = float(self.weight)
        if self.off_by is not None:
            out["off_by"] = float(self.off_by)
        return out

    def read_teach(self, r: Any, d: dict[str, Any], path: str, scene: Scene) -> dict[str, Any]:
        if "to" not in d:
            return {}
        two = two_of(r, d["to"], f"{path}.to")
        to = tuple(r.tilt(a, f"{path}.to[{i}]") for i, a in enumerate(two))
        if not to[0] < to[1]:
            raise r.fail(f"{path}.to", "expected [low, high] with low < high")
        return {"to": to}

    def teach_to_yaml(self, ts: TeachStep, scene: Scene) -> dict[str, Any]:
        from ..writer import _angles  # (the writer imports the reader)

        return {} if ts.to is None else {"to": _angles(ts.to)}

    def frame(self) -> str:
        return self.frame_name

    def mind(self, run: Run, index: int) -> StepMind:
        return TiltMind(self, run, index)

    def floor_path(self, task: Task, before: tuple[Floor, ...]) -> Floor:
        """Its tilt, turned."""
        return Floor(radians=self.to)

    def plan(self, draft: Draft, rng: np.random.Generator) -> StepPlan:
        """The tilt drawn from the step's range (nothing drawn without one), held until
        its predicate holds."""
        var = draft.vary
        tilt = float(rng.uniform(*var.to)) if var.to is not None else self.to
        return StepPlan(draft.name, "tilt", self.frame_name, value=tilt, until=self.until,
                        note=f"tilt {math.degrees(tilt):.0f} deg")


def two_of(r: Any, v: Any, path: str) -> list[Any]:
    """A list of two (angles, as a file may write them)."""
    from sctd.skill.reader import kind_of

    if not isinstance(v, list) or len(v) != 2:
        raise r.fail(path, f"expected a list of 2 angles, got {kind_of(v)}")
    return v


class TiltMind(StepMind):
    """A person tilting the frame of the reach before, held at its goal (the module doc):
    about the way the frame already leans when it leans clearly (more than the person's
    ``lean``), else about the hand's y axis, tipping the top away from the arm's side
    (:meth:`_wrist_axis`); the axis kept while the step is wanted look
    after look."""

    def __init__(self, step: Tilt, run: Run, index: int):
        self.step, self.run, self.index = step, run, index
        self.waits = thresholds(step.until)  # the readings it waits for
        self._axis: Array | None = None
        if step.off_by is not None:
            anchor_mind(run, index).ask_placed()

    def move(self, sight: Sight) -> int:
        if holds(self.step.until, sight.readings, sight.positions):
            return 1
        if self.step.off_by is None:
            return 0
        return -1 if anchor_mind(self.run, self.index).look(sight).radial > self.step.off_by else 0

    def error(self, sight: Sight) -> float:
        """Tilting far enough, then the readings it waits for."""
        seen = anchor_mind(self.run, self.index).look(sight)
        err = seen.to_goal + self.run.person.per_rad * max(0.0, self.step.to - seen.tilt)
        for reading, target in self.waits.items():
            err += self.step.weight * max(0.0, target - float(sight.readings.get(reading, 0.0)))
        return err

    def want(self, sight: Sight) -> Want:
        seen, v = _held_still(self.run, self.index, sight)
        if self._axis is None or self.run.wanted != self.index:
            a = np.cross(UP, seen.z) if seen.tilt > self.run.person.lean else self._wrist_axis(sight)
            a[2] = 0.0
            n = float(np.linalg.norm(a))
            self._axis = a / n if n > 1e-9 else np.array([0.0, 1.0, 0.0])
        w = self._axis * self.run.person.gain * (self.step.to - seen.tilt)
        return frame_want(self.run.person, seen, sight.T_world_ee, v, w)

    def _wrist_axis(self, sight: Sight) -> Array:
        """The hand's y axis, turned the way that tips the frame's top away from the side
        the arm comes from: the task object's x axis (a task file turns it towards the
        arm: a mug's back towards the robot, the lips' out of the mouth). A hand carried
        in turned half a turn from its task's start tips the other way about its y."""
        a = sight.T_world_ee[:3, 1].copy()
        x_obj = sight.objects[self.run.task.object][:3, 0]
        tips = np.cross(a, UP)  # where a turn about a takes an upright frame's top
        return -a if float(tips[0] * x_obj[0] + tips[1] * x_obj[1]) > 0.0 else a

    def rest(self, sight: Sight) -> Want:
        seen = anchor_mind(self.run, self.index).look(sight)
        return Want(np.zeros(6), frame_weights(self.run.person, seen, sight.T_world_ee, True))


@dataclass(frozen=True)
class Upright(StepKind):
    """Bring the frame of the reach before it upright again, holding it at that reach's
    goal: done when its z axis is tilted less than ``below`` (rad). ``frame_name``: the
    frame of the reach before it (the reader fills it in)."""

    key = "upright"
    finish = True
    teaches = ()

    below: float
    frame_name: str = field(default="hand", compare=False)

    @classmethod
    def read(cls, r: Any, v: Any, path: str, scene: Scene, outcome: Outcome,
             before: tuple[Step, ...]) -> Upright:
        anchor = anchor_of(r, cls.key, path, before)
        d = r.fields(v, path, {"below"})
        return cls(r.tilt(d["below"], f"{path}.below"), anchor.frame())

    def to_yaml(self, scene: Scene) -> dict[str, Any]:
        from ..writer import _angle  # (the writer imports the reader)

        return {"below": _angle(self.below)}

    def frame(self) -> str:
        return self.frame_name

    def mind(self, run: Run, index: int) -> StepMind:
        return UprightMind(self, run, index)

    def floor_path(self, task: Task, before: tuple[Floor, ...]) -> Floor:
        """Nothing (a finish)."""
        return Floor()

    def plan(self, draft: Draft, rng: np.random.Generator) -> StepPlan:
        """The frame's axis brought up about its point; nothing drawn."""
        return StepPlan(draft.name, "upright", self.frame_name, quiet=True)


class UprightMind(StepMind):
    """A person bringing the frame of the reach before upright, held at its goal."""

    def __init__(self, step: Upright, run: Run, index: int):
        self.step, self.run, self.index = step, run, index

    def move(self, sight: Sight) -> int:
        return 1 if anchor_mind(self.run, self.index).look(sight).tilt < self.step.below else 0

    def error(self, sight: Sight) -> float:
        seen = anchor_mind(self.run, self.index).look(sight)
        return seen.to_goal + self.run.person.per_rad * seen.tilt

    def want(self, sight: Sight) -> Want:
        seen, v = _held_still(self.run, self.index, sight)
        w = uprighting(self.run.person, seen, seen.tilt)
        return frame_want(self.run.person, seen, sight.T_world_ee, v, w)

    def rest(self, sight: Sight) -> Want:
        seen = anchor_mind(self.run, self.index).look(sight)
        return Want(np.zeros(6), frame_weights(self.run.person, seen, sight.T_world_ee, True))
