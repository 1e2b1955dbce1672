"""Checked reading of a skill document's values: each check names the field's path.

:class:`Reader` is what every element class's ``from_yaml`` reads its parameters with,
so that all of them report errors the same way: ``file: path.to.field: problem``.
"""

from __future__ import annotations

import math
import posixpath
from collections.abc import Mapping
from typing import Any

import numpy as np

from .errors import SkillError
from .frames import Frame
from .modelfile import VectorFieldModel, vector_field_model_from_bytes
from .registry import unit_divisor


def kind_of(v: Any) -> str:
    """How a value reads in a message: ``nothing``, ``a list of 3``, ``str``, ..."""
    if v is None:
        return "nothing"
    if isinstance(v, list | tuple):
        return f"a list of {len(v)}"
    return type(v).__name__


def check_relative(file: str, where: str, rel: str) -> None:
    """Refuse a model path that is absolute or leaves the skill's directory."""
    norm = posixpath.normpath(rel)
    if (not rel or rel.startswith("/") or norm == "." or norm == ".." or norm.startswith("../")
            or "\\" in rel or "\0" in rel):
        raise SkillError(file, where, f"model path {rel!r} must be relative, inside the skill dir")


class Reader:
    """Checks on the values of one skill document.

    Parameters
    ----------
    file : str
        The skill file's name, for messages.
    files : mapping of str to bytes
        The bundle's model files by relative path (:meth:`model` reads them).
    """

    def __init__(self, file: str, files: Mapping[str, bytes]):
        self.file = file
        self.files = files
        self.frames: dict[str, Frame] = {}  # the skill's frames, once read
        self._models: dict[str, VectorFieldModel] = {}

    def fail(self, path: str, problem: str) -> SkillError:
        """The error to raise for ``path``."""
        return SkillError(self.file, path, problem)

    def mapping(self, v: Any, path: str) -> dict:
        if not isinstance(v, dict):
            raise self.fail(path, f"expected a mapping, got {kind_of(v)}")
        return v

    def known_keys(self, d: dict, path: str, allowed: set[str]) -> None:
        extra = sorted(set(map(str, d)) - allowed)
        if extra:
            where = f"{path}.{extra[0]}" if path else extra[0]  # (a top-level field: its name alone)
            raise self.fail(where, f"unknown field (allowed: {', '.join(sorted(allowed))})")

    def string(self, v: Any, path: str) -> str:
        if not isinstance(v, str) or not v:
            raise self.fail(path, f"expected a non-empty string, got {kind_of(v)}")
        return v

    def number(self, v: Any, path: str, lo: float | None = None, hi: float | None = None,
               lo_open: bool = False) -> float:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise self.fail(path, f"expected a number, got {kind_of(v)}")
        x = float(v)
        if not math.isfinite(x):
            raise self.fail(path, f"must be finite, got {x}")
        if lo is not None and (x < lo or (lo_open and x == lo)):
            raise self.fail(path, f"must be {'>' if lo_open else '>='} {lo}, got {x}")
        if hi is not None and x > hi:
            raise self.fail(path, f"must be <= {hi}, got {x}")
        return x

    def boolean(self, v: Any, path: str) -> bool:
        if not isinstance(v, bool):
            raise self.fail(path, f"expected true or false, got {kind_of(v)}")
        return v

    def integer(self, v: Any, path: str, lo: int = 0) -> int:
        if isinstance(v, bool) or not isinstance(v, int):
            raise self.fail(path, f"expected an integer, got {kind_of(v)}")
        if v < lo:
            raise self.fail(path, f"must be >= {lo}, got {v}")
        return v

    def vector(self, v: Any, path: str, n: int, unit: bool = False) -> np.ndarray:
        """``n`` finite numbers (shape (n,)); normalised when ``unit``."""
        if not isinstance(v, list | tuple) or len(v) != n:
            raise self.fail(path, f"expected a list of {n} numbers, got {kind_of(v)}")
        out = np.array([self.number(x, f"{path}[{i}]") for i, x in enumerate(v)])
        if unit:
            norm = float(np.linalg.norm(out))
            if norm < 1e-9:
                raise self.fail(path, "direction of zero length")
            out = out / unit_divisor(norm)
        return out

    def pose(self, v: Any, path: str) -> np.ndarray:
        """A pose [x, y, z, qx, qy, qz, qw] (shape (7,)) whose quaternion is unit (to 1e-3)."""
        p = self.vector(v, path, 7)
        n = float(np.linalg.norm(p[3:]))
        if abs(n - 1.0) > 1e-3:
            raise self.fail(path, f"quaternion [qx, qy, qz, qw] must be unit, has norm {n:.6f}")
        return p

    def choice(self, v: Any, path: str, options: tuple[str, ...]) -> str:
        if v not in options:
            raise self.fail(path, f"expected one of {', '.join(options)}, got {v!r}")
        return v

    def frame_ref(self, v: Any, path: str) -> str:
        """The name of one of the skill's frames."""
        name = self.string(v, path)
        if name not in self.frames:
            raise self.fail(path, f"unknown frame {name!r} (known: {', '.join(self.frames)})")
        return name

    def ee_frame_ref(self, v: Any, path: str) -> str:
        """The name of a frame that moves with the end-effector (the ee or a child)."""
        name = self.frame_ref(v, path)
        if self.frames[name].parent != "ee" and name != "ee":
            raise self.fail(path, f"frame {name!r} must move with the end-effector (parent: ee)")
        return name

    def model(self, rel: str, path: str) -> VectorFieldModel:
        """The vector-field model file ``rel`` of the bundle (read once per file)."""
        check_relative(self.file, path, rel)
        if rel in self._models:
            return self._models[rel]
        if rel not in self.files:
            raise self.fail(path, f"model file {rel!r} is missing")
        where = posixpath.join(posixpath.dirname(self.file), rel)
        model = vector_field_model_from_bytes(self.files[rel], rel, where)
        self._models[rel] = model
        return model
