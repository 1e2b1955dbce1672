"""Skill set files: several skills in one room, each tied to its task, and the
teleoperation that runs while none of them is engaged (docs/skill-sets.md).

A set file names its members' skill files and the settings of each member's start
region; this module reads it into a :class:`SkillSet` (the members' bundles and
validated skills, the settings as written), checked as a skill file is: every error
is a :class:`~sctd.skill.SkillError` reading ``file: path.to.field: what is wrong``,
and a member skill's own error is passed on behind the set file's name and the
member's field (``kitchen.yaml: members[1].skill: cabinet.yaml: states: ...``).

Which settings a member and the belief take, their defaults and the belief's ranges are
the runtime's (:class:`sctd.runtime.goals.Member`, :class:`~sctd.runtime.goals.BeliefModel`):
:func:`sctd.runtime.sets.goal_set` makes the running set from a :class:`SkillSet` and
checks what only the runtime knows (the belief's fields, the buttons the set takes).
What this module checks of a member's settings are their types and the ranges in
:data:`MEMBER_SETTINGS`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..files import FileError, load_yaml
from .catalog import find_skill
from .errors import SkillError
from .frames import WORLD_OBJECT
from .loader import MAX_TEXT, Bundle, bundle_from_file, skill_from_bundle
from .model import Skill
from .reader import Reader, kind_of

SET_FORMAT_VERSION = 1
MAX_MEMBERS = 16
DEFAULT_TELEOP = "teleop"
"""The teleoperation skill a set runs when its file names none (the shipped one)."""

MEMBER_SETTINGS: dict[str, tuple[float, float]] = {
    "point": (-10.0, 10.0),  # m, each coordinate (the goal point in the skill's object frame)
    "reach": (0.0, 10.0),  # m, > 0: how far from the point the start region extends
    "position_tolerance": (0.0, 1.0),  # m
    "angle_tolerance": (0.0, math.pi),  # rad
}
"""A member's settings besides its skill, and the range of each (``reach`` > 0, the
others >= their lower bound); their meaning and defaults: :class:`sctd.runtime.goals.Member`."""


@dataclass(frozen=True)
class SetMember:
    """One member of a set: the skill as the set names it (``ref``), its bundle and
    validated skill, and the settings the set gives it (the rest keep the runtime's
    defaults)."""

    ref: str
    bundle: Bundle = field(compare=False, repr=False)
    skill: Skill = field(compare=False, repr=False)
    settings: Mapping[str, Any] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.skill.name


@dataclass(frozen=True)
class SkillSet:
    """A skill set as read from its file (module doc).

    ``teleop_ref`` is the teleoperation skill as the file names it (None: the shipped
    one); ``belief`` the belief's parameters the file gives; ``source`` the set file
    (for messages)."""

    name: str
    members: tuple[SetMember, ...]
    teleop: Skill = field(compare=False, repr=False)
    teleop_bundle: Bundle = field(compare=False, repr=False)
    teleop_ref: str | None = None
    belief: Mapping[str, float] = field(default_factory=dict)
    description: str = ""
    source: str = ""

    def bundles(self) -> dict[str, Bundle]:
        """Every skill's bundle (the members' and teleoperation's), by skill id."""
        return {b.id: b for b in (self.teleop_bundle, *(m.bundle for m in self.members))}

    def to_yaml(self) -> dict[str, Any]:
        """The set file's document (what :func:`read_skill_set` reads back)."""
        doc: dict[str, Any] = {"sctd_set": SET_FORMAT_VERSION, "name": self.name}
        if self.description:
            doc["description"] = self.description
        if self.teleop_ref is not None:
            doc["teleop"] = self.teleop_ref
        if self.belief:
            doc["belief"] = dict(self.belief)
        doc["members"] = [{"skill": m.ref, **{k: list(v) if isinstance(v, tuple) else v
                                              for k, v in m.settings.items()}}
                          for m in self.members]
        return doc


Resolve = Callable[[str], Path]
"""Where a skill the set names is: a skill file's path (raises SkillError when none)."""


def resolver(folder: str | Path | None) -> Resolve:
    """Skills named relative to ``folder`` (a set file's), else as ``--skill`` takes them
    (:func:`~sctd.skill.catalog.find_skill`: stored, then shipped)."""
    return lambda ref: find_skill(ref, folder=folder)


def load_skill_set(path: str | Path) -> SkillSet:
    """Read and check a set file and every skill it names (module doc)."""
    name = str(path)
    try:
        doc = load_yaml(path, file=name)
    except FileError as e:
        raise SkillError(e.file, e.where, e.problem) from None
    return read_skill_set(doc, name, resolver(Path(path).parent))


def skill_set_of(refs: Sequence[str]) -> SkillSet:
    """The set of the skills ``refs`` (as ``--skill`` takes them), with the members'
    and the belief's default settings and the shipped teleoperation, named after its
    members (``drawer+cabinet-vf``); errors name ``--skill``."""
    loaded = {}
    for ref in refs:  # a skill's own error as it is, as for one --skill
        bundle = bundle_from_file(find_skill(ref))
        loaded[ref] = bundle, skill_from_bundle(bundle)
    doc = {"sctd_set": SET_FORMAT_VERSION, "name": "+".join(s.name for _, s in loaded.values()),
           "members": [{"skill": r} for r in refs]}
    return _SetReader("--skill", resolver(None), loaded).skill_set(doc)


