"""Which member of a running skill set the learner replaces (services/learner/member.py),
the check's baseline with a set, and the swap that names the member; without processes:
the daemon's summaries are those its ``skill`` queryable gives for the shipped kitchen
set (``set_summary``), and the daemon's swap is a stand-in."""

from __future__ import annotations

import argparse
import copy

import msgpack
import pytest

from sctd.cli.train import add_train_arguments, request_of
from sctd.runtime.sets import goal_set, set_summary
from sctd.skill import bundle_from_file, skill_summary
from sctd.skill.skillset import load_skill_set
from sctd_services.learner import service
from sctd_services.learner.check import CheckSettings
from sctd_services.learner.member import NoMember, member_to_replace, replaced_skill_id
from sctd_services.learner.request import Request, parse_request
from sctd_services.learner.service import Learner
from sctd_services.learner.store import Store
from tests.conftest import ROOT

KITCHEN = ROOT / "skills" / "sets" / "kitchen.yaml"  # drawer, cabinet-vf, light_switch-vf


@pytest.fixture(scope="module")
def kitchen() -> dict:
    """The daemon's ``skill`` summary while it runs the kitchen set in teleoperation."""
    spec = load_skill_set(KITCHEN)
    goals = goal_set(spec)
    return {**skill_summary(goals.teleop), "state": "teleop", "set": set_summary(spec.name, goals)}


def _ids(summary: dict) -> dict[str, str]:
    return {m["name"]: m["id"] for m in summary["set"]["members"]}


def _changed(summary: dict, member: str, **fields) -> dict:
    """``summary`` with the member ``member``'s ``fields`` changed."""
    out = copy.deepcopy(summary)
    next(m for m in out["set"]["members"] if m["name"] == member).update(fields)
    return out


def _tied(summary: dict, member: str, obj: str) -> dict:
    """``summary`` with ``member`` tied to ``obj``."""
    return _changed(summary, member, object=obj)


def _renamed(summary: dict, member: str, name: str) -> dict:
    """``summary`` after a skill named ``name`` replaced ``member``."""
    return _changed(summary, member, name=name)


# --- the rule -------------------------------------------------------------------------

def test_a_requested_member_is_the_one_replaced_with_or_without_a_set(kitchen):
    """Named in the request: that member, whatever the skill's name and object; without
    a set (or a daemon) it is passed on for the daemon to refuse."""
    assert member_to_replace(kitchen, "cabinet-vf", "drawer", "drawer_handle") == "cabinet-vf"
    assert member_to_replace(kitchen, "nobody", "x", "y") == "nobody"  # the daemon names the members
    single = {"id": "5af442ad88b9d1ee", "name": "pour", "object": "mug", "state": "approach"}
    assert member_to_replace(single, "drawer", "pour-vf-learned", "mug") == "drawer"
    assert member_to_replace(None, "drawer", "pour-vf-learned", "mug") == "drawer"


def test_without_a_set_or_a_daemon_no_member_is_named(kitchen):
    single = {k: v for k, v in kitchen.items() if k != "set"}
    assert member_to_replace(single, None, "pour-vf-learned", "mug") is None
    assert member_to_replace(None, None, "pour-vf-learned", "mug") is None


def test_with_a_set_the_member_of_the_skills_name_comes_before_its_object(kitchen):
    """A retrained member keeps its place, even when another member has its object."""
    assert member_to_replace(kitchen, None, "cabinet-vf", "door_handle") == "cabinet-vf"
    both = _tied(kitchen, "drawer", "door_handle")
    assert member_to_replace(both, None, "cabinet-vf", "door_handle") == "cabinet-vf"


def test_with_a_set_the_one_member_tied_to_the_skills_object_is_replaced(kitchen):
    """The learner's default name, <task>-<method>-learned, is no member's."""
    assert member_to_replace(kitchen, None, "drawer-vf-learned", "drawer_handle") == "drawer"
    assert member_to_replace(kitchen, None, "switch-linear-learned", "light_switch") == "light_switch-vf"


