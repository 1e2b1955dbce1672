"""A skill's feature frames: fixed offsets from the end-effector or the task object.

Plain data below the elements: the reader checks frame references against them, the
workspace turns them into flat transforms, the model holds them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from .. import se3
from .registry import ByValue

Array = NDArray[np.float64]

BUILTIN_FRAMES = ("ee", "object")
WORLD_OBJECT = "world"  # a skill's ``object``: the world frame itself (no object pose needed)


@dataclass(frozen=True, eq=False)
class Frame(ByValue):
    """A feature frame: a fixed offset from the ee or the object.

    ``pose`` (7,) is the offset ``[x, y, z, qx, qy, qz, qw]`` as given (a skill file
    writes it back so); ``T_parent_frame`` (4, 4) is its transform, the quaternion
    normalised.
    """

    name: str
    parent: Literal["ee", "object"]
    pose: Array
    T_parent_frame: Array = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "T_parent_frame", se3.transform_from_pose(self.pose))


def builtin_frames() -> dict[str, Frame]:
    """The frames every skill has: ``ee`` and ``object``, each its own parent."""
    identity = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    return {n: Frame(n, n, identity) for n in BUILTIN_FRAMES}  # type: ignore[arg-type]
