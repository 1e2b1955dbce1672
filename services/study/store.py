"""A study folder: what was measured, one participant per folder, written crash-safe.

Layout (``docs/study.md``)::

    DIR/plan.yaml              the plan the study runs (a copy, written once)
    DIR/P01/trials.csv         one row per finished or aborted trial (:data:`COLUMNS`)
    DIR/P01/answers.json       the questionnaires, one entry per block
    DIR/P01/logs/step-003.json a trial's log, named in its row by a path relative to DIR/P01

Crash safety: a kill at any moment loses at most the trial in progress.

- ``trials.csv`` is created whole (header written to a temporary file, fsync, rename)
  and then only appended to: one row per write of one line, then ``fsync``. A kill
  during a write can leave a last line without its newline; readers ignore it and say so
  (:class:`Trials`), and the next append first cuts it off (keeping it in
  ``dropped.txt``), so that a row never runs into a fragment.
- ``answers.json``, ``plan.yaml`` and every log are replaced whole: written to a
  temporary file in the same folder, fsync, rename, then the folder fsync'd.

The writer API (:class:`StudyStore`) is what a runner calls: :meth:`~StudyStore.
record_trial` after a trial, :meth:`~StudyStore.mark_aborted` for a trial stopped before
its end, :meth:`~StudyStore.record_answers` after a block's questionnaires, and
:meth:`~StudyStore.progress` on (re)start to learn what comes next.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .errors import StudyError
from .plan import Plan, Step, plan_from_yaml, plan_to_yaml
from .questionnaires import check_answers, check_participant_id

PLAN_FILE = "plan.yaml"
TRIALS_FILE = "trials.csv"
ANSWERS_FILE = "answers.json"
DROPPED_FILE = "dropped.txt"
LOGS = "logs"
COLUMNS = ("step", "participant", "condition", "task", "order", "trial", "practice", "seed", "success",
           "outcome", "reason", "completion_time_s", "duration_s", "mode_switches", "effort", "aborted",
           "log")
"""The columns of ``trials.csv``, in order (``docs/study.md`` says what each holds)."""


def write_atomic(path: Path, text: str) -> None:
    """``path`` holds ``text``, all or nothing: a temporary file in its folder, fsync,
    rename, fsync of the folder (so the rename itself survives a power cut)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)


def _fsync_dir(folder: Path) -> None:
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def append_line(path: Path, line: str) -> None:
    """Append one line (``line`` ends in a newline) with one write, then fsync."""
    fd = os.open(path, os.O_WRONLY | os.O_APPEND)
    try:
        data = line.encode("utf-8")
        if os.write(fd, data) != len(data):
            raise OSError(f"{path}: short write")
        os.fsync(fd)
    finally:
        os.close(fd)


@dataclass(frozen=True)
class TrialRow:
    """One row of ``trials.csv``: a plan step and what came of it (``success`` None and
    ``aborted`` True for a trial stopped before its end)."""

    step: int
    participant: str
    condition: str
    task: str
    order: int
    trial: int
    practice: bool
    seed: int
    success: bool | None
    outcome: str
    reason: str
    completion_time_s: float | None
    duration_s: float | None
    mode_switches: int | None
    effort: float | None
    aborted: bool = False
    log: str = ""

    @classmethod
    def of(cls, participant: str, step: Step, result: Mapping[str, Any], log: str = "") -> TrialRow:
        """The row of ``step`` from a trial's result (``TrialResult.as_dict()`` of
        :mod:`sctd_services.eval.trial`: ``outcome``, ``reason``, ``time_s``,
        ``duration_s``, ``mode_switches``, ``effort``)."""
        outcome = str(result["outcome"])
        return cls(step.index, participant, step.condition, step.task, step.order, step.trial, step.practice,
                   step.seed, outcome == "success", outcome, str(result.get("reason", "")),
                   _num(result.get("time_s")), _num(result.get("duration_s")),
                   None if result.get("mode_switches") is None else int(result["mode_switches"]),
                   _num(result.get("effort")), False, log)

    def csv_line(self) -> str:
        buf = io.StringIO()
        csv.writer(buf, lineterminator="\n").writerow([_cell(getattr(self, c)) for c in COLUMNS])
        return buf.getvalue()

    @classmethod
    def parse(cls, cells: list[str]) -> TrialRow:
        if len(cells) != len(COLUMNS):
            raise ValueError(f"{len(cells)} cells, expected {len(COLUMNS)}")
        d = dict(zip(COLUMNS, cells, strict=True))
        return cls(int(d["step"]), d["participant"], d["condition"], d["task"], int(d["order"]),
                   int(d["trial"]), _bool(d["practice"]) is True, int(d["seed"]), _bool(d["success"]),
                   d["outcome"], d["reason"],
                   _num(d["completion_time_s"]), _num(d["duration_s"]),
                   None if d["mode_switches"] == "" else int(d["mode_switches"]), _num(d["effort"]),
                   _bool(d["aborted"]) is True, d["log"])