def test_with_a_set_no_member_or_several_for_the_object_is_no_swap_naming_them(kitchen):
    with pytest.raises(NoMember) as e:
        member_to_replace(kitchen, None, "pour-vf-learned", "mug")
    assert str(e.value) == (
        "the running skill set 'kitchen' has no member named 'pour-vf-learned' nor one tied to 'mug' "
        "(members: drawer (drawer_handle), cabinet-vf (door_handle), light_switch-vf (light_switch)): "
        "name the member to replace in the request's member field (sctd train --member NAME)")
    with pytest.raises(NoMember, match="^the running skill set 'kitchen' has no member named 'x', and the "
                                       "members drawer, cabinet-vf are all tied to 'door_handle': name the "
                                       r"member to replace in the request's member field \(sctd train "
                                       r"--member NAME\)$"):
        member_to_replace(_tied(kitchen, "drawer", "door_handle"), None, "x", "door_handle")
    with pytest.raises(NoMember, match="nor one tied to None"):  # a skill of unknown object
        member_to_replace(kitchen, None, "x", None)


def test_the_baseline_is_the_replaced_members_skill_not_the_running_one(kitchen):
    """The set runs teleoperation until a member engages: the check compares the new
    skill with the member it replaces."""
    ids = _ids(kitchen)
    assert kitchen["id"] not in ids.values()  # teleoperation runs
    assert replaced_skill_id(kitchen, None, "drawer-vf-learned", "drawer_handle") == ids["drawer"]
    assert replaced_skill_id(kitchen, "cabinet-vf", "drawer-vf-learned", "drawer_handle") == ids["cabinet-vf"]
    assert replaced_skill_id(kitchen, None, "light_switch-vf", "x") == ids["light_switch-vf"]
    assert replaced_skill_id(kitchen, None, "pour-vf-learned", "mug") is None  # no swap: no baseline
    assert replaced_skill_id(kitchen, "nobody", "pour-vf-learned", "mug") is None
    single = {"id": "5af442ad88b9d1ee", "name": "pour", "object": "mug"}
    assert replaced_skill_id(single, None, "pour-vf-learned", "mug") == "5af442ad88b9d1ee"
    assert replaced_skill_id(None, None, "pour-vf-learned", "mug") is None


# --- the request ----------------------------------------------------------------------

def test_a_request_names_the_member_and_sctd_train_sends_it():
    req = parse_request(msgpack.packb({"task": "drawer", "method": "vf", "member": "drawer"}))
    assert req.member == "drawer"
    assert parse_request(msgpack.packb({"task": "drawer", "method": "vf"})).member is None
    p = argparse.ArgumentParser()
    add_train_arguments(p)
    assert request_of(p.parse_args(["--task", "drawer", "--method", "vf", "--member", "drawer"]))[
        "member"] == "drawer"
    assert "member" not in request_of(p.parse_args(["--task", "drawer", "--method", "vf"]))


# --- the learner: baseline and swap ---------------------------------------------------

@pytest.fixture
def learner(tmp_path, monkeypatch, kitchen):
    """A learner with its own store holding the kitchen's drawer member (evaluated on the
    task ``drawer``) and a retrained drawer skill; the daemon runs the kitchen set."""
    store = Store(tmp_path)
    member = store.add_skill(bundle_from_file(ROOT / "skills" / "drawer.yaml"),
                             {"task": "drawer", "object": "drawer_handle",
                              "evaluation": {"drawer": {"success_rate": 1.0}}})
    assert member.id == _ids(kitchen)["drawer"]
    b = bundle_from_file(ROOT / "skills" / "drawer.yaml")
    b = type(b)(name="drawer-vf-learned.yaml", yaml_text=b.yaml_text.replace("name: drawer\n",
                                                                            "name: drawer-vf-learned\n"),
                files=b.files)
    new = store.add_skill(b, {"task": "drawer", "object": "drawer_handle"})
    it = Learner(None, store, settings=CheckSettings())
    monkeypatch.setattr(it, "say", lambda *args, **fields: None)
    monkeypatch.setattr(it, "daemon_summary", lambda: kitchen)
    return it, new


def test_the_check_compares_with_the_member_it_replaces(learner):
    it, new = learner
    req = Request(task="drawer", method="vf", name="drawer-vf-learned")
    assert it._active_evaluation(req, new, "drawer_handle") == {"success_rate": 1.0}
    assert it._active_evaluation(Request(task="drawer", method="vf", member="cabinet-vf"), new,
                                 "drawer_handle") is None  # not stored here


