"""Wire contract v1: the key expressions of one robot, ``sctd/<robot>/...``
(docs/wire-contract.md)."""

from __future__ import annotations

from dataclasses import dataclass

DEFAULT_ROBOT = "edan"


@dataclass(frozen=True)
class Keys:
    """The key expressions of one robot (``sctd/<robot>/...``)."""

    robot: str = DEFAULT_ROBOT

    def __post_init__(self) -> None:
        if not self.robot or any(c in self.robot for c in "/*$?#"):
            raise ValueError(f"robot name {self.robot!r} must be a single key chunk")

    @property
    def prefix(self) -> str:
        return f"sctd/{self.robot}"

    def input(self, device: str = "*") -> str:
        return f"{self.prefix}/input/{device}"

    @property
    def state(self) -> str:
        return f"{self.prefix}/state"

    def objects(self, name: str = "*") -> str:
        return f"{self.prefix}/objects/{name}"

    @property
    def target(self) -> str:
        return f"{self.prefix}/target"

    @property
    def gripper(self) -> str:
        return f"{self.prefix}/gripper"

    @property
    def status(self) -> str:
        return f"{self.prefix}/status"

    @property
    def skill(self) -> str:
        return f"{self.prefix}/skill"

    @property
    def skill_swap(self) -> str:
        """The swap queryable (a policy can allow summaries on ``skill`` and swaps apart)."""
        return f"{self.prefix}/skill/swap"

    @property
    def skill_bundle(self) -> str:
        """The active skill's bundle, read-only (a policy can allow it alone: an observer's
        view reads the skill it draws without the right to ask ``skill``, which swaps in
        wire contract v1)."""
        return f"{self.prefix}/skill/bundle"

    @property
    def scene(self) -> str:
        return f"{self.prefix}/scene"

    def demos(self, task: str = "*", name: str = "*") -> str:
        """``sctd/<robot>/demos/<task>/<name>``: finished demonstrations (the recorder)."""
        return f"{self.prefix}/demos/{task}/{name}"

    @property
    def learner(self) -> str:
        """``sctd/<robot>/learner``: the learner service's training queryable."""
        return f"{self.prefix}/learner"

    @property
    def learner_status(self) -> str:
        """``sctd/<robot>/learner/status``: what the learner stored, refused, is doing."""
        return f"{self.prefix}/learner/status"

    @property
    def robot_status(self) -> str:
        """``sctd/<robot>/robot``: the robot service's status (driver, connection, the
        arm's mode, its fault), from ``sctd robot`` (docs/robots.md)."""
        return f"{self.prefix}/robot"

    @property
    def robot_recover(self) -> str:
        """``sctd/<robot>/robot/recover``: the robot service's queryable that clears a
        fault (``sctd robot NAME --recover``)."""
        return f"{self.prefix}/robot/recover"

    @property
    def sim_reset(self) -> str:
        """``sctd/<robot>/sim/reset``: the simulator's scene reset (a sim-only queryable)."""
        return f"{self.prefix}/sim/reset"
