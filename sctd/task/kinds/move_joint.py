"""Moving a joint's handle: the ``move_joint`` intent step.

``move_joint`` (a ``joint``, an ``overshoot``, ``back`` a predicate) moves the joint's
handle, held by the frame of the reach to that handle just before, along its path (a
prismatic joint's axis; a revolute joint's arc, along its tangent at the handle) to the
joint's threshold in the task's ``done`` plus the overshoot; done once the handle is the
person's ``past`` along its path beyond the threshold; back to the step before when
``back`` holds (the handle let go). A demonstration waits for the hand to hold the handle,
then takes it along its path to the planned position.

What a simulated person does (:class:`MoveJointMind`) is part of the kind.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ..judge import holds, thresholds
from ..kinematics import handle_jacobian, handle_pose
from ..model import Outcome, Predicate, Scene, Step
from .base import Array, Floor, Run, Sight, StepKind, StepMind, Want
from .reach import anchor_mind, anchor_of, frame_want, frame_weights, joint_name, lever, saturate, uprighting
from .teaching import Draft, StepPlan
from .tilt import two_of

if TYPE_CHECKING:  # (typing only)
    from ..model import Task, TeachStep


@dataclass(frozen=True)
class MoveJoint(StepKind):
    """Move ``joint``'s handle (held by the frame of the reach before it) along its path
    (a prismatic joint's axis, a revolute joint's arc) to the joint's threshold in the
    task's ``done`` plus ``overshoot`` (the joint's unit: m or rad); back to the previous
    step when ``back`` holds (the handle let go). ``frame_name``: the frame of the reach
    before it (the reader fills it in)."""

    key = "move_joint"
    teaches = ("to",)

    joint: str
    overshoot: float = 0.0
    back: Predicate | None = None
    frame_name: str = field(default="hand", compare=False)

    @classmethod
    def read(cls, r: Any, v: Any, path: str, scene: Scene, outcome: Outcome,
             before: tuple[Step, ...]) -> MoveJoint:
        from ..reader import predicate  # (the reader imports the registry)

        anchor = anchor_of(r, cls.key, path, before)
        d = r.fields(v, path, {"joint"}, {"overshoot", "back"})
        joint = joint_name(r, d["joint"], f"{path}.joint", scene)
        if f"{joint}.position" not in thresholds(outcome.done):
            raise r.fail(f"{path}.joint", f"outcome.done sets no at_least on {joint}.position: the joint "
                                          "has no target to move it to")
        if anchor.handle != joint:
            raise r.fail(f"{path}.joint", f"the reach before it must go to the handle of {joint!r} "
                                          f"(handle: {joint}): that is what moves it")
        read = r.angle if scene.joints[joint].kind == "revolute" else r.number  # (in the joint's unit)
        overshoot = read(d.get("overshoot", 0.0), f"{path}.overshoot", lo=0.0)
        return cls(joint, overshoot, predicate(r, d["back"], f"{path}.back", scene) if "back" in d else None,
                   anchor.frame())

    def to_yaml(self, scene: Scene) -> dict[str, Any]:
        from ..writer import _angle, _predicate  # (the writer imports the reader)

        out: dict[str, Any] = {"joint": self.joint}
        if self.overshoot != 0.0:
            out["overshoot"] = (_angle if self._revolute(scene) else float)(self.overshoot)
        if self.back is not None:
            out["back"] = _predicate(self.back, scene)
        return out

    def _revolute(self, scene: Scene) -> bool:
        return bool(scene.joints[self.joint].kind == "revolute")

    def read_teach(self, r: Any, d: dict[str, Any], path: str, scene: Scene) -> dict[str, Any]:
        """``to``: positions within the joint's travel (angles for a revolute joint)."""
        if "to" not in d:
            return {}
        joint = scene.joints[self.joint]
        if joint.hinge is not None:  # a revolute joint's positions are angles
            two = two_of(r, d["to"], f"{path}.to")
            lo, hi = tuple(r.angle(a, f"{path}.to[{i}]") for i, a in enumerate(two))
            if not lo < hi:
                raise r.fail(f"{path}.to", "expected [low, high] with low < high")
        else:
            lo, hi = r.pair(d["to"], f"{path}.to")
        travel = joint.travel
        if not (0.0 < lo and hi <= travel):
            raise r.fail(f"{path}.to", f"expected positions within the joint's travel (0, {travel:g}], "
                                       f"got [{lo}, {hi}]")
        return {"to": (lo, hi)}

    def teach_to_yaml(self, ts: TeachStep, scene: Scene) -> dict[str, Any]:
        from ..writer import _angles, _floats  # (the writer imports the reader)

        if ts.to is None:
            return {}
        return {"to": _angles(ts.to) if self._revolute(scene) else _floats(ts.to)}

    def frame(self) -> str:
        return self.frame_name

    def mind(self, run: Run, index: int) -> StepMind:
        return MoveJointMind(self, run, index)

    def floor_path(self, task: Task, before: tuple[Floor, ...]) -> Floor:
        """The handle along its path to the threshold (a revolute joint's angle times its
        lever)."""
        sc = task.scene
        j = sc.joints[self.joint]
        arm = float(np.linalg.norm(handle_jacobian(j, sc.bodies[j.handle].T_world, 0.0)))
        return Floor(along=thresholds(task.outcome.done).get(f"{self.joint}.position", 0.0) * arm)

    def plan(self, draft: Draft, rng: np.random.Generator) -> StepPlan:
        """The position drawn from the step's range (else the threshold plus the
        overshoot: nothing drawn), the handle held first."""
        var = draft.vary
        done = thresholds(draft.geometry.task.outcome.done)
        end = float(rng.uniform(*var.to)) if var.to is not None else \
            done[f"{self.joint}.position"] + self.overshoot
        return StepPlan(draft.name, "move_joint", self.frame_name, value=end, joint=self.joint,
                        grasped=f"{self.joint}.held", note=f"{self.joint} to {end:.3f}")


