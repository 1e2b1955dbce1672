"""The runner for people, without its processes: what the study page shows at each point
of a participant's plan, and what each of the page's requests does to the study folder
(``sctd study run --participant ID``, ``docs/study.md``, "Running a study with people").

:class:`StudyRunner` is a state machine over one participant's :class:`~.store.
StudyStore` progress. Its :meth:`~StudyRunner.screen` is one of

- ``instructions``: a block begins (and again on resume): what the condition's device
  does, the deadman, the task, how many practice and measured trials come;
- ``ready``: the next trial (practice or measured), its condition and task fixed by the
  plan's step, with the step's seed; the participant starts it;
- ``running``: the trial runs (:meth:`~StudyRunner.start` was called, no result yet);
- ``questionnaire``: a block's trials are done; its raw NASA-TLX and SUS are due;
- ``paused``: the experimenter paused (nothing starts until they continue);
- ``done``: every trial and questionnaire of the plan is recorded.

Everything that is recorded goes through the store's writer API, so what is finished is
on disk before the page is told. A trial in progress is also noted in
``DIR/<participant>/running.json`` (written whole, before the trial starts, removed
after its row): a runner that finds it on start was killed during that trial, and marks
it aborted (:meth:`~StudyRunner.recover`); the step then comes again, as
:meth:`~.store.StudyStore.progress` has every aborted trial do.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from .errors import StudyError
from .plan import Condition, Step
from .questionnaires import QUESTIONNAIRES, SUS, SUS_ITEMS, TLX, TLX_STEP, TLX_SUBSCALES
from .store import StudyStore, write_atomic

RUNNING_FILE = "running.json"
INTERRUPTED = "interrupted: the runner stopped during the trial (killed, crashed or a power cut)"
SCREENS = ("instructions", "ready", "running", "questionnaire", "paused", "done")

DEADMAN = ("Hold the deadman to move: Shift on the keyboard, the right shoulder button (RB/R1) on a "
           "gamepad, or a finger on the on-screen stick. Let go and the arm stops at once. The arm also "
           "stops when this page is hidden or loses focus.")
DEVICE = {
    "teleop": ("The arm moves as you push, in one of two modes at a time: in the first the stick moves the "
               "hand (left/right, forward/back; up/down on the second axis: w/s keys, the right stick), "
               "in the second the same axes turn it. The mode button (space or m; A on a gamepad) "
               "switches between them. Nothing guides the hand: you do all of the task yourself."),
    "skill": ("The arm helps you with this task: the stick's few axes move the hand in the ways the task "
              "needs at each stage, and the help changes as you get on (the mode button, space or m, or A, "
              "moves to the next stage; e or B goes back one). Push where you want the hand to go; the arm "
              "keeps it on a useful path."),
    "set": ("You move the hand directly until the arm sees which task you are going for; then it helps with "
            "that task as a skill does (e or B leaves the help, c or X chooses another task)."),
}


def instructions(condition: Condition, task_title: str, practice: int, trials: int) -> list[str]:
    """The paragraphs shown before a block of ``condition`` on a task (``task_title``)."""
    parts = [f"The task: {task_title}.", DEVICE[condition.kind], DEADMAN]
    if practice:
        parts.append(f"First {_trials(practice, 'practice')} to get to know it (not counted), then "
                     f"{_trials(trials, 'measured')}. Afterwards two short questionnaires about this way of "
                     "controlling the arm.")
    else:
        parts.append(f"{_trials(trials, 'measured')}, then two short questionnaires.")
    parts.append("Each trial starts when you first push with the deadman held. You may stop at any time: "
                 "let go of the deadman, and tell the experimenter.")
    return parts


def _trials(n: int, what: str) -> str:
    return f"{n} {what} trial{'s' if n != 1 else ''}"


def questionnaire_items() -> dict[str, Any]:
    """The two questionnaires as the page shows them (from :mod:`.questionnaires`)."""
    return {TLX: {"title": QUESTIONNAIRES[TLX]["title"], "step": TLX_STEP,
                  "items": [{"key": s.key, "question": s.question, "low": s.low, "high": s.high}
                            for s in TLX_SUBSCALES]},
            SUS: {"title": QUESTIONNAIRES[SUS]["title"], "items": list(SUS_ITEMS),
                  "low": "strongly disagree", "high": "strongly agree"}}


class StudyRunner:
    """One participant's way through the plan (module doc).

    Parameters
    ----------
    store : StudyStore
    participant : str
        An id of the plan (a :class:`StudyError` otherwise, naming the plan's ids).
    titles : mapping
        Task name (as the plan gives it) -> the task's title, for the instructions.

    Requests (:meth:`next`, :meth:`start`, :meth:`answer`, ...) return None when done, or
    a sentence saying why not, for the page. Not thread-safe: the caller serialises.
    """

    def __init__(self, store: StudyStore, participant: str, titles: Mapping[str, str]):
        self.store, self.participant, self.titles = store, participant, dict(titles)
        self.schedule = store.plan.schedule(participant)
        self.folder = store.folder(participant)
        self.steps = self.schedule.steps()
        self.read: tuple[str, str] | None = None  # the block whose instructions were read
        self.running: Step | None = None
        self.paused = False
        self.last: dict[str, Any] | None = None  # the last trial's outcome, for the page
        self.recovered = self.recover()

    # -- the study folder ---------------------------------------------------------------------
    def recover(self) -> str | None:
        """A trial left running by a runner that was killed: marked aborted (unless its row
        was written just before the kill); what was done, or None."""
        marker = self.folder / RUNNING_FILE
        if not marker.exists():
            return None
        try:
            index = int(json.loads(marker.read_text(encoding="utf-8"))["step"])
        except (ValueError, KeyError, TypeError) as e:
            raise StudyError(f"{marker}: not a running trial's note ({e}); remove it to go on") from None
        finished = {r.step for r in self.store.trials(self.participant).rows if not r.aborted}
        note = None
        if index not in finished:
            self.store.mark_aborted(self.participant, index, INTERRUPTED)
            note = (f"participant {self.participant}: step {index}: {INTERRUPTED}; marked aborted, it comes "
                    "again")
        marker.unlink()
        return note

    def attempt(self, step: Step) -> int:
        """The attempt ``step`` is on: 1 + the rows it already has (aborted ones)."""
        return 1 + sum(r.step == step.index for r in self.store.trials(self.participant).rows)

    # -- what the page shows ------------------------------------------------------------------
    def screen(self) -> dict[str, Any]:
        """What the page shows now: ``kind`` (:data:`SCREENS`) and what goes with it, plus
        where the participant is (``done``/``total`` trials, ``aborted``, ``block``)."""
        p = self.store.progress(self.participant)
        out: dict[str, Any] = {"participant": self.participant, "done": p.done, "total": p.total,
                               "aborted": p.aborted, "last": self.last, "blocks": self.blocks()}
        step = self.running or p.next_step
        key = p.answers_due or ((step.condition, step.task) if step is not None else None)
        if key is not None:
            out["block"] = self._block(*key)
        if self.running is not None:
            return {**out, "kind": "running", "step": self._step(self.running)}
        if self.paused:
            return {**out, "kind": "paused"}
        if p.answers_due is not None:
            return {**out, "kind": "questionnaire", "questionnaires": questionnaire_items()}
        if p.next_step is None:
            return {**out, "kind": "done"}
        if key != self.read:
            c = self.store.plan.condition(p.next_step.condition)
            return {**out, "kind": "instructions",
                    "paragraphs": instructions(c, self.titles.get(p.next_step.task, p.next_step.task),
                                               self.store.plan.practice, self.store.plan.trials)}
        return {**out, "kind": "ready", "step": self._step(p.next_step)}

    def blocks(self) -> list[dict[str, Any]]:
        """The participant's blocks in order, each with its finished trials and whether its
        questionnaires are answered (the experimenter's overview)."""
        finished = {r.step for r in self.store.trials(self.participant).rows if not r.aborted}
        answered = {(b["condition"], b["task"]) for b in self.store.answers(self.participant)["blocks"]}
        out = []
        for b in self.schedule.blocks:
            mine = [s for s in self.steps if (s.condition, s.task) == (b.condition, b.task)]
            out.append({"condition": b.condition, "task": b.task, "trials": len(mine),
                        "finished": sum(s.index in finished for s in mine),
                        "answered": (b.condition, b.task) in answered})
        return out

    def _block(self, condition: str, task: str) -> dict[str, Any]:
        keys = [(b.condition, b.task) for b in self.schedule.blocks]
        c = self.store.plan.condition(condition)
        return {"index": keys.index((condition, task)) + 1, "of": len(keys), "condition": condition,
                "kind": c.kind, "task": task, "title": self.titles.get(task, task)}

    def _step(self, s: Step) -> dict[str, Any]:
        plan = self.store.plan
        return {"index": s.index, "condition": s.condition, "task": s.task, "practice": s.practice,
                "trial": s.trial, "of": plan.practice if s.practice else plan.trials, "seed": s.seed,
                "attempt": self.attempt(s)}

    # -- the page's requests ------------------------------------------------------------------
    def _refuse(self, *kinds: str) -> str | None:
        kind = self.screen()["kind"]
        return None if kind in kinds else f"not now: the page shows {kind}"

    def next(self) -> str | None:
        """The instructions were read: the block's first (or next) trial is ready."""
        why = self._refuse("instructions")
        if why is None:
            s = self.store.progress(self.participant).next_step
            assert s is not None
            self.read = (s.condition, s.task)
        return why

    def start(self) -> Step | str:
        """The ready trial starts: noted in ``running.json`` first; the step, or why not."""
        why = self._refuse("ready")
        if why is not None:
            return why
        s = self.store.progress(self.participant).next_step
        assert s is not None
        write_atomic(self.folder / RUNNING_FILE, json.dumps({"step": s.index, "seed": s.seed,
                                                             "attempt": self.attempt(s)}))
        self.running, self.last = s, None
        return s

    def finish(self, result: Mapping[str, Any], log: Mapping[str, Any] | None) -> None:
        """The running trial ended by its task's outcome: its row (and log) recorded."""
        s = self._running()
        row = self.store.record_trial(self.participant, s.index, result, log)
        self._ended({"step": s.index, "outcome": row.outcome, "reason": row.reason,
                     "time_s": row.completion_time_s, "practice": s.practice})

    def abort(self, reason: str, duration_s: float | None = None) -> None:
        """The running trial was stopped before its end (a safety stop, a closed page, a
        pause): recorded as aborted; it comes again."""
        s = self._running()
        self.store.mark_aborted(self.participant, s.index, reason, duration_s)
        self._ended({"step": s.index, "outcome": "aborted", "reason": reason, "time_s": None,
                     "practice": s.practice})

    def _running(self) -> Step:
        if self.running is None:
            raise StudyError(f"participant {self.participant}: no trial is running")
        return self.running

    def _ended(self, last: dict[str, Any]) -> None:
        (self.folder / RUNNING_FILE).unlink(missing_ok=True)
        self.running, self.last = None, last

    def answer(self, answers: Mapping[str, Any]) -> str | None:
        """The due block's questionnaires: stored (checked and scored by the store), or the
        store's error naming the item and the value (nothing stored then)."""
        why = self._refuse("questionnaire")
        if why is not None:
            return why
        due = self.store.progress(self.participant).answers_due
        assert due is not None
        try:
            self.store.record_answers(self.participant, *due, answers)
        except StudyError as e:
            return str(e)
        return None

    def pause(self) -> None:
        """The experimenter's pause: nothing starts until :meth:`unpause` (a running trial
        is the caller's to stop)."""
        self.paused = True

    def unpause(self) -> None:
        self.paused = False


def rig_folder(folder: Path, step: Step, attempt: int) -> Path:
    """Where a trial's processes write (its MCAP, their logs): ``logs/step-003-1`` in the
    participant's folder, one per attempt, so that an aborted attempt's log is kept."""
    return folder / "logs" / f"step-{step.index:03d}-{attempt}"
