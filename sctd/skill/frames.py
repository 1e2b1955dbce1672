"""A skill's feature frames: fixed offsets from the end-effector or the task object.

Plain data below the elements: the reader checks frame references against them, the
workspace turns them into flat transforms, the model holds them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from .registry import ByValue

Array = NDArray[np.float64]

BUILTIN_FRAMES = ("ee", "object")
WORLD_OBJECT = "world"  # a skill's ``object``: the world frame itself (no object pose needed)


@dataclass(frozen=True, eq=False)
class Frame(ByValue):
    """A feature frame: a fixed offset ``T_parent_frame`` (4, 4) from the ee or the object."""

    name: str
    parent: Literal["ee", "object"]
    T_parent_frame: Array


def builtin_frames() -> dict[str, Frame]:
    """The frames every skill has: ``ee`` and ``object``, each its own parent."""
    return {n: Frame(n, n, np.eye(4)) for n in BUILTIN_FRAMES}  # type: ignore[arg-type]
