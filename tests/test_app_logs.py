"""Log folders: ``--logs`` is always kept; a temporary one is removed when the command
succeeds, kept and named when it fails, and removed when it stayed empty."""

from __future__ import annotations

from sctd.app import logs


def test_a_temporary_folder_goes_on_success_and_stays_named_on_failure(capsys):
    ok = logs.log_folder(None, "sctd-test-")
    (ok / "daemon.log").write_text("ran\n")
    logs.finish(True)
    assert not ok.exists()

    failed = logs.log_folder(None, "sctd-test-")
    empty = logs.log_folder(None, "sctd-test-")
    (failed / "daemon.log").write_text("stopped on an error\n")
    logs.finish(False)
    assert failed.exists() and not empty.exists()
    assert f"the logs of this run are kept in {failed}" in capsys.readouterr().err
    (failed / "daemon.log").unlink()
    failed.rmdir()


def test_the_folder_logs_names_is_made_and_never_removed(tmp_path):
    given = logs.log_folder(tmp_path / "a" / "b", "sctd-test-")
    assert given == tmp_path / "a" / "b" and given.is_dir()
    logs.finish(True)
    assert given.is_dir()


def test_a_command_s_temporary_logs_follow_its_exit_code(tmp_path, monkeypatch):
    """Through ``sctd``'s entry point: the folder a failing command made is kept."""
    from sctd.cli import main as cli

    made = []

    def command(code):
        def run(args):
            made.append(logs.log_folder(None, "sctd-test-"))
            (made[-1] / "x.log").write_text("x\n")
            return code
        return run

    for code in (0, 1):
        monkeypatch.setattr(cli, "build_parser", lambda argv, c=code: _Parser(command(c)))
        assert cli.main([]) == code
    assert not made[0].exists() and made[1].exists()
    (made[1] / "x.log").unlink()
    made[1].rmdir()


class _Parser:
    def __init__(self, func):
        self.func = func

    def parse_args(self, argv):
        import argparse
        return argparse.Namespace(func=self.func, command="test")
