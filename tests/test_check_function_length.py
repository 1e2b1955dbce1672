"""``tools/check_function_length.py`` (run by ``make lint``): a function of 61 lines from
``def`` to its last line fails and is named; one of 60 passes."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

TOOL = Path(__file__).resolve().parents[1] / "tools" / "check_function_length.py"


@pytest.fixture(scope="module")
def checker():
    spec = importlib.util.spec_from_file_location("check_function_length", TOOL)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _function(name: str, lines: int) -> str:
    """A function ``lines`` long from its ``def`` line to its last, inclusive."""
    body = [f"    x{i} = {i}" for i in range(lines - 2)]
    return "\n".join([f"def {name}():", *body, "    return 0", ""])


def test_a_61_line_function_fails_and_is_named(checker, tmp_path, capsys):
    src = tmp_path / "long.py"
    src.write_text("import os\n\n\n" + _function("too_long", 61))
    assert checker.main([str(src)]) == 1
    assert capsys.readouterr().out.splitlines() == [f"{src}:4 too_long 61"]


def test_a_60_line_function_passes(checker, tmp_path, capsys):
    src = tmp_path / "ok.py"
    src.write_text(_function("just_fits", 60))
    assert checker.main([str(src)]) == 0
    assert capsys.readouterr().out == ""


def test_methods_and_nested_functions_are_measured_by_their_qualified_name(checker):
    nested = "\n".join("        " + line for line in _function("inner", 61).splitlines())
    source = f"class C:\n    def method(self):\n{nested}\n        return 1\n"
    found = {name: length for _, name, length in checker.function_lengths(source)}
    assert found == {"C.method": 63, "C.method.inner": 61}


def test_the_generated_codec_is_the_one_file_left_out(checker):
    assert [str(p) for p in checker.GENERATED] == ["sim/canbus/_codec_generated.py"]
    files = {str(p) for p in checker.python_files([TOOL.parents[1] / "sim" / "canbus"])}
    assert not any(f.endswith("_codec_generated.py") for f in files)
    assert any(f.endswith("codegen.py") for f in files)
