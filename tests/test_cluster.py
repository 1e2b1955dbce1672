"""Lockstep trials on a Dask cluster (``services/eval/cluster.py``, docs/cluster.md).

Fast: the address checks (plain TCP only on loopback, TLS with its files), a shipped
trial against the trial read from files, and the report of a dead worker's trials from
the scheduler's event (a stand-in client). Slow: ``sctd cluster scheduler`` and
``sctd cluster worker`` on loopback, the same results as local runs, a worker killed
mid-evaluation; and hosts in network namespaces over mutual TLS with ``sctd certs``.
"""

from __future__ import annotations

import json
import os
import signal
import threading
from pathlib import Path
from typing import Any

import pytest

from sctd.cli.main import main
from sctd.task import find_task
from sctd_services.eval.cluster import (
    SERVER_ROLE,
    ClusterError,
    ClusterExecutor,
    Rerun,
    TlsFiles,
    check_address,
    check_listen,
    connect,
    tls_files,
)
from sctd_services.eval.evaluate import Shipped, entries, evaluate, lockstep_job, shipped_job
from sctd_services.eval.trial import TaskSpec
from tests.conftest import ROOT, sctd, wait_for

SKILL = str(ROOT / "skills" / "pour.yaml")
SHORT = TaskSpec.of(find_task("pour"), time_limit=1.0)  # simulated s: a trial of a few tenths of a second


# --- fast: no process ---------------------------------------------------------------


@pytest.mark.parametrize("address", ["tcp://10.213.13.1:8786", "10.0.0.5:8786", "tcp://robot-pc:8786",
                                     "tcp://[2001:db8::1]:8786"])
def test_plain_tcp_to_another_host_is_refused(address):
    with pytest.raises(ClusterError, match="plain tcp:// is for loopback only"):
        check_address(address, None)
    with pytest.raises(ClusterError, match="loopback only"):
        connect(address)  # refused before anything is sent


@pytest.mark.parametrize("address", ["tcp://127.0.0.1:8786", "127.0.0.1:8786", "tcp://localhost:1",
                                     "tcp://[::1]:8786"])
def test_plain_tcp_on_loopback_is_allowed(address):
    assert check_address(address, None).startswith("tcp://")


def test_tls_needs_its_files_and_plain_tcp_refuses_them(tmp_path):
    with pytest.raises(ClusterError, match="tls:// needs --certs"):
        check_address("tls://10.213.13.1:8786", None)
    files = TlsFiles.from_folder(tmp_path, "sctd-operator")
    assert check_address("tls://10.213.13.1:8786", files) == "tls://10.213.13.1:8786"
    with pytest.raises(ClusterError, match="use tls://"):
        check_address("tcp://127.0.0.1:8786", files)
    with pytest.raises(ClusterError, match=r"ca\.pem: no such file"):
        files.security()
    with pytest.raises(ClusterError, match="udp://"):
        check_address("udp://127.0.0.1:8786", None)


def test_listening_beyond_loopback_needs_tls(tmp_path):
    check_listen("127.0.0.1", None)
    with pytest.raises(ClusterError, match=r"--host 0\.0\.0\.0: plain TCP listens on loopback only"):
        check_listen("0.0.0.0", None)
    check_listen("10.213.13.1", TlsFiles.from_folder(tmp_path, SERVER_ROLE))


def test_tls_flags():
    assert tls_files(None, None, None, None, "sctd-learner") is None
    assert tls_files(None, None, None, "/c", "sctd-learner") == TlsFiles(
        Path("/c/ca.pem"), Path("/c/sctd-learner.pem"), Path("/c/sctd-learner-key.pem"))
    with pytest.raises(ClusterError, match="go together"):
        tls_files("ca.pem", None, None, None, "sctd-learner")
    with pytest.raises(ClusterError, match="one or the other"):
        tls_files("a", "b", "c", "/c", "sctd-learner")


