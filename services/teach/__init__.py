"""``sctd teach``: a demonstrator that shows a task on the simulated arm, recorded.

The stand-in for kinesthetic teaching: full 6-DoF targets straight to the simulator
(no shared-control daemon), with the variation a person shows between demonstrations,
each one recorded (:mod:`sctd_services.record`), judged by the scene, and kept or
discarded.

- :mod:`.plan`: what each demonstration will be (:func:`plan_demonstration`, seeded, pure);
- :mod:`.motion`: the smooth motions it is made of, in the task object's frame (pure);
- :mod:`.stream`: :class:`Teacher`, the targets on Zenoh, paced by the arm, the scene
  reset, the watch for another commander;
- :mod:`.demonstrator`: :func:`teach`, the session (attempts, judging, keeping).
"""

from .demonstrator import Attempt, TeachOptions, describe_outcome, judge, teach
from .motion import Line, TipTurn, move, task_motions, upright
from .plan import (
    DemoPlan,
    SceneGeometry,
    Speeds,
    StepPlan,
    facing,
    plan_demonstration,
    scene_geometry,
)
from .stream import (
    CommanderConflict,
    SimulatorLost,
    StreamLimits,
    Teacher,
    TeachingError,
    WrongScene,
)

__all__ = [
    "Attempt",
    "CommanderConflict",
    "DemoPlan",
    "Line",
    "SceneGeometry",
    "SimulatorLost",
    "Speeds",
    "StepPlan",
    "StreamLimits",
    "TeachOptions",
    "Teacher",
    "TeachingError",
    "TipTurn",
    "WrongScene",
    "describe_outcome",
    "facing",
    "judge",
    "move",
    "plan_demonstration",
    "scene_geometry",
    "task_motions",
    "teach",
    "upright",
]
