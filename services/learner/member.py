"""Which member of the daemon's running skill set a learned skill replaces.

The daemon's ``skill`` summary says whether it runs a skill set (its ``set`` part,
docs/wire-contract.md): a swap into a set replaces one member, and the daemon refuses
one that names none unless the new skill has a member's name (docs/skill-sets.md). The
learner names the member (docs/learner.md, "Swapping into a skill set"):

1. the request's ``member``, when it gives one;
2. else, with a set running, the member of the learned skill's name (a retrained member);
3. else the one member tied to the learned skill's object;
4. else none: several members share that object, or none has it. The skill stays
   stored, not swapped, and the reason names the candidates and the ``member`` field.

Without a set (or without a daemon) a request's ``member`` is passed on as it is: the
daemon refuses ``member=`` when it runs one skill, and says so; the daemon, not a
summary read a moment earlier, knows what it runs when the swap arrives.

Pure functions of the summary: no Zenoh here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

HOW_TO_NAME = "name the member to replace in the request's member field (sctd train --member NAME)"


class NoMember(ValueError):
    """No member of the running set is the one a learned skill replaces: why, naming the
    candidates and the ``member`` field."""


def set_members(summary: Mapping[str, Any] | None) -> list[Mapping[str, Any]] | None:
    """The running set's members (``{id, name, object, ...}`` each, in the set's order),
    or None when no daemon answered or it runs one skill."""
    part = (summary or {}).get("set")
    return None if not isinstance(part, Mapping) else list(part.get("members") or [])


def member_to_replace(summary: Mapping[str, Any] | None, requested: str | None, name: str,
                      obj: str | None) -> str | None:
    """The member a learned skill replaces (module doc), or None: no set runs and the
    request named none.

    Parameters
    ----------
    summary : mapping or None
        The daemon's ``skill`` summary (None: no daemon answered).
    requested : str or None
        The request's ``member``.
    name : str
        The learned skill's name.
    obj : str or None
        Its task object (None: unknown, tied to no member).

    Raises
    ------
    NoMember
        A set runs, the request names no member, no member has the skill's name, and not
        exactly one member is tied to ``obj``.
    """
    members = set_members(summary)
    if requested is not None or members is None:
        return requested
    if any(m.get("name") == name for m in members):
        return name
    tied = [str(m.get("name")) for m in members if m.get("object") == obj]
    if len(tied) == 1:
        return tied[0]
    set_name = (summary or {}).get("set", {}).get("name")
    everyone = ", ".join(f"{m.get('name')} ({m.get('object')})" for m in members)
    if tied:
        raise NoMember(f"the running skill set {set_name!r} has no member named {name!r}, and the "
                       f"members {', '.join(tied)} are all tied to {obj!r}: {HOW_TO_NAME}")
    raise NoMember(f"the running skill set {set_name!r} has no member named {name!r} nor one tied to "
                   f"{obj!r} (members: {everyone}): {HOW_TO_NAME}")


def replaced_skill_id(summary: Mapping[str, Any] | None, requested: str | None, name: str,
                      obj: str | None) -> str | None:
    """The id of the skill a swap of the learned skill would replace, the baseline of its
    check: the running skill's, or with a set the chosen member's (:func:`member_to_replace`);
    None when no daemon answered, no member is chosen, or the set has no member of the
    requested name."""
    members = set_members(summary)
    if members is None:
        sid = (summary or {}).get("id")
        return None if not sid else str(sid)
    try:
        member = member_to_replace(summary, requested, name, obj)
    except NoMember:
        return None
    sid = next((m.get("id") for m in members if m.get("name") == member), None)
    return None if not sid else str(sid)
