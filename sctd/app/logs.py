"""Where a run's logs go: the folder ``--logs`` names, which is always kept, or a
temporary one, which is removed when the command succeeds and kept when it fails (the
error names it), so that a clean run leaves nothing behind in the temporary directory.

``sctd``'s entry point (:func:`sctd.cli.main.main`) calls :func:`finish` with the
command's outcome."""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

_TEMPORARY: list[Path] = []


def log_folder(given: str | Path | None, prefix: str) -> Path:
    """``given`` (made if missing), else a new temporary folder named ``<prefix>...``
    that :func:`finish` removes on success."""
    if given:
        path = Path(given)
        path.mkdir(parents=True, exist_ok=True)
        return path
    path = Path(tempfile.mkdtemp(prefix=prefix))
    _TEMPORARY.append(path)
    return path


def finish(succeeded: bool) -> None:
    """Remove the temporary log folders of a run that succeeded (and the empty ones of
    any run); name on stderr those of a failed run, which are kept."""
    while _TEMPORARY:
        path = _TEMPORARY.pop()
        if succeeded or not path.exists() or not any(path.iterdir()):
            shutil.rmtree(path, ignore_errors=True)
        else:
            print(f"sctd: the logs of this run are kept in {path}", file=sys.stderr, flush=True)
