"""Skill set files (sctd.skill.skillset, sctd.runtime.sets): the shipped set loads and
runs, every error names the set file and the field, and ``sctd run``'s flags make one
skill or a set."""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import pytest
import yaml

from sctd.app.errors import Parser
from sctd.cli.run import add_run_arguments, daemon_skills
from sctd.runtime.goals import BeliefModel, GoalSet, Member
from sctd.runtime.sets import goal_set
from sctd.skill import SkillError, bundle_from_file
from sctd.skill.catalog import find_skill_set, shipped_folder
from sctd.skill.skillset import (
    MAX_MEMBERS,
    MEMBER_SETTINGS,
    load_skill_set,
    read_skill_set,
    resolver,
    skill_set_of,
)

ROOT = Path(__file__).resolve().parents[1]
KITCHEN = ROOT / "skills" / "sets" / "kitchen.yaml"


@pytest.fixture(scope="module")
def kitchen():
    return load_skill_set(KITCHEN)


@pytest.fixture
def room(tmp_path):
    """A folder with a set file's skills beside it: ``write(doc)`` writes ``set.yaml``
    and returns its path."""
    for name in ("drawer.yaml", "cabinet-vf.yaml", "cabinet-vf.npz", "teleop.yaml"):
        shutil.copy(ROOT / "skills" / name, tmp_path / name)
    drawer = (ROOT / "skills" / "drawer.yaml").read_text()
    (tmp_path / "drawer-as-teleop.yaml").write_text(drawer.replace("name: drawer", "name: teleop"))

    def write(doc, name: str = "set.yaml") -> Path:
        path = tmp_path / name
        path.write_text(doc if isinstance(doc, str) else yaml.safe_dump(doc))
        return path
    return write


def base(**changes) -> dict:
    doc = {"sctd_set": 1, "name": "room",
           "members": [{"skill": "drawer.yaml", "point": [0, 0, 0], "reach": 0.3},
                       {"skill": "cabinet-vf.yaml"}]}
    doc.update(changes)
    return doc


def fails(room, doc, where: str, problem: str) -> None:
    """Loading ``doc`` fails, naming the set file, the field ``where`` and ``problem``."""
    path = room(doc)
    with pytest.raises(SkillError) as e:
        goal_set(load_skill_set(path))
    assert str(e.value).startswith(f"{path}: {where}: " if where else f"{path}: "), str(e.value)
    assert problem in str(e.value), str(e.value)


def test_the_shipped_kitchen_loads_and_runs_its_three_skills(kitchen):
    assert kitchen.name == "kitchen" and kitchen.teleop.name == "teleop" and kitchen.teleop_ref is None
    assert [(m.name, m.skill.object) for m in kitchen.members] == [
        ("drawer", "drawer_handle"), ("cabinet-vf", "door_handle"), ("light_switch-vf", "light_switch")]
    for m in kitchen.members:
        assert m.skill.id == bundle_from_file(ROOT / "skills" / m.ref).id
    goals = goal_set(kitchen)
    assert isinstance(goals, GoalSet) and goals.objects == {"drawer_handle", "door_handle", "light_switch"}
    assert goals.members[0].reach == 0.30 and goals.members[2] == Member(kitchen.members[2].skill)
    assert len(kitchen.bundles()) == 4  # the members' and teleoperation's
    shipped = shipped_folder() / "sets" / "kitchen.yaml"
    assert find_skill_set("kitchen") == find_skill_set("kitchen.yaml") == shipped


def test_a_set_reads_back_what_it_writes(kitchen, room):
    doc = base(description="two", teleop="teleop.yaml", belief={"beta": 20, "threshold": 0.9})
    first = load_skill_set(room(doc))
    again = load_skill_set(room(first.to_yaml(), "again.yaml"))
    assert again.to_yaml() == first.to_yaml() and dataclasses.replace(again, source=first.source) == first
    assert first.belief == {"beta": 20.0, "threshold": 0.9} and first.teleop_ref == "teleop.yaml"
    assert goal_set(first).model == BeliefModel(beta=20.0, threshold=0.9)
    assert read_skill_set(kitchen.to_yaml(), "k", resolver(KITCHEN.parent)) == dataclasses.replace(
        kitchen, source="k")


def test_a_members_settings_are_the_runtimes_member_fields():
    """The reader checks the settings :class:`Member` takes (one definition of them:
    their defaults stay Member's)."""
    assert set(MEMBER_SETTINGS) == {f.name for f in dataclasses.fields(Member)} - {"skill"}


