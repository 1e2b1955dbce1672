"""The questionnaires a participant answers after each block, as data, and their scoring.

- **Raw NASA-TLX** (Hart & Staveland 1988; the unweighted "raw TLX" of Hart 2006): six
  subscales rated 0-100 in steps of 5 (the 21 marks of the paper scale). Every
  subscale runs from low to high *workload*; for **performance** that means 0 "perfect"
  to 100 "failure" (a participant who did well marks the left end). The raw TLX is the
  mean of the six ratings (0-100, higher: more workload); the pairwise weighting of the
  original is left out, as many studies since have done (Hart 2006 reviews them).
- **SUS**, the System Usability Scale (Brooke 1996): ten statements rated 1 (strongly
  disagree) to 5 (strongly agree), odd ones worded positively and even ones negatively.
  Each odd item contributes ``rating - 1``, each even one ``5 - rating`` (0-4 each);
  the sum times 2.5 is the score, 0-100, higher: more usable.

An answer is checked here, before it is stored: every item present, an integer, in
range (and on the TLX's 5-point grid); the error names the participant, the condition,
the task, the item and the value. Participant ids are checked too: a study's files hold
pseudonyms (``P01``), never something that names or reaches a person. Pure: no I/O.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from .errors import StudyError

TLX = "nasa_tlx"
SUS = "sus"


@dataclass(frozen=True)
class Subscale:
    """One NASA-TLX subscale: its key in the answers, its question and its ends."""

    key: str
    question: str
    low: str  # what 0 means
    high: str  # what 100 means


TLX_SUBSCALES = (
    Subscale("mental", "Mental demand: how mentally demanding was the task?", "very low", "very high"),
    Subscale("physical", "Physical demand: how physically demanding was the task?", "very low", "very high"),
    Subscale("temporal", "Temporal demand: how hurried or rushed was the pace of the task?",
             "very low", "very high"),
    Subscale("performance", "Performance: how successful were you in accomplishing what you were asked "
             "to do?", "perfect", "failure"),
    Subscale("effort", "Effort: how hard did you have to work to accomplish your level of performance?",
             "very low", "very high"),
    Subscale("frustration", "Frustration: how insecure, discouraged, irritated, stressed and annoyed "
             "were you?", "very low", "very high"),
)
TLX_STEP = 5

SUS_ITEMS = (
    "I think that I would like to use this system frequently.",
    "I found the system unnecessarily complex.",
    "I thought the system was easy to use.",
    "I think that I would need the support of a technical person to be able to use this system.",
    "I found the various functions in this system were well integrated.",
    "I thought there was too much inconsistency in this system.",
    "I would imagine that most people would learn to use this system very quickly.",
    "I found the system very cumbersome to use.",
    "I felt very confident using the system.",
    "I needed to learn a lot of things before I could get going with this system.",
)

QUESTIONNAIRES: dict[str, dict[str, Any]] = {
    TLX: {"title": "NASA Task Load Index, raw (unweighted)",
          "reference": "Hart & Staveland 1988; Hart 2006 (raw TLX)",
          "when": "after each block (a condition on a task)",
          "items": {s.key: f"{s.question} (0 = {s.low}, 100 = {s.high})" for s in TLX_SUBSCALES},
          "scale": f"0-100 in steps of {TLX_STEP}",
          "scoring": "raw TLX = mean of the six ratings (0-100; higher = more workload; performance "
                     "is rated 0 = perfect to 100 = failure, so it adds to workload like the others)"},
    SUS: {"title": "System Usability Scale", "reference": "Brooke 1996",
          "when": "after each block (a condition on a task)",
          "items": {str(i + 1): text for i, text in enumerate(SUS_ITEMS)},
          "scale": "1 = strongly disagree .. 5 = strongly agree",
          "scoring": "odd items: rating - 1, even items: 5 - rating; sum x 2.5 "
                     "(0-100; higher = more usable)"},
}

# A pseudonym: 1-3 letters and 1-4 digits (P01, S12, PT003).
PSEUDONYM = re.compile(r"[A-Za-z]{1,3}[0-9]{1,4}")


def check_participant_id(pid: Any) -> str:
    """``pid`` when it is a pseudonym (:data:`PSEUDONYM`: ``P01``); a :class:`StudyError`
    otherwise, saying what it looks like (an e-mail address, a phone number, a name)."""
    if not isinstance(pid, str):
        raise StudyError(f"participant id {pid!r}: not a text id like P01")
    if PSEUDONYM.fullmatch(pid):
        return pid
    if "@" in pid:
        why = "looks like an e-mail address"
    elif len(re.sub(r"\D", "", pid)) >= 6:
        why = "looks like a phone number"
    elif re.search(r"[A-Za-z]{2,}[\s._-]+[A-Za-z]{2,}", pid) or " " in pid.strip():
        why = "looks like a person's name"
    else:
        why = "is not a pseudonym"
    raise StudyError(f"participant id {pid!r} {why}: a study's files hold pseudonyms only (1-3 letters "
                     "and 1-4 digits, e.g. P01); keep the key that links them to people elsewhere, "
                     "out of the study folder")


def _rating(value: Any, where: str, low: int, high: int, step: int = 1) -> int:
    if value is None:
        raise StudyError(f"{where}: missing")
    if isinstance(value, bool) or not isinstance(value, int | float) or value != int(value):
        raise StudyError(f"{where}: {value!r} is not a whole number")
    v = int(value)
    if not low <= v <= high:
        raise StudyError(f"{where}: {v} is out of range ({low}-{high})")
    if (v - low) % step:
        raise StudyError(f"{where}: {v} is not on the scale's steps of {step}")
    return v


def tlx_ratings(answer: Any, who: str) -> dict[str, int]:
    """The six NASA-TLX ratings of ``answer`` (a mapping subscale -> 0..100), checked;
    ``who``: ``participant P01, condition X, task T`` for the errors."""
    if not isinstance(answer, Mapping):
        raise StudyError(f"{who}: {TLX}: expected a mapping of the six subscales, not {answer!r}")
    known = {s.key for s in TLX_SUBSCALES}
    extra = sorted(set(map(str, answer)) - known)
    if extra:
        raise StudyError(f"{who}: {TLX}.{extra[0]}: no such subscale (the six: {', '.join(sorted(known))})")
    return {s.key: _rating(answer.get(s.key), f"{who}: {TLX}.{s.key}", 0, 100, TLX_STEP)
            for s in TLX_SUBSCALES}


def raw_tlx(answer: Any, who: str = "answer") -> float:
    """The raw TLX: the mean of the six ratings (checked, :func:`tlx_ratings`)."""
    r = tlx_ratings(answer, who)
    return sum(r.values()) / len(r)


def sus_ratings(answer: Any, who: str) -> list[int]:
    """The ten SUS ratings of ``answer`` (a list in item order, or a mapping ``"1"``..``"10"``),
    checked; items are numbered from 1 in the errors."""
    if isinstance(answer, Mapping):
        extra = sorted(str(k) for k in answer if str(k) not in {str(i) for i in range(1, 11)})
        if extra:
            raise StudyError(f"{who}: {SUS}.{extra[0]}: no such item (items 1-10)")
        answer = [answer.get(str(i), answer.get(i)) for i in range(1, 11)]
    if not isinstance(answer, Sequence) or isinstance(answer, str):
        raise StudyError(f"{who}: {SUS}: expected the ten ratings, not {answer!r}")
    if len(answer) > len(SUS_ITEMS):
        raise StudyError(f"{who}: {SUS}: {len(answer)} ratings, the scale has {len(SUS_ITEMS)} items")
    items = list(answer) + [None] * (len(SUS_ITEMS) - len(answer))
    return [_rating(v, f"{who}: {SUS}.{i + 1}", 1, 5) for i, v in enumerate(items)]


def sus_score(answer: Any, who: str = "answer") -> float:
    """The SUS score, 0-100 (Brooke 1996): odd items ``rating - 1``, even ``5 - rating``,
    the sum times 2.5."""
    r = sus_ratings(answer, who)
    return 2.5 * sum(v - 1 if i % 2 == 0 else 5 - v for i, v in enumerate(r))


def check_answers(answers: Mapping[str, Any], who: str) -> dict[str, Any]:
    """A block's answers (``{"nasa_tlx": {...}, "sus": [...]}``, both required) checked and
    scored: the same with ``raw_tlx`` and ``sus_score`` added."""
    unknown = sorted(set(answers) - {TLX, SUS})
    if unknown:
        raise StudyError(f"{who}: {unknown[0]}: no such questionnaire (known: {TLX}, {SUS})")
    for q in (TLX, SUS):
        if q not in answers:
            raise StudyError(f"{who}: {q}: missing")
    tlx = tlx_ratings(answers[TLX], who)
    sus = sus_ratings(answers[SUS], who)
    return {TLX: tlx, SUS: sus, "raw_tlx": sum(tlx.values()) / len(tlx), "sus_score": sus_score(sus, who)}
