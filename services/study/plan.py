"""A user study's plan: participants x conditions x tasks, counterbalanced, with seeds.

Within subjects: every participant does every task under every condition. A **block**
is one condition on one task: ``practice`` trials (not analysed), then ``trials``
measured ones, then the questionnaires (:mod:`.questionnaires`). A participant's blocks
go condition by condition in the order of their sequence of the balanced Latin square
(:mod:`.latin`), and within a condition task by task in the plan's order.

Seeds (each trial's start and the scene's variation, as ``sctd eval`` uses them): for
participant ``p`` (from 0) and task ``t`` (from 0), ``b = seed + (p * tasks + t) *
(practice + trials)``; the practice trials take ``b .. b + practice - 1``, the measured
ones the next ``trials``. Every condition of a participant gets the same seeds on a
task, so that a paired comparison differs in the condition alone; participants get
different ones. Participant ``k`` (``P01`` is 1) follows sequence ``(k - 1) mod R`` of
the ``R`` sequences.

:func:`make_plan` builds it, :func:`plan_to_yaml` writes the file an ethics application
can attach (a header comment says what it is), :func:`plan_from_yaml` reads one back,
checked. Pure: names are not resolved here (:mod:`.conditions` does that at the edge),
and nothing is read or written.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import yaml

from . import latin
from .errors import StudyError
from .questionnaires import QUESTIONNAIRES, check_participant_id

VERSION = 1
KIND = "sctd-study-plan"
TELEOP = "teleop"  # the condition name of the competent teleoperation baseline
CONDITION_KINDS = ("skill", "teleop", "set")


@dataclass(frozen=True)
class Condition:
    """A condition: its ``name`` as given on the command line (a skill's or a skill set's
    name or path, or ``teleop``), its ``kind`` and what it is, in words."""

    name: str
    kind: str
    about: str = ""


@dataclass(frozen=True)
class Block:
    """A condition on a task: practice seeds, then measured seeds."""

    condition: str
    task: str
    practice_seeds: tuple[int, ...]
    seeds: tuple[int, ...]


@dataclass(frozen=True)
class Step:
    """One trial of a participant's schedule: ``index`` in the schedule (from 0), the
    block's condition and task, ``order`` (the condition's position in the participant's
    sequence, from 1), ``trial`` (from 1 among the block's practice or measured trials)."""

    index: int
    condition: str
    task: str
    order: int
    trial: int
    practice: bool
    seed: int


@dataclass(frozen=True)
class Schedule:
    """One participant's: pseudonym, sequence (a row of the square) and blocks in order."""

    participant: str
    sequence: int
    order: tuple[str, ...]
    blocks: tuple[Block, ...]

    def steps(self) -> list[Step]:
        """Every trial, in the order it is run."""
        out: list[Step] = []
        for b in self.blocks:
            pos = self.order.index(b.condition) + 1
            for practice, seeds in ((True, b.practice_seeds), (False, b.seeds)):
                for k, s in enumerate(seeds):
                    out.append(Step(len(out), b.condition, b.task, pos, k + 1, practice, s))
        return out


@dataclass(frozen=True)
class Plan:
    """A study's plan (module doc)."""

    conditions: tuple[Condition, ...]
    tasks: tuple[str, ...]
    practice: int
    trials: int
    seed: int
    sequences: tuple[tuple[str, ...], ...]
    participants: tuple[Schedule, ...]
    title: str = "sctd user study"
    warnings: tuple[str, ...] = field(default=())

    @property
    def condition_names(self) -> list[str]:
        return [c.name for c in self.conditions]

    def schedule(self, participant: str) -> Schedule:
        for s in self.participants:
            if s.participant == participant:
                return s
        known = ", ".join(s.participant for s in self.participants)
        raise StudyError(f"participant {participant}: not in the plan (its participants: {known})")

    def condition(self, name: str) -> Condition:
        for c in self.conditions:
            if c.name == name:
                return c
        raise StudyError(f"condition {name}: not in the plan ({', '.join(self.condition_names)})")


def participant_id(k: int, n: int) -> str:
    """The pseudonym of participant ``k`` (from 1) of ``n``: ``P01`` (``P001`` past 99)."""
    return f"P{k:0{max(2, len(str(n)))}d}"


def balance_warnings(n_participants: int, n_sequences: int) -> list[str]:
    """What the file must say when the participants do not fill the square's sequences
    equally (the counterbalance is complete only for a multiple of their number)."""
    if n_sequences <= 1 or n_participants % n_sequences == 0:
        return []
    if n_participants < n_sequences:
        return [f"{n_participants} participants for {n_sequences} sequences: the counterbalance is "
                f"incomplete (sequences {n_participants + 1}-{n_sequences} have no participant); order "
                f"and carryover effects are not balanced; use a multiple of {n_sequences} participants"]
    return [f"{n_participants} participants for {n_sequences} sequences: not a multiple, so "
            f"{n_participants % n_sequences} of the sequences have one participant more than the others and "
            f"the counterbalance is not exact; use a multiple of {n_sequences} participants"]


def make_plan(conditions: Sequence[Condition], tasks: Sequence[str], participants: int, practice: int,
              trials: int, seed: int = 0, title: str = "sctd user study") -> Plan:
    """The plan (module doc). Raises :class:`StudyError` for a duplicate condition or
    task, or a count out of range, naming the flag."""
    names = [c.name for c in conditions]
    for what, given in (("--condition", names), ("--task", list(tasks))):
        if not given:
            raise StudyError(f"{what}: at least one is needed")
        dup = next((x for i, x in enumerate(given) if x in given[:i]), None)
        if dup is not None:
            raise StudyError(f"{what}: {dup} is given twice (each {what[2:]} once)")
    for flag, v, low in (("--participants", participants, 1), ("--practice", practice, 0),
                         ("--trials", trials, 1)):
        if v < low:
            raise StudyError(f"{flag}: {v} is below {low}")
    sequences = tuple(tuple(names[i] for i in row) for row in latin.williams_rows(len(names)))
    per = practice + trials
    schedules = []
    for p in range(participants):
        order = sequences[p % len(sequences)]
        blocks = []
        for cond in order:
            for t, task in enumerate(tasks):
                b = seed + (p * len(tasks) + t) * per
                blocks.append(Block(cond, task, tuple(range(b, b + practice)),
                                    tuple(range(b + practice, b + per))))
        schedules.append(Schedule(participant_id(p + 1, participants), p % len(sequences), order,
                                  tuple(blocks)))
    return Plan(tuple(conditions), tuple(tasks), practice, trials, seed, sequences, tuple(schedules), title,
                tuple(balance_warnings(participants, len(sequences))))


def _header(plan: Plan) -> list[str]:
    n, c, t = len(plan.participants), len(plan.conditions), len(plan.tasks)
    lines = [
        f"sctd study plan: {plan.title}",
        "A within-subjects user study of shared control with sctd: every participant does every task",
        "under every condition. Written by `sctd study plan`; docs/study.md describes every field.",
        "",
        f"Design: {n} participants x {c} conditions x {t} task(s) = {n * c * t} blocks; a block is one "
        f"condition on one task: {plan.practice} practice trial(s) (not analysed), then {plan.trials} "
        "measured trial(s), then the questionnaires. Within a condition the tasks follow the order of "
        "`tasks`.",
        "Conditions:",
        *(f"  {k.name}: {k.about or k.kind}" for k in plan.conditions),
        f"Tasks: {', '.join(plan.tasks)}",
        f"Counterbalancing: {latin.construction(c)}.",
        f"Participant k follows sequence (k - 1) mod {len(plan.sequences)} (see `sequences`).",
        "Seeds: each trial's start; every condition of a participant gets the same seeds on a task",
        "(paired comparisons differ in the condition alone), participants get different ones.",
        "Questionnaires after each block: raw NASA-TLX (Hart & Staveland 1988; Hart 2006) and the",
        "System Usability Scale (Brooke 1996); items and scoring under `questionnaires`.",
        "Participants are pseudonymous (P01, ...): no name, contact or other identifying data goes into",
        "the plan or the study folder; the key linking pseudonyms to people is kept apart from them.",
    ]
    lines += [f"WARNING: {w}" for w in plan.warnings]
    wrapped = [part for x in lines for part in (textwrap.wrap(x, 94, subsequent_indent="  ") or [""])]
    return ["# " + x if x else "#" for x in wrapped]


def plan_document(plan: Plan) -> dict[str, Any]:
    """The plan as the plain document the file holds."""
    return {
        "v": VERSION, "kind": KIND, "title": plan.title, "seed": plan.seed,
        "design": {"participants": len(plan.participants), "practice_trials": plan.practice,
                   "measured_trials": plan.trials,
                   "counterbalancing": latin.construction(len(plan.conditions)),
                   "complete_counterbalance": not plan.warnings},
        "warnings": list(plan.warnings),
        "conditions": [{"name": c.name, "kind": c.kind, "about": c.about} for c in plan.conditions],
        "tasks": list(plan.tasks),
        "sequences": [list(s) for s in plan.sequences],
        "questionnaires": QUESTIONNAIRES,
        "participants": [{"id": s.participant, "sequence": s.sequence + 1, "order": list(s.order),
                          "blocks": [{"condition": b.condition, "task": b.task,
                                      "practice_seeds": list(b.practice_seeds), "seeds": list(b.seeds)}
                                     for b in s.blocks]}
                         for s in plan.participants],
    }


class _Dumper(yaml.SafeDumper):
    """Block style, except lists of plain values on one line (``seeds: [1, 2, 3]``)."""


def _list(dumper: yaml.SafeDumper, data: list) -> yaml.Node:
    flow = all(isinstance(x, int | float | str) for x in data) and sum(len(str(x)) for x in data) < 80
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_Dumper.add_representer(list, _list)


def plan_to_yaml(plan: Plan) -> str:
    """The plan file's text: the header comment, then the document."""
    body = yaml.dump(plan_document(plan), Dumper=_Dumper, sort_keys=False, default_flow_style=False,
                     width=100, allow_unicode=True)
    return "\n".join(_header(plan)) + "\n\n" + body


def _need(doc: Any, key: str, kind: type | tuple[type, ...], where: str) -> Any:
    if not isinstance(doc, dict) or key not in doc:
        raise StudyError(f"{where}{key}: missing")
    v = doc[key]
    if not isinstance(v, kind) or (isinstance(v, bool) and kind is int):
        raise StudyError(f"{where}{key}: {v!r} is not {getattr(kind, '__name__', kind)}")
    return v


def _ints(v: Any, where: str) -> tuple[int, ...]:
    if not isinstance(v, list) or not all(isinstance(x, int) and not isinstance(x, bool) for x in v):
        raise StudyError(f"{where}: {v!r} is not a list of whole numbers")
    return tuple(v)


def _conditions(doc: Any, file: str) -> tuple[Condition, ...]:
    out = []
    for i, c in enumerate(_need(doc, "conditions", list, f"{file}: ")):
        where = f"{file}: conditions[{i}]."
        kind = _need(c, "kind", str, where)
        if kind not in CONDITION_KINDS:
            raise StudyError(f"{where}kind: {kind!r} is not one of {', '.join(CONDITION_KINDS)}")
        out.append(Condition(_need(c, "name", str, where), kind, str(c.get("about", ""))))
    names = [c.name for c in out]
    if len(set(names)) != len(names) or not names:
        raise StudyError(f"{file}: conditions: {names}: each condition once, at least one")
    return tuple(out)


def _schedule(s: Any, i: int, names: list[str], tasks: list[str], file: str) -> Schedule:
    where = f"{file}: participants[{i}]."
    pid = _need(s, "id", str, where)
    try:
        check_participant_id(pid)
    except StudyError as e:
        raise StudyError(f"{where}id: {e}") from None
    order = tuple(_need(s, "order", list, where))
    if sorted(order) != sorted(names):
        raise StudyError(f"{where}order: {list(order)} is not an order of the conditions {names}")
    blocks = []
    for j, b in enumerate(_need(s, "blocks", list, where)):
        bw = f"{where}blocks[{j}]."
        cond, task = _need(b, "condition", str, bw), _need(b, "task", str, bw)
        if cond not in names:
            raise StudyError(f"{bw}condition: {cond!r} is not one of the plan's conditions {names}")
        if task not in tasks:
            raise StudyError(f"{bw}task: {task!r} is not one of the plan's tasks {tasks}")
        blocks.append(Block(cond, task, _ints(b.get("practice_seeds", []), f"{bw}practice_seeds"),
                            _ints(_need(b, "seeds", list, bw), f"{bw}seeds")))
    return Schedule(pid, int(_need(s, "sequence", int, where)) - 1, order, tuple(blocks))


def plan_from_yaml(text: str, file: str = "plan.yaml") -> Plan:
    """The plan a file written by :func:`plan_to_yaml` holds, checked: errors read
    ``file: field: problem``."""
    try:
        doc = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise StudyError(f"{file}: not YAML: {e}") from None
    if not isinstance(doc, dict) or doc.get("kind") != KIND:
        raise StudyError(f"{file}: kind: not an sctd study plan (expected kind: {KIND})")
    if doc.get("v") != VERSION:
        raise StudyError(f"{file}: v: {doc.get('v')!r}: this sctd reads version {VERSION}")
    conditions = _conditions(doc, file)
    names = [c.name for c in conditions]
    tasks = [str(t) for t in _need(doc, "tasks", list, f"{file}: ")]
    design = _need(doc, "design", dict, f"{file}: ")
    parts = tuple(_schedule(s, i, names, tasks, file)
                  for i, s in enumerate(_need(doc, "participants", list, f"{file}: ")))
    ids = [s.participant for s in parts]
    if len(set(ids)) != len(ids):
        raise StudyError(f"{file}: participants: an id is given twice ({', '.join(ids)})")
    seqs = tuple(tuple(str(x) for x in s) for s in doc.get("sequences", []))
    return Plan(conditions, tuple(tasks), int(_need(design, "practice_trials", int, f"{file}: design.")),
                int(_need(design, "measured_trials", int, f"{file}: design.")), int(doc.get("seed", 0)),
                seqs, parts, str(doc.get("title", "sctd user study")),
                tuple(str(w) for w in doc.get("warnings", [])))
