"""Starts the demonstrations did not cover: a task's hand start drawn wider than its file
says, or another task's hand start in this task's scene.

A skill is taught from demonstrations that start where the task file's ``start`` and
``vary`` put the hand. A person starts wherever they are. ``sctd suite --starts`` and
``sctd eval --starts`` try a skill from:

- ``own``: the task file's start, as every figure does by default;
- ``wide``: the same start, drawn :data:`WIDE` times as far each way (position and yaw);
- ``foreign``: the start of another task in a room of the two: the other task and this
  one laid out side by side as ``sctd eval --set`` lays out a room
  (:func:`~sctd.task.compose.room`), the hand at the other task's start, going for
  this task. Trial ``seed`` takes the ``seed``-th of the other tasks in turn (those
  that share a room with it: two tasks that each hold something in the hand do not),
  so that 20 trials visit each of eight others two or three times.

Pure: the tasks are given; which of them the arm can reach is the caller's to judge.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

from .compose import room
from .model import Task, Vary
from .reader import TaskError

STARTS = ("own", "wide", "foreign")
WIDE = 2.0  # how much wider a wide start is drawn than the file's vary


def widened(task: Task, factor: float = WIDE) -> Task:
    """``task`` with its hand start drawn ``factor`` times as far each way."""
    v = task.scene.start.vary
    start = replace(task.scene.start, vary=Vary(v.position * factor, v.yaw * factor))
    return replace(task, scene=replace(task.scene, start=start))


def from_start_of(task: Task, other: Task) -> Task:
    """``task`` in a room with ``other``, the hand at ``other``'s start (:func:`room`).

    Raises
    ------
    TaskError
        The two do not share a room (both hold something in the hand, a name clash).
    """
    return room([other, task], task.name)


def shares_a_room(task: Task, other: Task) -> bool:
    """Whether ``task`` and ``other`` can be laid out in one room."""
    try:
        room([other, task], task.name)
    except TaskError:
        return False
    return True


def foreign_start(task: Task, others: Sequence[Task], seed: int) -> tuple[Task, str]:
    """The task trial ``seed`` runs from another task's start: the ``seed``-th of
    ``others`` that share a room with it (in turn, by name, ``task`` itself left out),
    and that task's name.

    Raises
    ------
    ValueError
        No other task to take a start from.
    """
    pool = sorted((t for t in others if t.name != task.name and shares_a_room(task, t)), key=lambda t: t.name)
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
