"""The robot-driver contract: what ``sctd robot`` needs of any arm.

A driver owns the link to one arm. The service that runs it (``sctd robot NAME``,
:mod:`sctd_services.robots.service`) calls, from one thread:

1. :meth:`RobotDriver.connect` once (raises :class:`RobotError` when the arm cannot be
   reached or refuses us: nothing is served);
2. :meth:`RobotDriver.read` in a loop: the arm's next state at its own control rate, as
   a :class:`Reading` (the driver paces the loop: it blocks until the next state is
   due), or None when none came within the timeout;
3. :meth:`RobotDriver.command` with the newest admitted target (a pose of the hand in
   the world, 4x4), or None to hold where the arm is;
4. :meth:`RobotDriver.grip` with each new gripper command (``sctd/<robot>/gripper``)
   where the driver has a gripper (:attr:`RobotDriver.has_gripper`);
5. :meth:`RobotDriver.recover` when a person asks for it after a fault, then
   :meth:`RobotDriver.close` once.

A fault of the arm (a reflex, a control exception, a lost connection) surfaces as
:class:`RobotFault` from :meth:`read` or :meth:`command`. From then on the driver
commands nothing until :meth:`recover` returned: recovery is explicit, never automatic.

Frames: ``world`` is the frame the task file's scene is written in (the arm's base,
unless the driver is told where the base stands); ``ee`` is the hand frame the task's
held objects and skills are relative to (the driver maps the arm's own flange or TCP to
it).
"""

from __future__ import annotations

import argparse
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from ..wire.codec import GripperCmd, GripperReading

Array = NDArray[np.float64]


class RobotError(Exception):
    """A driver cannot start or go on: bad settings, an arm that cannot be reached or
    speaks something else. The message names where and what."""


class RobotFault(RobotError):
    """The arm faulted: it stopped following targets until a recovery.

    Attributes
    ----------
    kind : str
        ``reflex`` (the arm's own safety stopped it), ``control`` (a control exception),
        ``connection`` (the link is lost or timed out), ``protocol`` (the arm spoke
        something else).
    """

    def __init__(self, kind: str, message: str):
        super().__init__(f"{kind}: {message}")
        self.kind = kind
        self.message = message


@dataclass
class Reading:
    """One state of the arm.

    Attributes
    ----------
    stamp : float
        When the arm measured it, as Unix time (s) on this host's clock (a driver maps
        the arm's own clock to it).
    T_world_ee : ndarray, shape (4, 4)
        The hand (``ee``) in the world.
    q, dq : list of float, optional
        Joint positions (rad) and velocities (rad/s).
    wrench : list of float, optional
        The estimated external wrench on the hand, [fx, fy, fz, tx, ty, tz] in the world
        (N, N m).
    mode : str
        The arm's own word for what it is doing (``idle``, ``move``, ``reflex`` ...).
    gripper : GripperReading, optional
        The hand's fingers, where the driver has a gripper.
    """

    stamp: float
    T_world_ee: Array
    q: list[float] | None = None
    dq: list[float] | None = None
    wrench: list[float] | None = None
    mode: str = ""
    gripper: GripperReading | None = None


class RobotDriver(ABC):
    """One arm behind the contract (module doc). Use as a context manager: ``with
    driver: driver.connect() ...`` closes it whatever happens.

    Class attributes
    ----------------
    name : str
        The registry's name of the driver (``sctd robot NAME``).
    description : str
        One line for ``sctd robot --list``.
    owns_scene : bool
        The driver simulates the task's scene itself (objects, outcome; the Pinocchio
        simulator's physics). Otherwise the service runs the scene as an observer of
        the readings.
    """

    name: ClassVar[str] = ""
    description: ClassVar[str] = ""
    owns_scene: ClassVar[bool] = False

    @classmethod  # noqa: B027 - none by default: a driver without flags of its own
    def add_arguments(cls, parser: argparse.ArgumentParser) -> None:
        """Add the driver's own flags (``sctd robot NAME --help`` lists them)."""

    @classmethod
    @abstractmethod
    def from_args(cls, args: argparse.Namespace, task: Any) -> RobotDriver:
        """The driver for parsed flags and the task whose scene it serves (a
        :class:`sctd.task.Task`, or None); RobotError for a bad flag."""

    @property
    @abstractmethod
    def rate(self) -> float:
        """The arm's control rate, Hz (readings come at most this often)."""

    @abstractmethod
    def connect(self) -> None:
        """Reach the arm and get ready to follow targets (the hand stays where it is)."""

    @abstractmethod
    def read(self, timeout: float) -> Reading | None:
        """The arm's next state; None when none came within ``timeout`` s. Raises
        RobotFault when the arm faulted."""

    @abstractmethod
    def command(self, T_world_ee: Array | None, stamp: float | None = None) -> None:
        """Follow this hand pose (world, 4x4), or hold where the arm is (None). Called
        after each :meth:`read` with the newest admitted target and its sender's
        ``stamp`` (Unix time, s: differences of stamps give the target's velocity)."""

    @abstractmethod
    def recover(self) -> None:
        """Clear a fault (reconnect after a lost link); RobotError when the arm cannot
        be recovered from here (the message says what a person must do)."""

    @property
    def has_gripper(self) -> bool:
        """Whether the driver drives a gripper (:meth:`grip`; its readings carry
        ``gripper``)."""
        return False

    def grip(self, cmd: GripperCmd) -> None:
        """Start carrying out a gripper command (``sctd/<robot>/gripper``; it returns at
        once, the fingers move on their own). The service calls it once per command
        number, never while the arm is faulted. RobotError where there is no gripper."""
        raise RobotError(f"the {self.name} driver has no gripper")

    def move_to(self, T_world_ee: Array) -> None:
        """Bring the hand to ``T_world_ee`` with the arm's own planner and limits, before
        serving (``sctd robot NAME --task T --move-to-start``: an operator's explicit
        step, never the person's input); RobotError when it cannot."""
        raise RobotError(f"the {self.name} driver cannot move to a start pose on its own")

    def close(self) -> None:  # noqa: B027 - a driver with nothing to let go
        """Stop following targets and let the link go (idempotent)."""

    def objects(self) -> dict[str, Array]:
        """The scene's object poses (world, 4x4) when the driver owns the scene."""
        return {}

    def outcome(self) -> dict[str, Any]:
        """The task's outcome fields when the driver owns the scene."""
        return {}

    def health(self) -> dict[str, Any]:
        """Driver-specific counters for the robot's status message."""
        return {}

    def __enter__(self) -> RobotDriver:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