def read_skill_set(doc: Any, file: str, resolve: Resolve) -> SkillSet:
    """A set file's document (parsed YAML) as a :class:`SkillSet`; ``file`` names it in
    errors, ``resolve`` finds the skills it names."""
    return _SetReader(file, resolve).skill_set(doc)


class _SetReader(Reader):
    """Walks a set document, checking each field and naming its path on error."""

    def __init__(self, file: str, resolve: Resolve,
                 loaded: Mapping[str, tuple[Bundle, Skill]] | None = None):
        super().__init__(file, {})
        self.resolve = resolve
        self.loaded = dict(loaded or {})  # skills read already, by the name the set gives

    def skill_set(self, doc: Any) -> SkillSet:
        doc = self.mapping(doc, "")
        self.known_keys(doc, "", {"sctd_set", "name", "description", "teleop", "belief", "members"})
        version = doc.get("sctd_set")
        if version != SET_FORMAT_VERSION:
            raise self.fail("sctd_set", f"expected format version {SET_FORMAT_VERSION}, got {version!r}")
        name = self.text(doc.get("name"), "name")
        description = self.text(doc.get("description", ""), "description", empty=True)
        teleop_ref = None if doc.get("teleop") is None else self.string(doc["teleop"], "teleop")
        teleop_bundle, teleop = self.skill(teleop_ref or DEFAULT_TELEOP, "teleop")
        if teleop.object != WORLD_OBJECT:
            raise self.fail("teleop", f"skill {teleop.name!r} is on the object {teleop.object!r}: "
                                      f"teleoperation runs on {WORLD_OBJECT!r}")
        belief = self.belief(doc.get("belief", {}))
        members = self.members(doc.get("members"), teleop)
        return SkillSet(name, members, teleop, teleop_bundle, teleop_ref, belief, description, self.file)

    def text(self, v: Any, path: str, empty: bool = False) -> str:
        if empty and v == "":
            return v
        text = self.string(v, path)
        if len(text) > MAX_TEXT:
            raise self.fail(path, f"{len(text)} characters, at most {MAX_TEXT}")
        return text

    def skill(self, ref: str, path: str) -> tuple[Bundle, Skill]:
        """The skill ``ref`` names: its own error passed on behind ``path``."""
        if ref in self.loaded:
            return self.loaded[ref]
        try:
            bundle = bundle_from_file(self.resolve(ref))
            self.loaded[ref] = bundle, skill_from_bundle(bundle)
        except SkillError as e:
            raise self.fail(path, str(e)) from None
        return self.loaded[ref]

    def belief(self, v: Any) -> dict[str, float]:
        """The belief's parameters as numbers (their names and ranges: the runtime's)."""
        d = self.mapping(v, "belief")
        return {str(k): self.number(x, f"belief.{k}") for k, x in d.items()}

    def members(self, v: Any, teleop: Skill) -> tuple[SetMember, ...]:
        if not isinstance(v, list):
            raise self.fail("members", f"expected a list of members, got {kind_of(v)}")
        if not 1 <= len(v) <= MAX_MEMBERS:
            raise self.fail("members", f"a set has 1 to {MAX_MEMBERS} members, got {len(v)}")
        members: list[SetMember] = []
        for i, m in enumerate(v):
            member = self.member(m, f"members[{i}]")
            taken = {x.name: f"members[{k}]" for k, x in enumerate(members)} | {teleop.name: "teleop"}
            if member.name in taken:
                raise self.fail(f"members[{i}].skill", f"skill name {member.name!r} is also "
                                                      f"{taken[member.name]}'s: the set's skills need "
                                                      "names of their own")
            members.append(member)
        return tuple(members)

    def member(self, v: Any, path: str) -> SetMember:
        d = self.mapping(v, path)
        self.known_keys(d, path, {"skill", *MEMBER_SETTINGS})
        ref = self.string(d.get("skill"), f"{path}.skill")
        bundle, skill = self.skill(ref, f"{path}.skill")
        if skill.object == WORLD_OBJECT:
            raise self.fail(f"{path}.skill", f"skill {skill.name!r} is on {WORLD_OBJECT!r}: a member is "
                                             "tied to its task object, whose pose makes it a candidate")
        settings: dict[str, Any] = {}
        for key, (lo, hi) in MEMBER_SETTINGS.items():
            if key not in d:
                continue
            where = f"{path}.{key}"
            if key == "point":
                settings[key] = tuple(float(x) for x in self.vector(d[key], where, 3))
                for k, x in enumerate(settings[key]):
                    self.number(x, f"{where}[{k}]", lo, hi)
            else:
                settings[key] = self.number(d[key], where, lo, hi, lo_open=key == "reach")
        return SetMember(ref, bundle, skill, settings)
