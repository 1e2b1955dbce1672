"""Whether the hand can take what a task has it take, before anything moves: each item
and knob no wider than the fingers open, and every place the hand must be at to take
one, turn one or put one down within the arm's reach (``sctd tasks show``, and the
simulator before it starts).

The hand is checked in the orientation the task starts it in (the intents of its
registered steps keep it: level, turned as at the start), at the scene's default poses.
"""

from __future__ import annotations

import numpy as np

from sctd import se3
from sctd.task import Task
from sctd.task.kinds.handling import PlaceStep
from sctd.task.kinds.knob import Knob
from sctd.task.kinds.pickable import Item

from .fingers import MAX_WIDTH
from .robot import ArmModel


def _places(task: Task) -> list[tuple[str, np.ndarray]]:
    """(what, the hand's position) of every grip and every put-down the task asks for."""
    sc = task.scene
    out = []
    for name, b in sc.bodies.items():
        for facet in b.facets.values():
            if isinstance(facet, Item | Knob):
                out.append((f"{name}'s grip", b.T_world[:3, :3] @ [0.0, 0.0, facet.grip] + b.T_world[:3, 3]))
    for s in task.intent:
        if isinstance(s.action, PlaceStep):
            a = s.action
            item = sc.bodies[a.item].facets["item"]
            assert isinstance(item, Item)  # (the reader checks)
            S = sc.bodies[a.onto].T_world
            out.append((f"{a.item} put down on {a.onto}",
                        S[:3, :3] @ [a.at[0], a.at[1], item.grip] + S[:3, 3]))
    return out


def hand_problems(task: Task, arm: ArmModel, opening: float = MAX_WIDTH) -> list[str]:
    """What the hand cannot do of ``task`` with ``arm`` and fingers opening ``opening`` m:
    each a sentence naming the body and why; empty when it can do all of it."""
    from .simulation import start_posture  # (the simulation imports the scenes this uses)

    problems = []
    for name, b in task.scene.bodies.items():
        for facet in b.facets.values():
            if isinstance(facet, Item | Knob) and 2 * facet.radius > opening:
                problems.append(f"{name} is {200 * facet.radius:.1f} cm across; the fingers open "
                                f"{100 * opening:.1f} cm: the hand cannot take it")
    R = task.scene.start.T_world[:3, :3]
    for what, p in _places(task):
        try:
            start_posture(arm, se3.transform_from_rt(R, p))
        except RuntimeError:
            problems.append(f"{what} at [{p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}] is out of the arm's reach "
                            f"({arm.urdf_path.name}, frame {arm.ee_frame!r}) with the hand as it starts")
    return problems