@pytest.mark.parametrize("doc, where, problem", [
    (base(sctd_set=2), "sctd_set", "expected format version 1"),
    (base(colour="red"), "colour", "unknown field"),
    (base(name=""), "name", "expected a non-empty string"),
    (base(members=[]), "members", "1 to 16 members, got 0"),
    (base(members={"skill": "drawer.yaml"}), "members", "expected a list"),
    (base(members=[{"skill": "drawer.yaml"}] * (MAX_MEMBERS + 1)), "members", "got 17"),
    (base(members=[{"skill": "drawer.yaml", "radius": 1}]), "members[0].radius", "unknown field"),
    (base(members=[{"reach": 0.3}]), "members[0].skill", "expected a non-empty string"),
    (base(members=[{"skill": "drawer.yaml", "reach": "far"}]), "members[0].reach", "expected a number"),
    (base(members=[{"skill": "drawer.yaml", "reach": float("nan")}]), "members[0].reach", "finite"),
    (base(members=[{"skill": "drawer.yaml", "reach": 0}]), "members[0].reach", "must be > 0.0"),
    (base(members=[{"skill": "drawer.yaml", "angle_tolerance": 4}]), "members[0].angle_tolerance",
     "must be <="),
    (base(members=[{"skill": "drawer.yaml", "point": [0, 0]}]), "members[0].point", "a list of 3"),
    (base(members=[{"skill": "drawer.yaml", "point": [0, 0, 20]}]), "members[0].point[2]", "<= 10.0"),
    (base(members=[{"skill": "drawer.yaml"}, {"skill": "drawer.yaml"}]), "members[1].skill",
     "skill name 'drawer' is also members[0]'s"),
    (base(members=[{"skill": "teleop.yaml"}]), "members[0].skill",
     "skill 'teleop' is on 'world': a member is tied to its task object"),
    (base(members=[{"skill": "drawer-as-teleop.yaml"}]), "members[0].skill",
     "skill name 'teleop' is also teleop's"),
    (base(teleop="drawer.yaml"), "teleop", "is on the object 'drawer_handle': teleoperation runs on 'world'"),
    (base(teleop=7), "teleop", "expected a non-empty string"),
    (base(belief={"beta": 40, "gamma": 1}), "belief.gamma", "unknown field"),
    (base(belief={"threshold": 0.3}), "belief.threshold", "expected a number in (0.5, 1)"),
    (base(belief={"beta": "sharp"}), "belief.beta", "expected a number"),
    (base(belief=[1]), "belief", "expected a mapping"),
])
def test_each_error_names_the_set_file_and_the_field(room, doc, where, problem):
    fails(room, doc, where, problem)


def test_a_members_own_error_is_passed_on_behind_the_set_file(room, tmp_path):
    fails(room, base(members=[{"skill": "nope.yaml"}]), "members[0].skill",
          f"nope.yaml: no such skill: not a file ({tmp_path / 'nope.yaml'})")
    broken = (ROOT / "skills" / "drawer.yaml").read_text().replace("object: drawer_handle", "object: ''")
    (tmp_path / "broken.yaml").write_text(broken)
    fails(room, base(members=[{"skill": "broken.yaml"}]), "members[0].skill",
          f"{tmp_path / 'broken.yaml'}: object: expected a non-empty string")
    (tmp_path / "binary.yaml").write_bytes(b"sctd_skill: 1\n\xff\xfe")
    fails(room, base(members=[{"skill": "binary.yaml"}]), "members[0].skill",
          f"{tmp_path / 'binary.yaml'}: not UTF-8 text (byte 14)")


def test_a_skill_that_reacts_to_the_choose_button_is_refused(room, tmp_path):
    text = (ROOT / "skills" / "teleop.yaml").read_text()
    (tmp_path / "chooser.yaml").write_text(text.replace("name: teleop", "name: chooser").replace(
        "object: world", "object: mug").replace(
        "type: button, button: 0}\n    - {from: rotate", "type: button, button: 3}\n    - {from: rotate"))
    fails(room, base(members=[{"skill": "chooser.yaml"}]), "members[0].skill",
          f"{tmp_path / 'chooser.yaml'}: fsm.transitions[0].button: button 3 is the skill set's "
          "choose button")
    (tmp_path / "teleop3.yaml").write_text(text.replace("button: 0}", "button: 3}"))
    fails(room, base(teleop="teleop3.yaml"), "teleop", "fsm.transitions[0].button: button 3")


def test_a_set_file_that_is_not_a_mapping_or_not_yaml(room):
    fails(room, "- just a list\n", "", "expected a mapping")
    path = room("name: a\nname: b\n")
    with pytest.raises(SkillError, match=rf"{path}: line \d+: invalid YAML \(duplicate key 'name'\)"):
        load_skill_set(path)


