"""The active skill's bundle, kept by the skill server for whoever may read it.

A view (``sctd view``) needs the whole active skill, field models included, which the
summary does not carry. The daemon never holds a bundle while it ticks (wire contract:
"Who answers"), so the bytes are kept on disk, in a folder of the daemon's own (mode
0700, removed when it stops), by the process that has them anyway: the daemon writes the
bundle it started with before it ticks, the skill server each bundle it swapped in. A
skill server that dies and is started again finds them there. The file's name is the
skill's id (its content hash), so the bundle served is the one with the id the daemon
reports as active, byte for byte. A skill set's skills (its members and teleoperation)
are all kept while it runs: any of them may become the active one without a swap.
"""

from __future__ import annotations

import os
from collections.abc import Collection
from pathlib import Path

KEEP = 4  # bundles kept at most (the active one and the ones swapped in just before it)
SUFFIX = ".bundle"


def keep(folder: str | Path, skill_id: str, data: bytes, limit: int = KEEP,
         pinned: Collection[str] = ()) -> None:
    """Store the packed bundle ``data`` of the skill ``skill_id`` in ``folder`` (written
    whole, then renamed into place), and drop the oldest beyond ``limit``, never one of
    the ids ``pinned`` (a skill set's skills, which may run again without a swap)."""
    folder = Path(folder)
    path = folder / f"{skill_id}{SUFFIX}"
    part = folder / f".{skill_id}.part"
    part.write_bytes(data)
    os.replace(part, path)
    os.utime(path)  # newest, also when it was kept before (a swap back)
    kept_files = sorted((p for p in folder.glob(f"*{SUFFIX}") if p.name[:-len(SUFFIX)] not in pinned),
                        key=lambda p: p.stat().st_mtime_ns, reverse=True)
    for old in kept_files[limit:]:
        old.unlink(missing_ok=True)


def kept(folder: str | Path, skill_id: str) -> bytes | None:
    """The packed bundle of ``skill_id`` kept in ``folder``, or None."""
    if not folder or not skill_id or not skill_id.isalnum():
        return None
    try:
        return (Path(folder) / f"{skill_id}{SUFFIX}").read_bytes()
    except OSError:
        return None