def _num(v: Any) -> float | None:
    if v is None or v == "":
        return None
    x = float(v)
    return x if math.isfinite(x) else None


def _bool(v: str) -> bool | None:
    if v == "":
        return None
    if v not in ("0", "1"):
        raise ValueError(f"{v!r} is not 0 or 1")
    return v == "1"


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, float):
        return f"{v:.4f}".rstrip("0").rstrip(".")
    return str(v)


@dataclass
class Trials:
    """What a ``trials.csv`` holds: its rows, and the problems met reading it (a last
    line cut short by a kill, a malformed row): each was skipped, none is fatal."""

    rows: list[TrialRow] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


def read_trials(path: Path) -> Trials:
    """The rows of ``path`` (none when it does not exist), tolerating a truncated last
    line and malformed rows (:class:`Trials`); a wrong header is a :class:`StudyError`."""
    out = Trials()
    if not path.exists():
        return out
    text = path.read_text(encoding="utf-8", errors="replace")
    lines = text.split("\n")
    if lines and lines[-1] != "":
        out.problems.append(f"{path}: line {len(lines)}: cut short ({lines[-1][:40]!r}...): the trial being "
                            "written when the writer stopped; ignored")
    lines = lines[:-1]
    if not lines:
        return out
    header = next(csv.reader([lines[0]]))
    if tuple(header) != COLUMNS:
        raise StudyError(f"{path}: line 1: the header is not sctd's trials.csv header ({', '.join(COLUMNS)})")
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        try:
            out.rows.append(TrialRow.parse(next(csv.reader([line]))))
        except (ValueError, StopIteration) as e:
            out.problems.append(f"{path}: line {n}: not a trial row ({e}); ignored")
    return out


@dataclass(frozen=True)
class Progress:
    """Where a participant is in the plan: ``next_step`` the first trial without a
    finished row (None: all done; an aborted trial is run again), ``answers_due`` the
    block (condition, task) whose questionnaires are due before anything else (None:
    none), ``done`` and ``total`` the finished and planned trials, ``aborted`` rows."""

    participant: str
    done: int
    total: int
    next_step: Step | None
    answers_due: tuple[str, str] | None
    aborted: int

    @property
    def finished(self) -> bool:
        return self.next_step is None and self.answers_due is None


