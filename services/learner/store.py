"""The learner's store: demonstrations by task, trained skills by content id.

Layout (``docs/learner.md``)::

    <store>/demos/<task>/<name>.csv     a demonstration, the recorder's CSV
    <store>/demos/<task>/<name>.json    where it came from: object, key, received
    <store>/skills/<id>/<name>.yaml     a trained skill's bundle (YAML and model files)
    <store>/skills/<id>/record.json     its record (sctd.skill.catalog reads it)

Every file appears complete or not at all: it is written under a hidden temporary
name and renamed (a skill's folder as a whole), so a learner killed at any moment
(kill -9 included) leaves a store that a restarted one reads; the temporary leftovers
are removed when a store is opened.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sctd.learn.demos import Demo, read_demo_csv
from sctd.learn.summary import plain
from sctd.skill import Bundle
from sctd.skill.catalog import RECORD, StoredSkill, read_record, stored_skills
from sctd.wire import codec

COLUMNS = ",".join(codec.DEMO_COLUMNS)
MAX_DEMOS_PER_TASK = 1000  # demonstrations one task may hold
MAX_TASK_BYTES = 256 * 1024 * 1024  # their CSVs together


class StoreFull(ValueError):
    """A demonstration the store has no room for: ``reason`` (a short tag) and what."""

    def __init__(self, reason: str, detail: str):
        self.reason = reason
        super().__init__(detail)


def _hidden(name: str) -> bool:
    return name.startswith(".")


def _write_atomic(path: Path, data: bytes) -> None:
    """``path`` with ``data``, all or nothing (a hidden temporary file, then a rename)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def csv_text(rows: list[list[float]], columns: tuple[str, ...] | None = None) -> str:
    """A demonstration's CSV (the recorder's format, :func:`sctd.wire.codec.format_demo_row`:
    time to the microsecond, poses to 1e-9, the fingers' width to the micrometre and
    grasped 0/1 where the rows have them, the other bodies' poses where ``columns`` name
    them; None: the pose's and the gripper's by the rows' width)."""
    cols = codec.demo_columns(rows) if columns is None else columns
    lines = [",".join(cols)] + [codec.format_demo_row(r, cols) for r in rows]
    return "\n".join(lines) + "\n"


class SkillRecord:
    """A stored skill's record (``record.json``): read once, changed in memory
    (:meth:`update`), and written whole, all or nothing (:meth:`save`), when a change
    must be on disk.

    Attributes
    ----------
    path : Path
    data : dict
        The record as it will be written.
    """

    def __init__(self, path: Path, data: dict[str, Any]):
        self.path = path
        self.data = data

    @classmethod
    def read(cls, path: Path) -> SkillRecord:
        return cls(path, json.loads(path.read_text()))

    def update(self, changes: dict[str, Any]) -> None:
        """Merge ``changes`` in (top-level keys replaced); nothing is written."""
        self.data.update(changes)

    def save(self) -> None:
        _write_atomic(self.path, json.dumps(self.data, indent=1, default=plain).encode())


@dataclass(frozen=True)
class StoredDemo:
    """A demonstration in the store."""

    task: str
    name: str
    path: Path  # the CSV
    object: str
    duplicate: bool = False  # it was already stored (same name, same rows)


