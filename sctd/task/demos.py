"""What a folder of demonstrations is of: its ``demos.yaml``.

Beside the demonstration CSVs (:mod:`sctd.learn.demos`), ``demos.yaml``
(:data:`DEMOS_FILE`) names the task they show and the task object whose frame their
poses are in. ``sctd teach`` and ``sctd record`` write it with the first demonstration
they keep in a folder, and refuse to add another object's; ``sctd learn`` reads it
(:func:`read_demos_info`), so that a skill learned from the folder is in that object's
frame without naming it again::

    sctd_demos: 1
    task: pour
    object: mug
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..files import FileError, load_yaml

DEMOS_FILE = "demos.yaml"  # beside the CSVs: what they are demonstrations of
DEMOS_VERSION = 1


class DemosInfoError(ValueError):
    """A ``demos.yaml`` sctd will not take: ``path: problem``."""


@dataclass(frozen=True)
class DemosInfo:
    """What a folder's demonstrations are of: the task, and the task object whose frame
    their poses are in (a skill learned from them is in that frame)."""

    task: str
    object: str

    def to_yaml(self) -> str:
        return (f"# what the demonstrations in this folder are of (sctd learn reads it)\n"
                f"sctd_demos: {DEMOS_VERSION}\ntask: {self.task}\nobject: {self.object}\n")


def read_demos_info(directory: str | Path) -> DemosInfo | None:
    """The folder's :data:`DEMOS_FILE`, or None where there is none.

    Raises
    ------
    DemosInfoError
        The file is not a mapping with ``sctd_demos: 1`` and a non-empty ``task`` and
        ``object`` (named by the file and the key).
    """
    path = Path(directory) / DEMOS_FILE
    if not path.exists():
        return None
    try:
        doc = load_yaml(path)
    except FileError as exc:
        raise DemosInfoError(str(exc)) from None
    if not isinstance(doc, dict):
        raise DemosInfoError(f"{path}: expected a mapping (sctd_demos, task, object)")
    if doc.get("sctd_demos") != DEMOS_VERSION:
        raise DemosInfoError(f"{path}: sctd_demos: expected {DEMOS_VERSION}, got {doc.get('sctd_demos')!r}")
    for key in ("task", "object"):
        v = doc.get(key)
        if not isinstance(v, str) or not v.strip():
            raise DemosInfoError(f"{path}: {key}: expected a name, got {v!r}")
    unknown = sorted(set(doc) - {"sctd_demos", "task", "object"})
    if unknown:
        raise DemosInfoError(f"{path}: unknown key(s): {', '.join(map(str, unknown))}")
    return DemosInfo(doc["task"], doc["object"])