class StudyStore:
    """A study folder (module doc) for the plan it was created with.

    Parameters
    ----------
    directory : Path
    plan : Plan
    """

    def __init__(self, directory: Path, plan: Plan):
        self.directory = Path(directory)
        self.plan = plan

    @classmethod
    def create(cls, directory: str | Path, plan: Plan) -> StudyStore:
        """The folder for ``plan``: made with its copy of the plan, or opened when it has
        that plan already; a :class:`StudyError` when it has another."""
        d = Path(directory)
        text = plan_to_yaml(plan)
        existing = d / PLAN_FILE
        if existing.exists():
            if plan_from_yaml(existing.read_text(encoding="utf-8"), str(existing)) != plan:
                raise StudyError(f"{existing}: the folder holds another plan; use a new folder, or that plan")
        else:
            write_atomic(existing, text)
        return cls(d, plan)

    @classmethod
    def open(cls, directory: str | Path, plan: Plan | None = None) -> StudyStore:
        """An existing folder with ``plan``, or the plan it holds."""
        d = Path(directory)
        if not d.is_dir():
            raise StudyError(f"{d}: no such study folder")
        if plan is None:
            f = d / PLAN_FILE
            if not f.exists():
                raise StudyError(f"{f}: no plan in the folder (pass --plan)")
            plan = plan_from_yaml(f.read_text(encoding="utf-8"), str(f))
        return cls(d, plan)

    def folder(self, participant: str) -> Path:
        """The participant's folder (the id checked first: a pseudonym)."""
        check_participant_id(participant)
        self.plan.schedule(participant)
        return self.directory / participant

    def _trials_file(self, participant: str) -> Path:
        """The participant's ``trials.csv``, made with its header when new, a fragment
        a kill left at its end cut off (and kept in ``dropped.txt``)."""
        path = self.folder(participant) / TRIALS_FILE
        if not path.exists():
            write_atomic(path, ",".join(COLUMNS) + "\n")
            return path
        with open(path, "rb+") as fh:
            data = fh.read()
            if data and not data.endswith(b"\n"):
                cut = data.rfind(b"\n") + 1
                with open(path.parent / DROPPED_FILE, "ab") as note:
                    note.write(data[cut:] + b"\n")
                    note.flush()
                    os.fsync(note.fileno())
                fh.truncate(cut)
                fh.flush()
                os.fsync(fh.fileno())
        return path

    def _step(self, participant: str, index: int) -> Step:
        check_participant_id(participant)
        steps = self.plan.schedule(participant).steps()
        if not 0 <= index < len(steps):
            raise StudyError(f"participant {participant}: step {index}: the plan has steps "
                             f"0-{len(steps) - 1}")
        return steps[index]

    def write_log(self, participant: str, step: int, log: Mapping[str, Any]) -> str:
        """Write a trial's log (JSON) whole; returns its path relative to the participant's
        folder, for the trial's row."""
        rel = f"{LOGS}/step-{step:03d}.json"
        write_atomic(self.folder(participant) / rel, json.dumps(log))
        return rel

    def record_trial(self, participant: str, step: int, result: Mapping[str, Any],
                     log: Mapping[str, Any] | None = None) -> TrialRow:
        """Append the finished trial ``step`` (an index into the participant's schedule)
        with its ``result`` (:meth:`TrialRow.of`) and, given, its log (written first)."""
        s = self._step(participant, step)
        rel = self.write_log(participant, step, log) if log is not None else ""
        row = TrialRow.of(participant, s, result, rel)
        append_line(self._trials_file(participant), row.csv_line())
        return row

    def mark_aborted(self, participant: str, step: int, reason: str,
                     duration_s: float | None = None) -> TrialRow:
        """Append trial ``step`` as aborted (stopped before its end: the person asked, a
        safety stop, a fault). It is left out of the analysis and run again on resume."""
        s = self._step(participant, step)
        row = TrialRow(s.index, participant, s.condition, s.task, s.order, s.trial, s.practice, s.seed, None,
                       "aborted", reason, None, duration_s, None, None, True, "")
        append_line(self._trials_file(participant), row.csv_line())
        return row

    def record_answers(self, participant: str, condition: str, task: str, answers: Mapping[str, Any]) -> None:
        """Store a block's questionnaires (checked and scored first,
        :func:`~.questionnaires.check_answers`; a block answered again is replaced)."""
        blocks = self.plan.schedule(participant).blocks
        if not any(b.condition == condition and b.task == task for b in blocks):
            raise StudyError(f"participant {participant}: condition {condition}, task {task}: no such block "
                             "in the plan")
        scored = check_answers(answers, f"participant {participant}, condition {condition}, task {task}")
        doc = self.answers(participant)
        doc["blocks"] = [b for b in doc["blocks"] if (b["condition"], b["task"]) != (condition, task)]
        doc["blocks"].append({"condition": condition, "task": task, **scored})
        write_atomic(self.folder(participant) / ANSWERS_FILE, json.dumps(doc, indent=1))

    def answers(self, participant: str) -> dict[str, Any]:
        """The participant's ``answers.json`` (``{"v", "participant", "blocks": [...]}``)."""
        path = self.folder(participant) / ANSWERS_FILE
        if not path.exists():
            return {"v": 1, "participant": participant, "blocks": []}
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as e:
            raise StudyError(f"{path}: not JSON: {e}") from None
        if not isinstance(doc, dict) or not isinstance(doc.get("blocks"), list):
            raise StudyError(f"{path}: blocks: missing")
        return doc

    def trials(self, participant: str) -> Trials:
        """The participant's rows (:func:`read_trials`)."""
        return read_trials(self.folder(participant) / TRIALS_FILE)

    def progress(self, participant: str) -> Progress:
        """What comes next for ``participant`` (:class:`Progress`): resume from here."""
        steps = self.plan.schedule(participant).steps()
        rows = self.trials(participant).rows
        finished = {r.step for r in rows if not r.aborted}
        answered = {(b["condition"], b["task"]) for b in self.answers(participant)["blocks"]}
        nxt = next((s for s in steps if s.index not in finished), None)
        due = None
        for b in self.plan.schedule(participant).blocks:
            mine = [s for s in steps if (s.condition, s.task) == (b.condition, b.task)]
            if nxt is not None and nxt in mine:
                break
            if (b.condition, b.task) not in answered:
                due = (b.condition, b.task)
                break
        return Progress(participant, len(finished & {s.index for s in steps}), len(steps), nxt, due,
                        sum(r.aborted for r in rows))

    def participants(self) -> list[str]:
        """The plan's participants that have a folder here."""
        return [s.participant for s in self.plan.participants if (self.directory / s.participant).is_dir()]
