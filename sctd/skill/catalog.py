"""Where a skill named on the command line is found.

``--skill`` (and ``sctd inspect``, ``swap``, ``eval``, ``demo``) take a path or a name,
resolved in this order:

1. a path that exists (``skills/pour.yaml``, ``./mine.yaml``);
2. the shipped skills, by name with or without ``.yaml`` (``pour``, ``pour.yaml``),
   also when given as a path that does not exist here (``skills/pour.yaml`` from
   another folder): the repository's ``skills/`` folder, which the wheel installs as
   the package data ``sctd_skills``.

An unknown name is a :class:`~sctd.skill.SkillError` that lists the places searched and
the closest shipped names. (A learner's store of trained skills will go between 1 and
2 when the learner service exists.)
"""

from __future__ import annotations

import difflib
from importlib import resources
from pathlib import Path

from .errors import SkillError

SHIPPED_PACKAGE = "sctd_skills"


def shipped_folder() -> Path:
    """The folder of the shipped skills (``skills/`` of the checkout, or where the wheel
    installed them)."""
    return Path(str(resources.files(SHIPPED_PACKAGE)))


def shipped_skills() -> list[Path]:
    """The shipped skill files, by name."""
    return sorted(shipped_folder().glob("*.yaml"))


def find_skill(name: str | Path) -> Path:
    """The skill file ``name`` refers to (see the module docstring for the order).

    Raises
    ------
    SkillError
        Neither a path nor a shipped skill: the message names both places searched and
        the close matches among the shipped names.
    """
    path = Path(name)
    if path.is_file():
        return path
    folder = shipped_folder()
    stem = path.name[:-5] if path.name.endswith(".yaml") else path.name
    if stem and path.name not in ("", ".", ".."):
        shipped = folder / f"{stem}.yaml"
        if shipped.is_file():
            return shipped
    known = [p.stem for p in shipped_skills()]
    close = difflib.get_close_matches(stem, known, n=3, cutoff=0.5)
    hint = f"did you mean {', '.join(close)}?" if close else f"shipped: {', '.join(known)}"
    raise SkillError(str(name), "", f"no such skill: not a file ({path.absolute()}) nor a shipped "
                                    f"skill in {folder}; {hint}")