def _daemon(monkeypatch, replaced: str) -> list[str | None]:
    """The daemon's swap, replacing ``replaced``: the members the learner names, as it asks."""
    asked: list[str | None] = []

    def daemon_swap(session, keys, bundle, timeout, member=None):
        asked.append(member)
        return True, {"ok": True, "id": bundle.id, "name": "x", "state": "approach", "member": replaced}

    monkeypatch.setattr(service.client, "swap", daemon_swap)
    return asked


@pytest.mark.parametrize("requested", [None, "drawer"])
def test_the_swap_names_the_member_and_the_reply_and_record_say_which(learner, monkeypatch, requested):
    """Chosen by its object or named in the request, the member is named in the swap."""
    it, new = learner
    asked = _daemon(monkeypatch, "drawer")
    record = it.store.record(new.id)
    req = Request(task="drawer", method="vf", name="drawer-vf-learned", member=requested)
    swapped, why, daemon = it._swap(new, req, True, "6/6 trials succeeded", record)
    assert swapped and asked == ["drawer"]
    assert why == "swapped, replacing the member 'drawer': 6/6 trials succeeded"
    assert record.data["member"] == "drawer" and len(record.data["swaps"]) == 1
    out = service._Outcome(new, True, swapped, why, {}, {}, None, {}, daemon)
    assert out.reply()["member"] == "drawer"


def test_a_retrained_member_is_swapped_without_naming_it(learner, monkeypatch, kitchen):
    """The member of the skill's own name is the daemon's default: the selector is left
    out (a name it cannot carry is replaced too)."""
    it, new = learner
    asked = _daemon(monkeypatch, "drawer-vf-learned")
    monkeypatch.setattr(it, "daemon_summary", lambda: _renamed(kitchen, "drawer", "drawer-vf-learned"))
    swapped, why, _ = it._swap(new, Request(task="drawer", method="vf"), True, "ok", it.store.record(new.id))
    assert swapped and asked == [None] and "replacing the member 'drawer-vf-learned'" in why


def test_into_a_daemon_running_one_skill_a_requested_member_is_passed_on(learner, monkeypatch, kitchen):
    """No set: no member is named unless the request names one, which the daemon
    refuses (it knows what it runs when the swap arrives); the reason is its error."""
    it, new = learner
    monkeypatch.setattr(it, "daemon_summary", lambda: {k: v for k, v in kitchen.items() if k != "set"})
    asked: list[str | None] = []

    def daemon_swap(session, keys, bundle, timeout, member=None):
        asked.append(member)
        if member is not None:
            return False, {"error": "member=: the daemon runs one skill"}
        return True, {"ok": True, "id": bundle.id, "name": "x", "state": "approach"}

    monkeypatch.setattr(service.client, "swap", daemon_swap)
    record = it.store.record(new.id)
    swapped, why, _ = it._swap(new, Request(task="drawer", method="vf"), True, "ok", record)
    assert swapped and why == "swapped: ok" and record.data["member"] is None
    swapped, why, _ = it._swap(new, Request(task="drawer", method="vf", member="drawer"), True, "ok", record)
    assert not swapped and why == "not swapped: member=: the daemon runs one skill; check: ok"
    assert asked == [None, "drawer"]


def test_no_member_chosen_is_no_swap_and_the_skill_stays_stored(learner, monkeypatch, kitchen):
    it, new = learner
    monkeypatch.setattr(service.client, "swap", lambda *a, **k: pytest.fail("no swap was to be asked"))
    monkeypatch.setattr(it, "daemon_summary", lambda: _tied(kitchen, "cabinet-vf", "drawer_handle"))
    record = it.store.record(new.id)
    swapped, why, daemon = it._swap(new, Request(task="drawer", method="vf"), True, "6/6", record)
    assert not swapped and daemon is None
    assert why.startswith("stored, not swapped: the running skill set 'kitchen' has no member named "
                          "'drawer-vf-learned', and the members drawer, cabinet-vf are all tied to "
                          "'drawer_handle': name the member to replace in the request's member field")
    assert why.endswith("; check: 6/6") and "swaps" not in record.data
    assert it.store.skill(new.id) is not None
