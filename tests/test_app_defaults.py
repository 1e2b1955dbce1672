"""sctd.app.defaults: the tasks and skills commands take when not told, read from
``sctd/app/defaults.yaml``; a missing or malformed file is an error naming the file and
the field, which ``sctd`` reports with exit 2."""

from __future__ import annotations

import argparse

import pytest
import yaml

from sctd.app import defaults as defaults_module
from sctd.app.defaults import DEFAULTS_FILE, DefaultsError, defaults, defaults_from_document, load_defaults
from sctd.bench.demos import demo_kind
from sctd.skill.catalog import find_skill
from sctd.task import find_task


@pytest.fixture
def shipped_doc() -> dict:
    return yaml.safe_load(DEFAULTS_FILE.read_text())


@pytest.fixture
def broken_defaults(tmp_path, monkeypatch):
    """Points the shipped defaults at a file the test writes (``sctd_defaults: 1`` with no
    task); the cached defaults are dropped before and after."""
    path = tmp_path / "defaults.yaml"
    path.write_text("sctd_defaults: 1\nskill: pour\n")
    monkeypatch.setattr(defaults_module, "DEFAULTS_FILE", path)
    defaults.cache_clear()
    yield path
    defaults.cache_clear()


def test_the_shipped_defaults_name_tasks_and_skills_that_exist():
    d = load_defaults(DEFAULTS_FILE)
    assert d == defaults()
    assert (d.task, d.skill, d.learned_skill) == ("pour", "pour", "pour-vf")
    task = find_task(d.task)
    for skill in (d.skill, d.learned_skill):
        assert find_skill(skill).is_file()
    assert find_task(d.bench_learn.tilt).scene.held is not None
    assert demo_kind(d.bench_learn.tilt).shape == "tilt"
    assert demo_kind(d.bench_learn.pull).shape == "pull"
    assert [demo_kind(k).name for k in d.bench_learn.fields] == list(d.bench_learn.fields)
    assert task.object == "mug"


def test_the_defaults_file_is_no_task_and_no_skill():
    """It sits beside its reader, not among the shipped tasks or skills, whose catalogs
    take every ``*.yaml`` of their folder."""
    from sctd.skill.catalog import shipped_folder as skills_folder
    from sctd.task import shipped_folder as tasks_folder

    assert DEFAULTS_FILE.parent.name == "app" and DEFAULTS_FILE.is_file()
    assert DEFAULTS_FILE.parent not in (skills_folder(), tasks_folder())


@pytest.mark.parametrize("change, where, problem", [
    ({"sctd_defaults": 2}, "sctd_defaults", "expected 1, got 2"),
    ({"task": None}, "task", "expected a task's or skill's name, got None"),
    ({"skill": ""}, "skill", "expected a task's or skill's name, got ''"),
    ({"learned_skill": 3}, "learned_skill", "got 3"),
    ({"colour": "red"}, "", "unknown field 'colour'"),
    ({"bench_learn": {"tilt": "pour", "pull": "drawer"}}, "bench_learn.fields", "expected a list"),
    ({"bench_learn": {"tilt": "pour", "pull": "drawer", "fields": ["pour", 7]}}, "bench_learn.fields[1]",
     "expected a name, got 7"),
    ({"bench_learn": {"pull": "drawer", "fields": ["pour"]}}, "bench_learn.tilt", "missing"),
    ({"bench_learn": []}, "bench_learn", "expected a mapping"),
    ({"gripper": {"force": 20}}, "gripper.open_hold", "missing"),
    ({"gripper": {"force": -1, "open_hold": 0.5}}, "gripper.force", "expected a number in (0, 1000], got -1"),
    ({"gripper": {"force": 20, "open_hold": "long"}}, "gripper.open_hold", "got 'long'"),
    ({"gripper": {"force": 20, "open_hold": 0.5, "speed": 1}}, "gripper", "unknown field 'speed'"),
])
def test_a_malformed_document_names_the_field(shipped_doc, change, where, problem):
    doc = {**shipped_doc, **change}
    with pytest.raises(DefaultsError) as e:
        defaults_from_document(doc, "d.yaml")
    assert e.value.file == "d.yaml" and e.value.where == where and problem in e.value.problem


def test_a_missing_field_or_file_is_an_error(shipped_doc, tmp_path):
    doc = dict(shipped_doc)
    del doc["task"]
    with pytest.raises(DefaultsError, match=r"d\.yaml: task: missing"):
        defaults_from_document(doc, "d.yaml")
    with pytest.raises(DefaultsError, match="cannot open"):
        load_defaults(tmp_path / "none.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("task: [\n")
    with pytest.raises(DefaultsError, match="invalid YAML"):
        load_defaults(bad)


def test_sctd_reports_a_broken_defaults_file_and_exits_2(broken_defaults, capsys):
    from sctd.cli.main import main

    assert main(["demo"]) == 2
    assert capsys.readouterr().err.strip() == f"sctd demo: {broken_defaults}: task: missing"
    assert main(["bench", "latency"]) == 2
    assert f"sctd bench latency: {broken_defaults}: task: missing" in capsys.readouterr().err


def test_the_simulator_and_the_stand_in_report_a_broken_defaults_file(broken_defaults, capsys):
    from sctd_sim import kinematic, service

    assert service.main([]) == 2
    assert f"sctd sim: {broken_defaults}: task: missing" in capsys.readouterr().err
    assert kinematic.main([]) == 2
    assert f"sctd kinematic: {broken_defaults}: task: missing" in capsys.readouterr().err


def test_the_flags_take_their_defaults_from_the_file():
    from sctd.bench.eval import add_bench_eval_arguments
    from sctd.bench.latency import add_latency_arguments
    from sctd.cli.demo import add_demo_arguments
    from sctd_sim.kinematic import add_arguments as add_kinematic_arguments

    d = defaults()
    for add, dest, value in ((add_demo_arguments, "skill", d.skill),
                             (add_latency_arguments, "skill", d.skill),
                             (add_bench_eval_arguments, "skill", d.learned_skill),
                             (add_kinematic_arguments, "task", d.task)):
        p = argparse.ArgumentParser()
        add(p)
        assert getattr(p.parse_args([]), dest) == value
        assert f"(default {value})" in " ".join(p.format_help().split())


def test_sctd_run_takes_the_grasp_buttons_settings_from_the_file(tmp_path, monkeypatch, shipped_doc):
    """``--grasp-force`` and ``--grasp-open-hold`` default to the file's ``gripper``, and
    the runtime's own defaults (a config built in code) are the shipped file's numbers."""
    from sctd.cli.run import add_run_arguments
    from sctd.runtime.controller import RuntimeConfig

    shipped = defaults().gripper
    config = RuntimeConfig()
    assert (config.grasp_force, config.grasp_open_hold) == (shipped.force, shipped.open_hold)
    path = tmp_path / "defaults.yaml"
    path.write_text(yaml.safe_dump({**shipped_doc, "gripper": {"force": 35, "open_hold": 0.8}}))
    monkeypatch.setattr(defaults_module, "DEFAULTS_FILE", path)
    defaults.cache_clear()
    try:
        p = argparse.ArgumentParser()
        add_run_arguments(p)
        args = p.parse_args(["--skill", "pour"])
        assert (args.grasp_force, args.grasp_open_hold) == (35.0, 0.8)
        assert "(default 35.0)" in " ".join(p.format_help().split())
        assert p.parse_args(["--skill", "pour", "--grasp-force", "12"]).grasp_force == 12.0
    finally:
        defaults.cache_clear()
