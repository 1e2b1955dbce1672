"""The command-line flags of the simulator service, defined once.

``python -m sctd_sim.service`` and ``sctd sim`` take the same flags: this module defines
them and both parse with it. It imports nothing heavy (no Pinocchio, python-can or
Zenoh beyond what :mod:`sctd.runtime` already loads), so the ``sctd`` command line
builds its parser without loading the simulator. The arm's flags (``--urdf``,
``--ee-frame``) are a group of their own, :func:`add_arm_arguments` and
:func:`arm_from_args`, for any program that runs the simulated arm.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from sctd.app.defaults import defaults
from sctd.app.options import add_arguments, add_robot_argument, add_task_argument
from sctd.wire.ros_options import add_ros_arguments
from sctd.wire.session import add_zenoh_arguments

from .guard import add_limit_arguments

if TYPE_CHECKING:
    from .robot import ArmModel


def _setting(default: Any, help: str, **meta: Any) -> Any:
    return field(default=default, metadata={"help": help, **meta})


@dataclass(frozen=True)
class SimSettings:
    """The simulator's rates and joint bus. Each field is a ``sctd sim`` flag of the same
    name (``--state-rate``, :mod:`sctd.app.options`); :class:`~sctd_sim.service.SimService`
    and :class:`~sctd_sim.simulation.Simulation` take their defaults from here."""

    rate: float = _setting(1000.0, "simulation cycle rate, Hz")
    state_rate: float = _setting(1000.0, "state publication rate, Hz, at most --rate")
    object_rate: float = _setting(50.0, "objects rate, Hz")
    scene_rate: float = _setting(10.0, "scene key (task outcome, health) rate, Hz")
    faults: str = _setting("", "joint-bus faults, e.g. drop=0.01,corrupt=0.001,delay=0.002 (also "
                               "duplicate, delay_rate, bus_off, tx=0/1, rx=0/1, seed)", metavar="SPEC")
    can_interface: str = _setting("virtual", "joint bus: python-can's in-process virtual bus (default), a "
                                             "socketcan interface such as vcan0, or auto (socketcan when "
                                             "--can-channel exists)",
                                  choices=("virtual", "socketcan", "auto"))
    can_channel: str | None = _setting(None, "socketcan interface name (default vcan0 for socketcan/auto)")
    drive_timeout: float = _setting(0.01, "drive command timeout before it brakes, s")


def add_service_arguments(p: argparse.ArgumentParser) -> None:
    """Add the simulator service's flags (see :func:`sctd_sim.service.run`) to ``p``."""
    add_task_argument(p, defaults().task,
                      help="the task whose scene to simulate: the path of a task file, or the name of "
                           "a shipped or registered one; sctd tasks lists them", several=True)
    add_robot_argument(p)
    add_arm_arguments(p)
    p.add_argument("--trial-seed", type=int, default=None, metavar="N",
                   help="start from the seeded random start N of an evaluation trial (the hand and the "
                        "objects moved within what the task file's vary fields say)")
    # three calls keep the flags' order: only the numbers say their default in the help
    add_arguments(p, SimSettings, only=("rate", "state_rate", "object_rate", "scene_rate"), show_default=True)
    add_arguments(p, SimSettings, only=("faults", "can_interface", "can_channel"))
    add_arguments(p, SimSettings, only=("drive_timeout",), show_default=True)
    add_limit_arguments(p)
    p.add_argument("--no-stamp-check", action="store_true",
                   help="do not refuse targets stamped before the simulator started (senders "
                        "with unsynchronised clocks)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--view", action="store_true",
                   help="live 3D view in a browser, served on 127.0.0.1 (needs viser: "
                        "pip install 'sctd[view]'; make setup installs it)")
    p.add_argument("--view-port", type=int, default=0, metavar="PORT",
                   help="port of the --view page on 127.0.0.1 (default 0: a free one; the URL "
                        "is printed)")
    p.add_argument("--json", action="store_true", help="print the final summary as JSON on stdout")
    add_ros_arguments(p, "the measured end effector as geometry_msgs/msg/PoseStamped on "
                         "<namespace>/ee_pose")
    add_zenoh_arguments(p)


def add_arm_arguments(p: argparse.ArgumentParser) -> None:
    """Add ``--urdf`` and ``--ee-frame``, the simulated arm (read back by
    :func:`arm_from_args`), to ``p``."""
    p.add_argument("--urdf", metavar="FILE", default=None,
                   help="the arm to simulate, as a URDF whose root is the world and whose chain to "
                        "--ee-frame is 7 revolute joints with limits and masses (other joints, such "
                        "as fingers, are locked); default: the shipped arm (docs/sim-urdf.md)")
    p.add_argument("--ee-frame", metavar="NAME", default=None,
                   help="the URDF's frame that targets move and state reports (the hand's tool "
                        "centre point); default: the shipped arm's")


def arm_from_args(args: argparse.Namespace) -> ArmModel:
    """The arm of ``--urdf`` and ``--ee-frame`` (:func:`add_arm_arguments`; each
    defaulting to the shipped arm's), checked by :func:`~sctd_sim.robot.load_arm_model`.

    Raises
    ------
    ValueError
        ``--urdf: FILE: problem``, or ``--ee-frame: FILE: problem`` when the URDF has no
        such frame.
    """
    # (Pinocchio is imported once the flags are parsed, not to build the parser)
    from .robot import EE_FRAME, URDF_PATH, ArmModelError, load_arm_model

    try:
        return load_arm_model(args.urdf or URDF_PATH, args.ee_frame or EE_FRAME)
    except ArmModelError as e:
        if e.part != "ee_frame":
            raise ValueError(f"--urdf: {e}") from None
        hint = "" if args.ee_frame else "; name the hand's frame with --ee-frame"
        raise ValueError(f"--ee-frame: {e}{hint}") from None
