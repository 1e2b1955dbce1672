"""Where a skill named on the command line is found.

``--skill`` (and ``sctd inspect``, ``swap``, ``eval``, ``demo``) take a path or a name,
resolved in this order:

1. a path that exists (``skills/pour.yaml``, ``./mine.yaml``);
2. the learner's store of trained skills (:func:`store_folder`): ``NAME@ID`` (the
   skill ``NAME`` with that content id, or an unambiguous prefix of it of at least 4
   characters), a bare ``ID`` (or such a prefix), or ``NAME``: the newest skill of
   that name;
3. the shipped skills, by name with or without ``.yaml`` (``pour``, ``pour.yaml``),
   also when given as a path that does not exist here (``skills/pour.yaml`` from
   another folder): the repository's ``skills/`` folder, which the wheel installs as
   the package data ``sctd_skills``.

An unknown name is a :class:`~sctd.skill.SkillError` that lists the places searched and
the closest names. A skill set file names its skills the same way, a path being
relative to the set file's folder (``find_skill(name, folder=...)``); ``--set`` takes a
set file's path or the name of a shipped set (``skills/sets/``, :func:`find_skill_set`).

The store's layout (written by the learner service, ``sctd_services.learner``; read
here so that every command finds what it trained): ``<store>/skills/<id>/`` holds the
skill's YAML and model files (its bundle) and ``record.json`` (``id``, ``name``,
``created`` and what the learner knows of it: task, method, demonstrations,
hyperparameters, report, evaluation).
"""

from __future__ import annotations

import difflib
import json
import os
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from .errors import SkillError

SHIPPED_PACKAGE = "sctd_skills"
STORE_ENV = "SCTD_STORE"
"""The environment variable that overrides the store's folder."""
RECORD = "record.json"
MIN_ID_PREFIX = 4


def shipped_folder() -> Path:
    """The folder of the shipped skills (``skills/`` of the checkout, or where the wheel
    installed them)."""
    return Path(str(resources.files(SHIPPED_PACKAGE)))


def shipped_skills() -> list[Path]:
    """The shipped skill files, by name."""
    return sorted(shipped_folder().glob("*.yaml"))


def store_folder() -> Path:
    """The learner's store: ``$SCTD_STORE``, else ``$XDG_DATA_HOME/sctd/store``, else
    ``~/.local/share/sctd/store`` (the XDG base directory default)."""
    given = os.environ.get(STORE_ENV)
    if given:
        return Path(given)
    data = os.environ.get("XDG_DATA_HOME") or os.path.join(os.path.expanduser("~"), ".local", "share")
    return Path(data) / "sctd" / "store"


@dataclass(frozen=True)
class StoredSkill:
    """A skill in the store: its folder, YAML file and record (``record.json``)."""

    id: str
    name: str
    created: float
    path: Path  # the YAML file
    record: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)

    @property
    def ref(self) -> str:
        """``NAME@ID``: what resolves to exactly this skill."""
        return f"{self.name}@{self.id}"


def read_record(folder: Path) -> StoredSkill | None:
    """The stored skill in ``folder`` (``<store>/skills/<id>``), or None when it is not
    a complete entry (no readable record, or its YAML is missing)."""
    try:
        rec = json.loads((folder / RECORD).read_text())
        sid, name, created = rec["id"], rec["name"], float(rec["created"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if not (isinstance(sid, str) and isinstance(name, str)) or sid != folder.name:
        return None
    path = folder / f"{name}.yaml"
    return StoredSkill(sid, name, created, path, rec) if path.is_file() else None


def stored_skills(store: Path | None = None) -> list[StoredSkill]:
    """Every complete entry of the store, oldest first (none when it does not exist)."""
    root = (store_folder() if store is None else store) / "skills"
    try:
        folders = [p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".")]
    except OSError:
        return []
    found = [s for s in map(read_record, folders) if s is not None]
    return sorted(found, key=lambda s: (s.created, s.id))


def _id_matches(wanted: str, sid: str) -> bool:
    return sid == wanted or (len(wanted) >= MIN_ID_PREFIX and sid.startswith(wanted))


def find_stored(ref: str, store: Path | None = None) -> StoredSkill | None:
    """The stored skill ``ref`` names (``NAME@ID``, ``ID``, or ``NAME``: the newest), or
    None.

    Raises
    ------
    SkillError
        An id prefix that more than one stored skill has.
    """
    skills = stored_skills(store)
    name, at, sid = ref.partition("@")
    if at:
        hits = [s for s in skills if s.name == name and _id_matches(sid, s.id)]
    else:
        by_name = [s for s in skills if s.name == ref]
        if by_name:
            return by_name[-1]
        hits = [s for s in skills if _id_matches(ref, s.id)]
    if len({s.id for s in hits}) > 1:
        raise SkillError(ref, "", "ambiguous id prefix: " + ", ".join(s.ref for s in hits))
    return hits[-1] if hits else None


def find_skill(name: str | Path, folder: str | Path | None = None) -> Path:
    """The skill file ``name`` refers to (see the module docstring for the order); with
    ``folder`` (a skill set file's), a relative path is a path in that folder, not in the
    working directory.

    Raises
    ------
    SkillError
        Neither a path, nor a stored nor a shipped skill: the message names the places
        searched and the close matches among the known names.
    """
    path = Path(name)
    if folder is not None and not path.is_absolute():
        path = Path(folder) / path
    if path.is_file():
        return path
    path = Path(name)
    text = str(name)
    if text and "/" not in text:
        stored = find_stored(text)
        if stored is not None:
            return stored.path
    shipped = shipped_folder()
    stem = path.name[:-5] if path.name.endswith(".yaml") else path.name
    if stem and path.name not in ("", ".", ".."):
        found = shipped / f"{stem}.yaml"
        if found.is_file():
            return found
    known = [p.stem for p in shipped_skills()] + sorted({s.name for s in stored_skills()})
    close = difflib.get_close_matches(stem, known, n=3, cutoff=0.5)
    hint = f"did you mean {', '.join(close)}?" if close else f"known: {', '.join(known)}"
    where = (Path(folder) / path if folder is not None and not path.is_absolute() else path).absolute()
    raise SkillError(text, "", f"no such skill: not a file ({where}), nor in the "
                               f"learner's store ({store_folder()}), nor a shipped skill in "
                               f"{shipped}; {hint}")


SETS = "sets"
"""The folder of the shipped skill sets, in the shipped skills' folder."""


def shipped_sets() -> list[Path]:
    """The shipped skill set files (``sctd run --set NAME``), by name."""
    return sorted((shipped_folder() / SETS).glob("*.yaml"))


def find_skill_set(name: str | Path) -> Path:
    """The skill set file ``name`` refers to: a path that exists, else a shipped set by
    name with or without ``.yaml`` (``kitchen``).

    Raises
    ------
    SkillError
        Neither: the message names the shipped sets.
    """
    path = Path(name)
    if path.is_file():
        return path
    stem = path.name[:-5] if path.name.endswith(".yaml") else path.name
    if stem and path.name not in (".", ".."):
        found = shipped_folder() / SETS / f"{stem}.yaml"
        if found.is_file():
            return found
    known = ", ".join(p.stem for p in shipped_sets()) or "none"
    raise SkillError(str(name), "", f"no such skill set: not a file ({path.absolute()}), nor a "
                                    f"shipped set in {shipped_folder() / SETS} (shipped: {known})")