def test_sctd_eval_refuses_plain_tcp_to_another_host(capsys):
    rc = main(["eval", "--skill", "pour", "--lockstep", "--trials", "1",
               "--scheduler", "tcp://10.213.13.1:8786"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "sctd eval: --scheduler tcp://10.213.13.1:8786: plain tcp:// is for loopback only" in err
    assert main(["eval", "--skill", "pour", "--scheduler", "tcp://127.0.0.1:1"]) == 2  # real time
    assert "--scheduler: only with --lockstep" in capsys.readouterr().err


def test_a_shipped_trial_is_the_trial_read_from_files():
    """What a worker on another host runs (the skill's bundle, the task file's text) gives
    what the trial read from this machine's files gives, seed for seed."""
    shipped = Shipped.of(SKILL, SHORT, None)
    for seed in (0, 1):
        assert shipped_job(shipped, SHORT, seed, False) == lockstep_job(SKILL, SHORT, seed, None, False, None)


class _FakeFuture:
    def __init__(self) -> None:
        self.callbacks: list = []

    def add_done_callback(self, fn) -> None:
        self.callbacks.append(fn)

    def cancel(self) -> None:
        pass


class _FakeClient:
    """What :class:`ClusterExecutor` uses of a Dask client; events are delivered by hand."""

    class scheduler:
        address = "tcp://127.0.0.1:8786"

    def __init__(self) -> None:
        self.handlers: dict[str, Any] = {}
        self.keys: list[str] = []

    def subscribe_topic(self, topic: str, handler) -> None:
        self.handlers[topic] = handler

    def submit(self, fn, *args: Any, key: str, pure: bool) -> _FakeFuture:
        self.keys.append(key)
        return _FakeFuture()


def test_a_dead_workers_trials_are_reported_by_name():
    from sctd_services.eval.evaluate import Trial

    client = _FakeClient()
    heard: list[Rerun] = []
    ex = ClusterExecutor(client, heard.append)
    for s in (3, 4, 5):
        ex.submit(Trial(f"pour seed {s}", lockstep_job, ()))
    k3, k4, _ = client.keys
    client.handlers["all"]((0.0, {"action": "add-worker", "worker": "tcp://127.0.0.1:2"}))
    client.handlers["all"]((0.0, {"action": "remove-worker", "worker": "tcp://127.0.0.1:1",
                                  "processing-tasks": {k4, "someone-else"}, "lost-computed-tasks": {k3}}))
    assert heard == ex.reruns == [Rerun("tcp://127.0.0.1:1", ("pour seed 3", "pour seed 4"))]
    assert str(heard[0]) == "worker tcp://127.0.0.1:1 died: trials pour seed 3, pour seed 4 re-run"


# --- slow: a cluster on loopback ------------------------------------------------------


def _printed(proc, prefix: str, timeout: float = 90.0) -> list[str]:
    """The words after ``prefix`` on the line the command prints once listening."""
    def line() -> str | None:
        text = proc.log_path.read_text(errors="replace")
        found = [ln for ln in text.splitlines() if ln.startswith(prefix)]
        return found[0] if found else None

    got = wait_for(lambda: line() or not proc.running(), timeout)
    assert isinstance(got, str), proc.log_path.read_text(errors="replace")[-3000:]
    return got.removeprefix(prefix).split()


def _listening(group: int) -> set[str]:
    """The addresses the processes of process group ``group`` listen on (TCP, from /proc)."""
    inodes = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            if int(stat.read_text().rsplit(")", 1)[1].split()[2]) != group:
                continue
            for fd in (stat.parent / "fd").iterdir():
                link = os.readlink(fd)
                if link.startswith("socket:["):
                    inodes.add(link[8:-1])
        except (OSError, IndexError, ValueError):  # a process gone meanwhile
            continue
    out = set()
    for table in ("tcp", "tcp6"):
        for row in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            f = row.split()
            if f[3] == "0A" and f[9] in inodes:  # LISTEN
                addr = bytes.fromhex(f[1].split(":")[0])
                ip = ".".join(str(b) for b in reversed(addr)) if table == "tcp" else addr.hex()
                out.add(ip)
    return out


@pytest.fixture(scope="module")
def loopback(tmp_path_factory):
    """``sctd cluster scheduler`` and ``sctd cluster worker --nworkers 2`` on loopback."""
    logs = tmp_path_factory.mktemp("cluster")
    with sctd("cluster", "scheduler", "--port", "0", log=logs / "scheduler.log") as scheduler:
        [address] = _printed(scheduler, "sctd cluster scheduler: ")
        with sctd("cluster", "worker", address, "--nworkers", "2", log=logs / "worker.log") as workers:
            _printed(workers, "sctd cluster worker: ")
            yield address, [scheduler.p.pid, workers.p.pid]


@pytest.mark.slow
def test_scheduler_workers_and_their_http_servers_listen_on_loopback_only(loopback):
    _, groups = loopback
    for group in groups:  # the scheduler; the nannies and their worker processes
        found = _listening(group)
        assert found and found <= {"127.0.0.1"}, found


def _local(trials: int, seed: int, tmp_path: Path) -> list[dict[str, Any]]:
    spec = TaskSpec.of(find_task("pour"), time_limit=4.0)
    [res] = evaluate(entries([SKILL], False, tmp_path), spec, trials, seed)
    return res["per_trial"]


@pytest.mark.slow
def test_trials_on_the_cluster_give_the_local_results(loopback, tmp_path):
    spec = TaskSpec.of(find_task("pour"), time_limit=4.0)
    with connect(loopback[0]) as pool:
        [res] = evaluate(entries([SKILL], False, tmp_path), spec, 3, 10, pool=pool)
        assert pool.reruns == []
        listening = pool.client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.address)
    assert listening.startswith("tcp://127.0.0.1:")
    assert res["per_trial"] == _local(3, 10, tmp_path)


@pytest.mark.slow
def test_a_killed_worker_has_its_trials_rerun_and_reported(loopback, tmp_path):
    heard: list[Rerun] = []
    with connect(loopback[0], on_rerun=heard.append) as pool:
        pids = pool.client.run(os.getpid)  # worker address -> its process
        victim = sorted(pids)[0]
        killed = threading.Event()

        def kill_when_busy() -> None:  # as soon as a trial runs on the victim
            if wait_for(lambda: pool.client.processing().get(victim), 120, 0.05):
                os.kill(pids[victim], signal.SIGKILL)
                killed.set()

        killer = threading.Thread(target=kill_when_busy, daemon=True)
        killer.start()
        spec = TaskSpec.of(find_task("pour"), time_limit=4.0)
        [res] = evaluate(entries([SKILL], False, tmp_path), spec, 6, 20, pool=pool)
        killer.join(5)
    assert killed.is_set()
    assert [r.worker for r in heard] == [victim], heard
    assert heard[0].trials and all(t.startswith("pour seed ") for t in heard[0].trials)
    assert res["trials"] == 6 and res["per_trial"] == _local(6, 20, tmp_path)


@pytest.mark.slow
def test_an_unreachable_scheduler_is_named_with_what_was_tried():
    from sctd.cli.procs import free_port

    address = f"tcp://127.0.0.1:{free_port()}"
    with pytest.raises(ClusterError, match=rf"--scheduler {address}: no Dask scheduler answered within 2 s "
                                           r"\(tried to connect over plain TCP\)"):
        connect(address, timeout=2.0)


# --- slow: hosts in network namespaces, mutual TLS ------------------------------------


@pytest.mark.slow
def test_trials_across_hosts_over_tls_with_sctd_certs(tmp_path):
    from sctd.deploy.netns import Hosts, last_json, namespaces
    from tests.conftest import require_namespaces, run_sctd

    require_namespaces()
    certs, other = tmp_path / "certs", tmp_path / "other"
    for d in (certs, other):
        r = run_sctd("certs", "--out", str(d))
        assert r.returncode == 0, r.stderr
    hosts = Hosts(["sched", "work", "client"], tmp_path / "logs")
    with hosts:
        address = f"tls://{hosts.addr('sched')}:8786"
        scheduler = hosts.python("sched", "sctd.cli.main", "cluster", "scheduler", "--host",
                                 hosts.addr("sched"), "--certs", str(certs), log="scheduler.log")
        assert wait_for(lambda: "sctd cluster scheduler: tls://" in scheduler.output(), 90), \
            scheduler.output()
        workers = hosts.python("work", "sctd.cli.main", "cluster", "worker", address, "--host",
                               hosts.addr("work"), "--certs", str(certs), log="worker.log")
        assert wait_for(lambda: "sctd cluster worker: tls://" in workers.output(), 90), workers.output()

        def eval_on(host_log: str, *flags: str) -> tuple[int, str]:
            p = hosts.python("client", "sctd.cli.main", "eval", "--skill", "pour", "--lockstep", "--trials",
                             "2", "--seed", "5", "--time-limit", "4", "--json", *flags, log=host_log)
            return p.p.wait(240), p.output()

        rc, out = eval_on("eval.log", "--scheduler", address, "--certs", str(certs))
        assert rc == 0, out[-3000:]
        got = last_json(out)
        assert got is not None and got["scheduler"] == address and got["reruns"] == [], out[-3000:]
        rc, out = eval_on("plain.log", "--scheduler", f"tcp://{hosts.addr('sched')}:8786")
        assert rc == 2 and "plain tcp:// is for loopback only" in out, out[-3000:]
        rc, out = eval_on("stranger.log", "--scheduler", address, "--certs", str(other))
        assert rc == 2 and "no Dask scheduler answered" in out, out[-3000:]
    assert namespaces(hosts.run_id) == []
    assert got["results"][0]["per_trial"] == json.loads(json.dumps(_local(2, 5, tmp_path)))


def test_the_learner_refuses_plain_tcp_to_another_host(tmp_path, capsys):
    from sctd_services.learner import main as learner_main

    rc = learner_main(["--store", str(tmp_path), "--scheduler", "tcp://10.213.13.1:8786"])
    assert rc == 2
    assert "sctd learner: --scheduler tcp://10.213.13.1:8786: plain tcp:// is for loopback only" in \
        capsys.readouterr().err


@pytest.mark.slow
def test_the_learners_check_runs_on_the_cluster(loopback):
    """The learner's check (:func:`sctd_services.learner.check.evaluation`) with the
    cluster's executor, as ``sctd learner --scheduler`` makes it: the verdict's figures
    of a check in this process."""
    from sctd.skill.catalog import StoredSkill
    from sctd_services.learner.check import CheckSettings, evaluation

    stored = StoredSkill("0" * 16, "pour", 0.0, Path(SKILL))
    settings = CheckSettings(trials=2, jobs=1)
    with connect(loopback[0]) as pool:
        remote = evaluation(stored, find_task("pour"), settings, 3, pool, stop_early=False)
    local = evaluation(stored, find_task("pour"), settings, 3, None, stop_early=False)
    assert remote["per_trial"] == local["per_trial"]
    assert remote["success_rate"] == local["success_rate"]