class MoveJointMind(StepMind):
    """A person moving a joint's handle held by the frame of the reach before (the module
    doc): onto the handle across its path and along the path towards the target, aiming
    at most the person's ``ahead`` m ahead."""

    def __init__(self, step: MoveJoint, run: Run, index: int):
        self.step, self.run, self.index = step, run, index
        # the joint's position to move it to, and the person's ``past`` in its unit
        self.end = thresholds(run.task.outcome.done)[f"{step.joint}.position"] + step.overshoot
        self.past = run.person.past / lever(run.scene.joints[step.joint])

    def _position(self, sight: Sight) -> float:
        return float(sight.readings.get(f"{self.step.joint}.position", 0.0))

    def move(self, sight: Sight) -> int:
        if self.step.back is not None and holds(self.step.back, sight.readings, sight.positions):
            return -1  # let go: that first
        reached = self.end - self.step.overshoot + self.past
        return 1 if self._position(sight) >= reached else 0

    def _path(self, sight: Sight) -> tuple[float, Array, Array, float]:
        """The joint's position, its handle there (world), the unit direction the handle
        moves in as the joint opens (a drawer's axis, a door's arc's tangent) and m of
        that path per unit of the joint."""
        joint = self.run.scene.joints[self.step.joint]
        H = sight.objects[joint.handle]
        o = self._position(sight)
        m = lever(joint)
        return o, handle_pose(joint, H, o)[:3, 3], handle_jacobian(joint, H, o) / m, m

    def error(self, sight: Sight) -> float:
        """The handle's path still to go (m) and the frame's distance off that path."""
        reach = anchor_mind(self.run, self.index)
        seen = reach.look(sight)
        o, handle, axis, m = self._path(sight)
        (a0, a1, a2), (h0, h1, h2) = axis.tolist(), handle.tolist()
        x, y, z = seen.p.tolist()
        d0, d1, d2 = h0 - x, h1 - y, h2 - z  # to the handle
        da = 0.0 + d0 * a0 + d1 * a1 + d2 * a2  # (summed as numpy's dot)
        l0, l1, l2 = d0 - da * a0, d1 - da * a1, d2 - da * a2  # lateral
        err = max(0.0, self.end - o) * m + math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
        upright = reach.step.upright
        return err if upright is None else err + self.run.person.per_rad * max(0.0, seen.tilt - upright)

    def want(self, sight: Sight) -> Want:
        reach = anchor_mind(self.run, self.index)
        seen = reach.look(sight)
        person = self.run.person
        o, handle, axis, m = self._path(sight)
        p = seen.p
        lateral = handle - p - float((handle - p) @ axis) * axis
        along = max(0.0, self.end - o) * m
        v = saturate(person.gain * (lateral + min(along, person.ahead) * axis), person.v_max)
        upright = reach.step.upright
        if upright is None:
            return frame_want(person, seen, sight.T_world_ee, v, None)
        w = uprighting(person, seen, max(0.0, seen.tilt - upright))
        return frame_want(person, seen, sight.T_world_ee, v, w)

    def rest(self, sight: Sight) -> Want:
        reach = anchor_mind(self.run, self.index)
        return Want(np.zeros(6), frame_weights(self.run.person, reach.look(sight), sight.T_world_ee,
                                               reach.step.upright is not None))