class Store:
    """A store folder (created when missing).

    Parameters
    ----------
    root : path
    """

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.demos_dir = self.root / "demos"
        self.skills_dir = self.root / "skills"
        self.demos_dir.mkdir(parents=True, exist_ok=True)
        self.skills_dir.mkdir(parents=True, exist_ok=True)
        self.cleaned = self._clean()

    def _clean(self) -> int:
        """Remove what a killed learner left half-written; how many there were."""
        n = 0
        for folder in [self.skills_dir, *[p for p in self.demos_dir.iterdir() if p.is_dir()]]:
            for p in folder.iterdir():
                if _hidden(p.name) and (p.name.endswith(".tmp") or p.name.startswith(".new-")):
                    shutil.rmtree(p) if p.is_dir() else p.unlink(missing_ok=True)
                    n += 1
        return n

    # --- demonstrations -------------------------------------------------------------

    def add_demo(self, msg: codec.DemoMsg, key: str = "") -> StoredDemo:
        """Store a decoded demonstration under its task and name. The same name with the
        same rows is a duplicate (stored once); the same name with other rows is kept
        too, as ``<name>-<hash>``: nothing a recorder sent is lost. A task holds at most
        :data:`MAX_DEMOS_PER_TASK` demonstrations and :data:`MAX_TASK_BYTES` of them
        (``StoreFull`` past them)."""
        folder = self.demos_dir / msg.task
        folder.mkdir(parents=True, exist_ok=True)
        text = csv_text(msg.rows, msg.columns)
        name = msg.name
        path = folder / f"{name}.csv"
        if not path.exists():
            self._room_for(msg.task, len(text))
        if path.exists():
            if path.read_text() == text:
                return StoredDemo(msg.task, name, path, msg.object, duplicate=True)
            name = f"{msg.name}-{hashlib.sha256(text.encode()).hexdigest()[:8]}"
            path = folder / f"{name}.csv"
            if path.exists():
                return StoredDemo(msg.task, name, path, msg.object, duplicate=True)
        meta = {"task": msg.task, "name": name, "sent_as": msg.name, "object": msg.object,
                "key": key, "received": time.time(), "rows": len(msg.rows)}
        _write_atomic(folder / f"{name}.json", json.dumps(meta, indent=1).encode())
        _write_atomic(path, text.encode())  # the CSV last: a listed demonstration is complete
        return StoredDemo(msg.task, name, path, msg.object)

    def _room_for(self, task: str, size: int) -> None:
        """StoreFull when a new demonstration of ``size`` bytes would take ``task`` past
        :data:`MAX_DEMOS_PER_TASK` or :data:`MAX_TASK_BYTES`."""
        csvs = [p for p in (self.demos_dir / task).glob("*.csv") if not _hidden(p.name)]
        if len(csvs) >= MAX_DEMOS_PER_TASK:
            raise StoreFull("task_full", f"task {task!r} holds {len(csvs)} demonstrations, the most "
                                         f"a task may hold ({MAX_DEMOS_PER_TASK})")
        used = sum(p.stat().st_size for p in csvs)
        if used + size > MAX_TASK_BYTES:
            raise StoreFull("task_full", f"task {task!r} holds {used} bytes of demonstrations; "
                                         f"{size} more would pass the {MAX_TASK_BYTES} allowed")

    def tasks(self) -> dict[str, int]:
        """Demonstrations per task."""
        return {p.name: len(self.demo_names(p.name))
                for p in sorted(self.demos_dir.iterdir()) if p.is_dir() and not _hidden(p.name)}

    def demo_names(self, task: str) -> list[str]:
        """The task's demonstrations, by name."""
        return sorted(p.stem for p in (self.demos_dir / task).glob("*.csv") if not _hidden(p.name))

    def demo_object(self, task: str, name: str) -> str | None:
        """The object a stored demonstration's poses are in (None if unknown)."""
        try:
            return str(json.loads((self.demos_dir / task / f"{name}.json").read_text())["object"])
        except (OSError, ValueError, KeyError, TypeError):
            return None

    def load_demos(self, task: str, names: list[str] | None = None) -> list[Demo]:
        """The task's demonstrations (all, or those named) as the learner reads them.

        Raises
        ------
        KeyError
            A name the task does not have (all of them named), or none at all.
        sctd.learn.DemoError
            A stored file the learner refuses, naming it and its row.
        """
        known = self.demo_names(task)
        wanted = known if names is None else list(names)
        missing = [n for n in wanted if n not in known]
        if missing:
            raise KeyError(f"task {task!r} has no demonstration(s) {', '.join(missing)} "
                           f"(stored: {', '.join(known) or 'none'})")
        if not wanted:
            raise KeyError(f"no demonstrations of task {task!r} in {self.demos_dir} "
                           f"(tasks: {', '.join(self.tasks()) or 'none'})")
        return [read_demo_csv(self.demos_dir / task / f"{n}.csv") for n in wanted]

    # --- skills ---------------------------------------------------------------------

    def add_skill(self, bundle: Bundle, record: dict[str, Any]) -> StoredSkill:
        """Store a skill's bundle and record under its content id (a skill already stored
        keeps its files; its record is replaced)."""
        sid = bundle.id
        folder = self.skills_dir / sid
        name = Path(bundle.name).stem
        rec = {**record, "id": sid, "name": name, "created": record.get("created", time.time())}
        if not folder.is_dir():
            tmp = Path(tempfile.mkdtemp(prefix=".new-", dir=self.skills_dir))
            try:
                for rel, data in bundle.files.items():
                    (tmp / rel).parent.mkdir(parents=True, exist_ok=True)
                    (tmp / rel).write_bytes(data)
                (tmp / f"{name}.yaml").write_text(bundle.yaml_text)
                (tmp / RECORD).write_text(json.dumps(rec, indent=1, default=plain))
                os.rename(tmp, folder)  # the whole entry appears at once
            except BaseException:
                shutil.rmtree(tmp, ignore_errors=True)
                raise
        else:
            existing = self.record(sid)
            existing.update(rec)
            existing.save()
        stored = read_record(folder)
        assert stored is not None
        return stored

    def record(self, sid: str) -> SkillRecord:
        """The record of the stored skill with content id ``sid``, as it is on disk."""
        return SkillRecord.read(self.skills_dir / sid / RECORD)

    def skill(self, sid: str) -> StoredSkill | None:
        """The stored skill with content id ``sid`` (exactly), or None."""
        folder = self.skills_dir / sid
        return read_record(folder) if folder.is_dir() else None

    def skills(self) -> list[StoredSkill]:
        """Every stored skill, oldest first."""
        return stored_skills(self.root)

