"""Starts the demonstrations did not cover: a task's hand start drawn wider than its file
says, or another task's hand start in this task's scene.

A skill is taught from demonstrations that start where the task file's ``start`` and
``vary`` put the hand. A person starts wherever they are. ``sctd suite --starts`` and
``sctd eval --starts`` try a skill from:

- ``own``: the task file's start, as every figure does by default;
- ``wide``: the same start, drawn :data:`WIDE` times as far each way (position and yaw);
- ``foreign``: the hand start of another task (its pose in the world and its ``vary``),
  in this task's scene with what this task's hand holds; trial ``seed`` takes the
  ``seed``-th of the other tasks in turn, so that 20 trials visit each of eight others
  two or three times.

Pure: the tasks are given; which of them the arm can reach is the caller's to judge.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from .model import Start, Task, Vary

STARTS = ("own", "wide", "foreign")
WIDE = 2.0  # how much wider a wide start is drawn than the file's vary


def widened(task: Task, factor: float = WIDE) -> Task:
    """``task`` with its hand start drawn ``factor`` times as far each way."""
    v = task.scene.start.vary
    start = replace(task.scene.start, vary=Vary(v.position * factor, v.yaw * factor))
    return replace(task, scene=replace(task.scene, start=start))


def from_start_of(task: Task, other: Task) -> Task:
    """``task`` with ``other``'s hand start (pose in the world, and how it varies)."""
    start = Start(other.scene.start.T_world.copy(), other.scene.start.vary)
    return replace(task, scene=replace(task.scene, start=start))


def foreign_start(task: Task, others: Sequence[Task], seed: int) -> tuple[Task, str]:
    """The task trial ``seed`` runs from another task's start: the ``seed``-th of
    ``others`` (in turn, by name, ``task`` itself left out), and that task's name.

    Raises
    ------
    ValueError
        No other task to take a start from.
    """
    pool = sorted((t for t in others if t.name != task.name), key=lambda t: t.name)
    if not pool:
        raise ValueError(f"task {task.name}: no other task whose start to take")
    other = pool[seed % len(pool)]
    return from_start_of(task, other), other.name


def trial_start(task: Task, starts: str, seed: int, others: Sequence[Task] = ()) -> tuple[Task, str]:
    """The task trial ``seed`` runs in with ``starts`` (:data:`STARTS`), and whose start
    it is (the task's own name unless ``foreign``)."""
    if starts == "own":
        return task, task.name
    if starts == "wide":
        return widened(task), task.name
    if starts == "foreign":
        return foreign_start(task, others, seed)
    raise ValueError(f"starts: {starts!r} is none of {', '.join(STARTS)}")