def test_skills_resolve_beside_the_set_file_else_as_skill_takes_them(room, tmp_path, monkeypatch):
    """A member named like a shipped skill is the file beside the set when there is
    one, else the shipped skill; never a file of the working directory."""
    (tmp_path / "drawer.yaml").unlink()
    cwd = tmp_path / "elsewhere"
    cwd.mkdir()
    (cwd / "drawer.yaml").write_text("not a skill")
    monkeypatch.chdir(cwd)
    s = load_skill_set(room(base()))
    assert s.members[0].skill.source == str(ROOT / "skills" / "drawer.yaml")
    assert s.members[1].skill.source == str(tmp_path / "cabinet-vf.yaml")


def _run_args(*argv: str):
    p = Parser(prog="sctd run")
    add_run_arguments(p)
    return p.parse_args(list(argv))


def test_one_skill_runs_as_it_always_did_and_two_make_a_set():
    one = daemon_skills(_run_args("--skill", "drawer"))
    assert set(one) == {"skill", "bundle"} and one["skill"].name == "drawer"
    assert one["bundle"] == bundle_from_file(ROOT / "skills" / "drawer.yaml").pack()
    two = daemon_skills(_run_args("--skill", "drawer", "--skill", "cabinet-vf"))
    assert two["skill"] is None and two["set_name"] == "drawer+cabinet-vf"
    assert [m.name for m in two["goals"].members] == ["drawer", "cabinet-vf"]
    assert two["goals"].teleop.name == "teleop" and len(two["set_bundles"]) == 3
    kitchen = daemon_skills(_run_args("--set", str(KITCHEN)))
    assert kitchen["set_name"] == "kitchen" and len(kitchen["goals"].members) == 3
    with pytest.raises(SkillError, match=r"^--skill: members\[1\]\.skill: skill name 'drawer' is also"):
        daemon_skills(_run_args("--skill", "drawer", "--skill", "drawer"))
    with pytest.raises(SkillError, match=r"^nope: no such skill"):
        skill_set_of(["drawer", "nope"])


def test_run_takes_a_skill_or_a_set_not_both(capsys):
    for argv in (("--skill", "drawer", "--set", "kitchen"), ()):
        with pytest.raises(SystemExit) as e:
            _run_args(*argv)
        assert e.value.code == 2
    assert "--set" in capsys.readouterr().err
    with pytest.raises(SkillError, match=r"^nope: no such skill set: .* \(shipped: .*\bkitchen\b.*\)"):
        daemon_skills(_run_args("--set", "nope"))


def test_inspect_checks_a_set_as_run_does_and_shows_its_members(room, capsys):
    from sctd.cli.main import main

    assert main(["inspect", "--set", "doors", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["name"] == "doors" and s["teleop"]["name"] == "teleop" and "engaged" not in s
    assert [(m["name"], m["object"], m["reach"]) for m in s["members"]] == [
        ("cabinet-vf", "door_handle", 0.35), ("drawer", "drawer_handle", 0.35),
        ("oven-vf", "oven_handle", 0.35)]
    assert s["members"][1]["start"] == "reach" and s["belief"] == dataclasses.asdict(BeliefModel())
    assert main(["inspect", "--set", "kitchen"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("skill set kitchen (") and "member cabinet-vf (id " in out
    bad = room(base(belief={"threshold": 0.3}))  # in range for the file's reader, not the runtime's
    assert main(["inspect", "--set", str(bad)]) == 2
    assert capsys.readouterr().err.strip() == (
        f"sctd inspect: {bad}: belief.threshold: expected a number in (0.5, 1), got 0.3")
    assert main(["inspect", "drawer", "--set", "doors"]) == 2
    assert main(["inspect"]) == 2
    assert "SKILL or --set" in capsys.readouterr().err


def test_skills_sets_lists_the_shipped_sets_read_and_checked(capsys):
    from sctd.cli.main import main

    assert main(["skills", "sets", "--json"]) == 0
    rows = {r["name"]: r for r in json.loads(capsys.readouterr().out)}
    assert {"doors", "kitchen", "kitchen-pour"} <= set(rows)
    assert rows["kitchen-pour"]["members"] == ["pour", "drawer", "light_switch-vf"]
    assert all("error" not in r and r["teleop"] == "teleop" for r in rows.values())
    assert main(["skills"]) == 0
    assert "skill sets (sctd skills sets): doors, " in capsys.readouterr().out
