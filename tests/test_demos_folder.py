"""A folder of demonstrations says what it is of (``demos.yaml``): written by the
recorder and demogen, read by ``sctd learn``; a skill whose object is not in a task is
refused by ``sctd eval`` before its first trial."""

from __future__ import annotations

import argparse
import shutil

import pytest

from sctd.cli.learn import add_learn_arguments, main_learn
from sctd.cli.main import main
from sctd.skill import load_skill
from sctd.task import find_task
from sctd.task.demos import DEMOS_FILE, DemosInfo, DemosInfoError, read_demos_info
from sctd_services.record import check_demos_folder, note_demos_folder
from sctd_sim import demogen
from tests.conftest import ROOT

POUR_DEMOS = ROOT / "skills" / "demos" / "pour"


def _learn(*argv: str) -> int:
    return main_learn(add_learn_arguments(argparse.ArgumentParser()).parse_args(list(argv)))


def test_the_info_round_trips_and_bad_files_are_named(tmp_path):
    info = DemosInfo("pour", "mug")
    (tmp_path / DEMOS_FILE).write_text(info.to_yaml())
    assert read_demos_info(tmp_path) == info
    assert read_demos_info(tmp_path / "nothing-here") is None
    for text, message in [("[1, 2]", "expected a mapping"),
                          ("sctd_demos: 2\ntask: pour\nobject: mug\n", "sctd_demos: expected 1, got 2"),
                          ("sctd_demos: 1\ntask: pour\n", "object: expected a name, got None"),
                          ("sctd_demos: 1\ntask: pour\nobject: ''\n", "object: expected a name"),
                          ("sctd_demos: 1\ntask: pour\nobject: mug\nframe: x\n", "unknown key(s): frame"),
                          ("sctd_demos: 1\ntask: [pour\n", "demos.yaml")]:
        (tmp_path / DEMOS_FILE).write_text(text)
        with pytest.raises(DemosInfoError, match=r".*demos\.yaml.*") as e:
            read_demos_info(tmp_path)
        assert message in str(e.value)


def test_the_recorder_notes_the_folder_once_and_refuses_another_object(tmp_path):
    check_demos_folder(tmp_path, "mug")  # an empty folder takes anything
    note_demos_folder(tmp_path, DemosInfo("pour", "mug"))
    note_demos_folder(tmp_path, DemosInfo("drawer", "drawer_handle"))  # never overwritten
    assert read_demos_info(tmp_path) == DemosInfo("pour", "mug")
    assert not list(tmp_path.glob(".demo-*"))  # no temporary file left
    check_demos_folder(tmp_path, "mug")
    with pytest.raises(ValueError, match=r"demos\.yaml: the demonstrations here are of 'mug' \(task pour\), "
                                         r"not 'drawer_handle'"):
        check_demos_folder(tmp_path, "drawer_handle")


def test_generated_demonstrations_say_what_they_are_of(tmp_path):
    demogen.write_demo_set(demogen.generate(find_task("drawer"), 2, seed=0), tmp_path)
    assert read_demos_info(tmp_path) == DemosInfo("drawer", "drawer_handle")


def test_learn_takes_the_object_from_the_folder_or_refuses(tmp_path, capsys):
    out = tmp_path / "pour.yaml"
    assert _learn(str(POUR_DEMOS), "--method", "linear", "--out", str(out), "--quiet") == 0
    assert load_skill(out).object == "mug"
    bare = tmp_path / "bare"
    shutil.copytree(POUR_DEMOS, bare)
    (bare / DEMOS_FILE).unlink()
    assert _learn(str(bare), "--method", "linear", "--out", str(tmp_path / "x.yaml"), "--quiet") == 2
    assert f"--object: name the task object whose frame the demonstrations are in: {bare} has no " \
           "demos.yaml" in capsys.readouterr().err
    assert _learn(str(POUR_DEMOS), "--method", "linear", "--object", "cup", "--out", str(tmp_path / "y.yaml"),
                  "--quiet") == 2
    assert "--object cup: the demonstrations in" in capsys.readouterr().err
    assert not (tmp_path / "x.yaml").exists() and not (tmp_path / "y.yaml").exists()


def test_eval_refuses_a_skill_whose_object_is_not_in_the_task(tmp_path, capsys):
    text = (ROOT / "skills" / "drawer-vf.yaml").read_text()
    skill = tmp_path / "lost.yaml"
    skill.write_text(text.replace("object: drawer_handle", "object: object")
                     .replace("frame: drawer_handle", "frame: object"))  # (its region's)
    shutil.copy(ROOT / "skills" / "drawer-vf.npz", tmp_path / "drawer-vf.npz")
    assert main(["eval", "--skill", str(skill), "--task", "cabinet", "--trials", "10", "--lockstep"]) == 2
    err = capsys.readouterr().err
    assert "its object 'object' is not in task cabinet" in err and "trials" not in err
