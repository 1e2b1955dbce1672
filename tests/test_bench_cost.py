"""``sctd bench cost`` and ``sctd bench check``: the baseline tree, the CPU and wake-up
counts from /proc, the verdicts against the goals, and the check's operating points."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import threading
import time

import pytest

from sctd.bench import check as bench_check
from sctd.bench import cost
from sctd.cli.main import build_parser, main
from sctd_services.learner.check import CheckSettings, SequentialRule
from tests.conftest import ROOT


def test_a_baseline_folder_runs_with_its_own_packages_first(tmp_path):
    for sub in cost.IMPORT_FOLDERS.values():
        (tmp_path / "tree" / sub).mkdir(parents=True)
    with cost.ExitStack() as stack:
        tree = cost.source_tree(str(tmp_path / "tree"), stack)
        assert tree.label == "baseline" and tree.env is not None
        links = tree.env["PYTHONPATH"].split(os.pathsep)[0]
        for name, sub in cost.IMPORT_FOLDERS.items():
            assert os.path.realpath(os.path.join(links, name)) == str((tmp_path / "tree" / sub).resolve())
    assert not os.path.exists(links)  # removed with the stack


def test_a_baseline_that_is_not_a_source_tree_is_refused_naming_what_is_missing(tmp_path):
    (tmp_path / "sctd").mkdir()
    with cost.ExitStack() as stack, pytest.raises(RuntimeError, match=r"not an sctd source tree .*sim"):
        cost.source_tree(str(tmp_path), stack)


def test_cpu_and_wakeups_are_read_from_proc():
    cpu0, sleeps0 = cost.tree_cpu(os.getpid())
    end = time.process_time() + 0.05
    while time.process_time() < end:
        pass
    for _ in range(20):
        time.sleep(0.001)
    cpu1, sleeps1 = cost.tree_cpu(os.getpid())
    assert cpu1 > cpu0 and sleeps1 >= sleeps0 + 20
    assert cost.tree_cpu(2**22 + 12345) == (0.0, 0)  # no such process: nothing


def test_cpu_is_told_apart_by_thread():
    """CPU spent in this thread is counted under its label (``main`` for the process's
    first thread, ``python`` for another, as under pytest-xdist), and a thread that only
    sleeps adds next to nothing to the other."""
    me = "main" if threading.get_native_id() == os.getpid() else "python"
    stop = threading.Event()
    t = threading.Thread(target=stop.wait, daemon=True)
    t.start()
    before = cost.thread_cpu(os.getpid())
    end = time.process_time() + 0.3
    while time.process_time() < end:
        pass
    after = cost.thread_cpu(os.getpid())
    stop.set()
    t.join()
    spent = {k: after[k] - before.get(k, 0.0) for k in after}
    assert spent[me] >= 0.25 and max(v for k, v in spent.items() if k != me) < 0.1, spent
    shares = cost.threads_between(before, after, 1.0)
    assert next(iter(shares)) == me  # largest first
    assert cost.thread_cpu(2**22 + 12345) == {}


def _phase(tree: str, spin: float, daemon: float, sim: float, late: float) -> dict:
    return {"tree": tree, "phase": f"pour zero spin {spin:g} us", "skill": "pour", "input": "zero",
            "spin_us": spin, "floor": False, "daemon_cpu": daemon, "sim_cpu": sim, "daemon_wakeups": 5000,
            "sim_wakeups": 5000, "lateness_p99_ms": late, "compute_p99_ms": 0.05, "latency_ms": None}


def test_the_verdicts_judge_this_trees_worst_phase_of_each_kind():
    floor = {**_phase("this", 0, 0.15, 0.45, 0.0), "floor": True}
    r = {"phases": [_phase("this", 0, 0.21, 0.19, 0.15), _phase("this", 0, 0.24, 0.18, 0.01),
                    _phase("this", 100, 0.4, 0.18, 0.01), _phase("baseline", 0, 0.5, 0.9, 0.9), floor],
         "lockstep": [{"tree": "this", "ms_per_step": 0.1}, {"tree": "baseline", "ms_per_step": 0.3}]}
    lines = cost.verdicts(r)
    # the spin-off phases against the floor of the same run: 0.24 / 0.15; a spin is not judged
    assert "  daemon, spin off, against the floor (15.0 %): worst 1.60x (goal <= 1.5x): NOT met" in lines
    r["phases"][1]["daemon_cpu"] = 0.22
    met = "  daemon, spin off, against the floor (15.0 %): worst 1.47x (goal <= 1.5x): met"
    assert met in cost.verdicts(r)
    assert not any("against the floor" in x for x in cost.verdicts({**r, "phases": r["phases"][:-1]}))
    assert "  lateness p99: worst 0.150 ms (goal <= 0.20 ms): met" in lines
    # the simulator and the lockstep step are figures, not goals (the floors replaced them)
    assert not any("simulator" in x or "lockstep" in x for x in lines)
    # a slower tick is no goal: its worst spin-off phase against the same 1 kHz floor, and
    # it never stands in for the 1 kHz phases the goal is about
    slow = [{**_phase("this", 0, 0.12, 0.2, 0.3), "rate": 500.0}, {**_phase("this", 100, 0.3, 0.2, 0.01),
                                                                  "rate": 500.0}]
    lines = cost.verdicts({**r, "phases": [*r["phases"], *slow]})
    assert ("  daemon at 500 Hz, spin off: worst 12.0 % of a core, 0.80x the 1 kHz floor, lateness p99 "
            "worst 0.300 ms (no goal)") in lines
    assert met in lines and "  lateness p99: worst 0.150 ms (goal <= 0.20 ms): met" in lines


def test_each_rate_is_a_phase_of_its_own_with_the_daemons_rate_on_its_command_line():
    """``--rates 1000,250``: every skill x input x spin at each rate, the daemon started with
    it; the floor once, at 1 kHz; a rate the simulator does not reach is refused."""
    argv = ["bench", "cost", "--skills", "pour", "--inputs", "full", "--spins", "0,100",
            "--rates", "1000,250"]
    args = build_parser(argv).parse_args(argv)
    phases = cost.phases_of(args)
    assert [p.name for p in phases] == ["pour full spin 0 us", "pour full spin 100 us",
                                        "pour full spin 0 us 250 Hz", "pour full spin 100 us 250 Hz",
                                        "floor: bare Zenoh peer"]
    argv = phases[2].daemon_argv("tcp/127.0.0.1:7447")
    assert argv[:2] == ("sctd.cli.main", "run") and argv[argv.index("--rate") + 1] == "250"
    assert argv[argv.index("--spin-us") + 1] == "0" and argv[argv.index("--skill") + 1] == "pour"
    assert phases[-1].rate == 1000.0 and "--rate" not in phases[-1].daemon_argv("tcp/127.0.0.1:7447")
    assert main(["bench", "cost", "--rates", "1000,2000"]) == 2


def test_bad_lists_are_refused_by_name(capsys):
    with pytest.raises(SystemExit):
        main(["bench", "cost", "--inputs", "zero,half"])
    assert "'zero,half': comma-separated zero and/or full" in capsys.readouterr().err


def test_the_fixed_rule_is_the_one_the_check_replaced():
    assert round(bench_check.fixed_rule(0.8), 3) == 0.376 and round(bench_check.fixed_rule(0.95), 3) == 0.914


def test_bench_check_prints_the_operating_points_without_processes(capsys):
    assert main(["bench", "check", "--no-end-to-end", "--sequences", "3000", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    rule = SequentialRule.around(CheckSettings().floor, CheckSettings().trials)
    for p in r["points"]:
        exact, n = rule.operating_point(p["p"])
        assert p["accept_exact"] == round(exact, 4) and p["trials_exact"] == round(n, 2)
        assert abs(p["accept_simulated"] - exact) <= 4 * math.sqrt(max(exact * (1 - exact), 1e-4) / 3000)
    assert r["runs"] == []


def test_each_figure_of_the_check_is_printed_with_its_floor():
    run = {"tree": "this", "request_to_swap_s": 19.0, "trials_alone_s": 14.0, "successes": 6, "trials": 6,
           "swapped": True, "timings": {"train_s": 2.0, "check_s": 16.5, "swap_s": 0.1},
           "lateness_quiet_ms": {"median": 0.005, "max": 0.005},
           "lateness_check_ms": {"median": 0.005, "max": 0.19}}
    line = bench_check._run_line(run)
    assert "19.0 s (floor  16.0)" in line and "check  16.5 (floor  14.0)" in line
    assert "floor" not in bench_check._run_line({**run, "trials_alone_s": None})
    assert "\n" not in line  # a swap is one line; a run that did not swap says the learner's why
    why = "not swapped: no daemon answered on sctd/edan/skill/swap; check: 6/6 trials succeeded"
    refused = bench_check._run_line({**run, "swapped": False, "reason": why}).splitlines()
    assert "NOT swapped" in refused[0] and refused[1] == f"      the learner: {why}"


@pytest.mark.slow
def test_the_checks_trials_alone_run_in_a_trees_own_environment():
    """The floor of the check: its trials without the learner, timed, in the tree's
    programs (here this code's)."""
    from sctd.task import find_task

    got = bench_check.trials_alone(cost.Tree("this"), find_task("pour"), ROOT / "skills" / "pour-linear.yaml",
                                   1, CheckSettings().seed)
    assert got["wall_s"] > 0 and got["successes"] in (0, 1)


@pytest.mark.slow
def test_a_baseline_commit_is_what_its_programs_import(tmp_path):
    """Exported from this repository, its programs import its packages, not the ones this
    code was loaded from (``python -m`` puts the working folder first: not a source tree's)."""
    if not (ROOT / ".git").exists():
        pytest.skip("needs a git checkout")
    with cost.ExitStack() as stack:
        tree = cost.source_tree("HEAD", stack)
        code = ("import sctd, sctd_sim, sctd_services; print(sctd.__file__); print(sctd_sim.__file__); "
                "print(sctd_services.__file__)")
        got = subprocess.run([sys.executable, "-c", code], env=tree.env, cwd=tree.cwd, capture_output=True,
                             text=True, check=True)
        links = tree.env["PYTHONPATH"].split(os.pathsep)[0]
        for f in got.stdout.split():
            assert f.startswith(links) and not f.startswith(str(ROOT)), got.stdout


@pytest.mark.slow
def test_bench_cost_measures_this_tree_and_a_commit_side_by_side(capsys, tmp_path):
    """One phase in each tree (the baseline exported from this repository's HEAD) and the
    floor: every figure there, and the programs ran (CPU and wake-ups counted)."""
    if not (ROOT / ".git").exists():
        pytest.skip("needs a git checkout")
    assert main(["bench", "cost", "--baseline", "HEAD", "--skills", "pour", "--inputs", "full",
                 "--spins", "50", "--window", "2", "--warmup", "1", "--eval-trials", "0",
                 "--tick-ticks", "100", "--json", "--logs", str(tmp_path)]) == 0
    r = json.loads(capsys.readouterr().out)
    # the tick path, this tree's probe on each tree's code: back to back and after the sleep,
    # then the floor's path in each tree, and the control loop
    assert [(x["tree"], x["skill"], x["input"], x["sleep_us"]) for x in r["tick_path"]] == [
        ("baseline", "pour", "full", 0.0), ("baseline", "pour", "full", 900.0),
        ("this", "pour", "full", 0.0), ("this", "pour", "full", 900.0),
        ("baseline", "floor", "zero", 0.0), ("baseline", "floor", "zero", 900.0),
        ("this", "floor", "zero", 0.0), ("this", "floor", "zero", 900.0),
        ("this", "loop", "zero", 0.0), ("this", "loop", "zero", 900.0)]
    assert all(x["us_per_tick"] > 0 for x in r["tick_path"])
    assert all(x["modes"] == {"running": 100} for x in r["tick_path"] if x["skill"] == "pour")
    assert [(p["tree"], p["floor"]) for p in r["phases"]] == [
        ("baseline", False), ("this", False), ("this", True)]
    for p in r["phases"]:
        assert p["daemon_cpu"] > 0 and p["sim_cpu"] > 0 and p["daemon_wakeups"] > 500
        # where it went, thread by thread: the tick's own thread and Zenoh's, summing to the whole
        assert p["daemon_threads"]["main"] > 0 and any(k in p["daemon_threads"] for k in ("rx", "tx", "net"))
        # /proc counts each thread's time in whole clock ticks (10 ms: 0.005 of a core over
        # this 2 s window) and the process's from the exact sum: each of the daemon's ~20
        # threads and its skill server's is off by up to a tick at each reading, about 0.01
        # of a core in all (one standard deviation), so 0.05 is five of them
        assert abs(sum(p["daemon_threads"].values()) - p["daemon_cpu"]) < 0.05
    for p in r["phases"][:2]:
        assert p["lateness_p99_ms"] is not None and p["latency_ms"]["n"] > 50  # the person's pushes answered
