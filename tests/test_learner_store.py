"""The learner's store, its requests and its check's verdict, without processes; and
the store as a place skill names resolve from (sctd.skill.catalog)."""

from __future__ import annotations

import json
import math
import random

import msgpack
import pytest
from hypothesis import given
from hypothesis import strategies as st

from sctd.learn.demos import read_demo_csv
from sctd.skill import SkillError, bundle_from_file, load_skill
from sctd.skill.catalog import find_skill, find_stored, shipped_folder, stored_skills
from sctd.wire import codec
from sctd_services.learner.check import CheckSettings, decided, rule_for, simulate, verdict
from sctd_services.learner.request import RequestError, parse_request
from sctd_services.learner.store import Store
from tests.conftest import ROOT

DEMO = ROOT / "skills" / "demos" / "pour" / "demo_00.csv"


def _msg(name: str = "demo_000", task: str = "pour", shift: float = 0.0) -> codec.DemoMsg:
    d = read_demo_csv(DEMO)
    rows = [[float(t), *map(float, p)] for t, p in zip(d.t, d.poses, strict=True)]
    rows[0][1] += shift
    return codec.DemoMsg(task, name, "mug", rows)


def test_a_stored_demonstration_reads_back_as_sent(tmp_path):
    store = Store(tmp_path)
    msg = _msg()
    s = store.add_demo(msg, key="sctd/edan/demos/pour/demo_000")
    assert not s.duplicate and s.path == tmp_path / "demos" / "pour" / "demo_000.csv"
    [d] = store.load_demos("pour")
    assert d.poses[:, 0].tolist() == pytest.approx([r[1] for r in msg.rows], abs=1e-9)
    assert store.tasks() == {"pour": 1} and store.demo_object("pour", "demo_000") == "mug"


def test_same_name_same_rows_is_one_demonstration_other_rows_are_kept_too(tmp_path):
    store = Store(tmp_path)
    store.add_demo(_msg())
    assert store.add_demo(_msg()).duplicate
    other = store.add_demo(_msg(shift=0.01))
    assert not other.duplicate and other.name.startswith("demo_000-")
    assert store.demo_names("pour") == ["demo_000", other.name]


def test_unknown_demonstrations_are_named(tmp_path):
    store = Store(tmp_path)
    store.add_demo(_msg())
    with pytest.raises(KeyError, match="demo_007"):
        store.load_demos("pour", ["demo_000", "demo_007"])
    with pytest.raises(KeyError, match="no demonstrations of task 'drawer'"):
        store.load_demos("drawer")


def test_a_killed_learners_leftovers_are_removed_and_ignored(tmp_path):
    store = Store(tmp_path)
    stored = store.add_skill(bundle_from_file(ROOT / "skills" / "pour.yaml"), {"task": "pour"})
    half = tmp_path / "skills" / ".new-abc"
    half.mkdir()
    (half / "x.yaml").write_text("half")
    (tmp_path / "demos" / "pour").mkdir()
    (tmp_path / "demos" / "pour" / ".demo_001.csv.1234.tmp").write_text("t,x")
    broken = tmp_path / "skills" / "0123456789abcdef"  # a folder without its record
    broken.mkdir()
    assert [s.id for s in stored_skills(tmp_path)] == [stored.id]
    again = Store(tmp_path)
    assert again.cleaned == 2 and not half.exists()
    assert [s.id for s in again.skills()] == [stored.id]


@pytest.fixture
def store(private_store):
    """The test run's store (``$SCTD_STORE``), emptied after the test."""
    yield Store(private_store)
    for sub in ("skills", "demos"):
        for p in sorted((private_store / sub).rglob("*"), reverse=True):
            p.rmdir() if p.is_dir() else p.unlink()


def _stored_copy(store: Store, src: str, name: str, created: float):
    b = bundle_from_file(ROOT / "skills" / src)
    b = type(b)(name=f"{name}.yaml", yaml_text=b.yaml_text, files=b.files)
    return store.add_skill(b, {"created": created, "task": "pour"})


def test_names_resolve_path_then_store_then_shipped(store):
    old = _stored_copy(store, "pour.yaml", "pour", created=1.0)
    new = _stored_copy(store, "pour-linear.yaml", "pour", created=2.0)
    assert find_skill("pour") == new.path  # the newest of the name, before the shipped one
    assert find_skill(f"pour@{old.id}") == old.path
    assert find_skill(old.id[:6]) == old.path  # an id prefix
    assert find_skill(ROOT / "skills/pour.yaml") == ROOT / "skills/pour.yaml"  # a path wins
    assert find_skill("drawer") == shipped_folder() / "drawer.yaml"
    assert load_skill(find_skill(new.ref)).id == new.id  # the content id is the skill's id
    with pytest.raises(SkillError, match="learner's store"):
        find_skill("pour@ffffffff")


def test_an_ambiguous_id_prefix_is_refused(store):
    text = (ROOT / "skills" / "pour.yaml").read_text()
    for sid in ("abcd1111aaaaaaaa", "abcd2222bbbbbbbb"):  # two entries, ids sharing "abcd"
        folder = store.skills_dir / sid
        folder.mkdir()
        (folder / "p.yaml").write_text(text)
        (folder / "record.json").write_text(json.dumps({"id": sid, "name": "p", "created": 1.0}))
    with pytest.raises(SkillError, match="ambiguous id prefix: p@abcd1111aaaaaaaa, p@abcd2222bbbbbbbb"):
        find_stored("abcd")
    assert find_stored("abcd2").id == "abcd2222bbbbbbbb"
    assert find_stored("abc") is None  # shorter than 4 characters: no prefix match


def test_the_record_is_what_the_catalog_reads(store):
    s = _stored_copy(store, "pour.yaml", "mine", created=5.0)
    rec = store.record(s.id)
    rec.update({"evaluation": {"pour": {"success_rate": 1.0}}})
    assert "evaluation" not in find_stored("mine").record  # changed in memory only
    rec.save()
    on_disk = json.loads((s.path.parent / "record.json").read_text())
    assert on_disk == rec.data and on_disk["id"] == s.id and on_disk["name"] == "mine"
    assert find_stored("mine").record["evaluation"]["pour"]["success_rate"] == 1.0
    assert [p.name for p in s.path.parent.iterdir() if p.name.startswith(".")] == []  # no leftovers


# --- requests -------------------------------------------------------------------------

def _req(**fields):
    return msgpack.packb(fields)


def test_a_request_names_the_vector_field_models_as_a_list_or_as_the_flag_does():
    """``vf-models``, the one list-valued hyperparameter: a list of names, or sctd learn's
    comma-separated form; anything else refused naming the field."""
    models = ("translation", "cylinder", "sphere", "point", "general")
    for names in (list(models), ",".join(models), " , ".join(models)):
        assert parse_request(_req(task="pour", method="vf", params={"vf-models": names})).params == {
            "models": models}
    for bad, why in (("nope", "a non-empty list of translation"), ([1], "a list of at most 16 names"),
                     (["point"] * 17, "a list of at most 16 names"), ("", "a list of at most 16 names"),
                     ({"a": 1}, "a list of at most 16 names")):
        with pytest.raises(RequestError, match=f"params.vf-models: expected {why}"):
            parse_request(_req(task="pour", method="vf", params={"vf-models": bad}))


def test_a_request_reads_learns_flags_by_their_names():
    r = parse_request(_req(task="pour", method="vf", params={"vf-combine": "weighted", "seed": 3,
                                                           "vf_max_n": 40, "despike": False}))
    assert r.params == {"vf_combine": "weighted", "random_state": 3, "vf_max_n": 40, "despike": False}
    assert r.gate and r.swap and r.demos is None and r.skill_name == "pour-vf-learned"
    lin = parse_request(_req(task="pour", method="linear", frames=["tip=0,0,0.12,0,0,0,1"]))
    assert lin.frames == {"tip": [0.0, 0.0, 0.12, 0.0, 0.0, 0.0, 1.0]}


@pytest.mark.parametrize("fields, where", [
    ({"method": "vf"}, "task"),
    ({"task": "pour"}, "method"),
    ({"task": "pour", "method": "svm"}, "method"),
    ({"task": "a/b", "method": "vf"}, "task"),
    ({"task": "pour", "method": "vf", "colour": 1}, "colour"),
    ({"task": "pour", "method": "vf", "params": {"no-despike": True}}, "params.no-despike"),
    ({"task": "pour", "method": "vf", "params": {"smoothness": [1]}}, "params.smoothness"),
    ({"task": "pour", "method": "vf", "frames": ["tip=0,0,0.12,0,0,0,1"]}, "frames"),
    ({"task": "pour", "method": "linear", "frames": ["tip=0,0,0.12,0,0,0,2"]}, "frames"),
    ({"task": "pour", "method": "vf", "demos": []}, "demos"),
    ({"task": "pour", "method": "vf", "gate": "yes"}, "gate"),
    ({"task": "pour", "method": "vf", "seed": -1}, "seed"),
    ({"task": "pour", "method": "vf", "member": 3}, "member"),
    ({"task": "pour", "method": "vf", "member": ""}, "member"),
    ({"task": "pour", "method": "vf", "member": "a=b"}, "member"),
    ({"task": "pour", "method": "vf", "member": "tab\there"}, "member"),
])
def test_a_malformed_request_is_named_by_its_field(fields, where):
    with pytest.raises(RequestError, match=f"^{where}: "):
        parse_request(_req(**fields))


def test_a_request_that_is_not_a_map_is_refused():
    with pytest.raises(RequestError, match="<request>"):
        parse_request(b"\xc1")


# --- the verdict ----------------------------------------------------------------------

def _ev(k: int, n: int = 10) -> dict:
    return {"successes": k, "trials": n, "success_rate": k / n}


def test_the_check_passes_at_the_floor_and_within_the_tolerance_of_the_active_skill():
    s = CheckSettings(trials=20, floor=0.9, tolerance=0.1)
    ok, why = verdict(_ev(6, 6), "pour", s, None)
    assert ok and "6/6 trials succeeded: accepted by the sequential test (success rate >= 0.95 " \
                  "against <= 0.80, at most 20 trials; the floor 0.90)" in why
    assert not verdict(_ev(5, 5), "pour", s, None)[0]  # undecided: too few
    kernels = {"blas": ["openblas 0.3.31 Haswell"], "machine": "x86_64", "numpy": "2.4.6",
               "openblas_coretype": "Haswell"}
    on = {**_ev(6, 6), "numerics": kernels}
    assert verdict(on, "pour", s, None)[1].endswith(
        "; numerics: openblas 0.3.31 Haswell (x86_64, numpy 2.4.6, OPENBLAS_CORETYPE=Haswell)")
    assert not verdict(_ev(0, 2), "pour", s, None)[0]
    assert verdict(_ev(6, 6), "pour", s, _ev(10))[0]  # raised to 1.0 - 0.1: the same test
    ok, why = verdict(_ev(9, 10), "pour", CheckSettings(floor=0.5, tolerance=0.05), _ev(10))
    assert not ok and "the active skill's 1.00 minus the tolerance 0.05" in why
    ok, why = verdict(None, "crank", s, None)
    assert not ok and "no lockstep evaluation for task 'crank'" in why


def test_the_sequential_test_has_the_operating_points_it_promises():
    """Known answers (exact, by dynamic programming over the truncated test) at the
    default floor: accepts a skill of 80 % with probability 0.354 (<= 0.38, as a fixed rule
    of at most one failure in ten trials: 0.376) and rejects one of 95 % with 0.065 (<=
    0.09; that rule: 0.086); a perfect skill after 6 trials."""
    rule = rule_for(CheckSettings(), None)
    assert (rule.low, rule.high, rule.max_trials) == (0.8, 0.95, 20)
    acc80, _ = rule.operating_point(0.8)
    acc95, n95 = rule.operating_point(0.95)
    acc100, n100 = rule.operating_point(1.0)
    assert round(acc80, 3) == 0.354 and round(1 - acc95, 3) == 0.065 and round(n95, 2) == 8.35
    assert acc100 == 1.0 and n100 == 6.0
    assert rule.decide(6, 0) is True and rule.decide(5, 0) is None and rule.decide(0, 2) is False


def test_ten_thousand_simulated_sequences_agree_with_the_exact_operating_points():
    """The test run on 10,000 random outcome sequences per success rate (seeded): the
    share accepted and the trials run are within 4 standard errors of the exact figures,
    and within the bounds at 0.8 and 0.95."""
    rng = random.Random(7)
    rule = rule_for(CheckSettings(), None)
    for p in (0.8, 0.9, 0.95):
        accepted, trials = simulate(rule, p, 10_000, rng)
        exact, n = rule.operating_point(p)
        assert abs(accepted - exact) < 4 * math.sqrt(exact * (1 - exact) / 10_000)
        assert abs(trials - n) < 0.15
    assert simulate(rule, 0.8, 10_000, rng)[0] <= 0.38 + 4 * math.sqrt(0.38 * 0.62 / 10_000)
    assert 1 - simulate(rule, 0.95, 10_000, rng)[0] <= 0.09 + 4 * math.sqrt(0.09 * 0.91 / 10_000)


@given(st.lists(st.booleans(), min_size=1, max_size=25), st.sampled_from([0.5, 0.8, 0.9, 0.95]),
       st.sampled_from([0.0, 0.1]), st.one_of(st.none(), st.integers(0, 10)))
def test_the_check_stops_where_the_test_decides_and_the_verdict_is_that_decision(
        outcomes, floor, tolerance, active_ok):
    """Run trial by trial, the check stops at the first prefix the test decides (at the
    latest at ``trials``), and the verdict on what ran is that decision."""
    s = CheckSettings(trials=len(outcomes), floor=floor, tolerance=tolerance)
    active = None if active_ok is None else _ev(active_ok)
    runs = [{"outcome": "success" if ok else "failure"} for ok in outcomes]
    k = next(k for k in range(1, len(runs) + 1) if decided(runs[:k], s, active) is not None)
    d = decided(runs[:k], s, active)
    assert verdict(_ev(sum(outcomes[:k]), k), "pour", s, active)[0] is d
    if all(outcomes[:k]):
        assert d  # successes alone never reject
    if not any(outcomes[:k]):
        assert not d


def test_check_settings_are_bounded():
    for bad in ({"trials": 0}, {"floor": 1.5}, {"tolerance": -0.1}, {"jobs": 0}):
        with pytest.raises(ValueError):
            CheckSettings(**bad)


# --- skipping the check is the operator's decision --------------------------------------

def test_a_request_cannot_skip_the_check_unless_the_operator_allows_it(store):
    """gate: false is refused by a learner started without --allow-unchecked; where it is
    allowed, the skill is 'not checked' in the reply and the record, never 'passed'."""
    from sctd_services.learner.request import Request
    from sctd_services.learner.service import Learner

    req = Request(task="pour", method="vf", gate=False)
    with pytest.raises(RequestError, match="gate: false: this learner checks every skill"):
        Learner(None, store, settings=CheckSettings()).handle(req)  # type: ignore[arg-type]
    s = _stored_copy(store, "pour.yaml", "unchecked", created=1.0)
    learner = Learner(None, store, settings=CheckSettings(allow_unchecked=True))  # type: ignore[arg-type]
    record = store.record(s.id)
    ev, passed, reason = learner._check(req, s, record)
    assert ev is None and passed is None and reason.startswith("not checked")
    assert record.data["check"] == {"passed": None, "checked": False, "reason": reason}
    swapped, why, _ = learner._swap(s, Request(task="pour", method="vf", gate=False, swap=False), passed,
                                    reason, record)
    assert not swapped and "not checked" in why


@pytest.mark.parametrize("swap", [False, True])
def test_a_request_writes_the_record_before_a_swap_and_once_at_the_end(store, monkeypatch, swap):
    """record.json is written when the skill is stored, before the daemon is asked to run
    it (a learner that dies waiting for the reply leaves its check on disk), and once at
    the end (the swap and the timings): never half-written."""
    from sctd_services.learner import service
    from sctd_services.learner import store as store_module
    from sctd_services.learner.request import Request
    from sctd_services.learner.service import Learner

    s = _stored_copy(store, "pour.yaml", "taught", created=1.0)
    record_path = s.path.parent / "record.json"
    learner = Learner(None, store, settings=CheckSettings(allow_unchecked=True))  # type: ignore[arg-type]
    monkeypatch.setattr(learner, "say", lambda *args, **fields: None)
    monkeypatch.setattr(learner, "_train", lambda req: (s, load_skill(s.path), {"method": "vf"}))
    monkeypatch.setattr(learner, "daemon_summary", lambda: None)
    writes: list[dict] = []
    write_atomic = store_module._write_atomic

    def counted(path, data):
        if path == record_path:
            writes.append(json.loads(data))
        write_atomic(path, data)

    monkeypatch.setattr(store_module, "_write_atomic", counted)
    asked: list[dict] = []

    def daemon_swap(session, keys, bundle, timeout, member=None):
        asked.append(json.loads(record_path.read_text()))  # what a learner killed now leaves
        return True, {"ok": True, "id": s.id}

    monkeypatch.setattr(service.client, "swap", daemon_swap)
    out = learner.handle(Request(task="pour", method="vf", gate=False, swap=swap))
    assert out.swapped is swap and out.passed is None
    if swap:
        assert len(writes) == 2 and asked == writes[:1]
        assert asked[0]["check"] == {"passed": None, "checked": False,
                                     "reason": "not checked (gate: false, allowed by the learner's operator)"}
        assert "timings" not in writes[0] and "swaps" not in writes[0]
    else:
        assert len(writes) == 1 and not asked
    final = json.loads(record_path.read_text())
    assert final == writes[-1] and final["timings"] == out.timings
    assert final["check"]["checked"] is False and ("swaps" in final) is swap


@pytest.mark.parametrize("bad", [".", "..", ".h", "a\x00b", "a/b", "x" * 65, "", "a b", "sub\\dir"])
def test_names_that_are_paths_are_refused_everywhere(store, bad):
    """A demonstration named '..' wrote into the store's root; a task '..' trained on its
    files; a NUL name ended in a traceback. Names are names: in the message, the request
    and so the store."""
    msg = _msg()
    for field in ("name", "task", "object"):
        data = codec.encode_demo(*(bad if f == field else getattr(msg, f if f != "object" else "object")
                                   for f in ("task", "name", "object")), msg.rows)
        with pytest.raises(codec.DecodeError) as e:
            codec.decode_demo(data)
        assert e.value.reason == f"bad_{field}"
    for field, value in (("task", bad), ("demos", [bad]), ("name", bad), ("object", bad)):
        fields = {"task": "pour", "method": "vf", field: value}
        with pytest.raises(RequestError, match=f"^{field}: "):
            parse_request(_req(**fields))
    assert not list(store.root.glob("**/*.csv"))


def test_a_demonstration_has_at_most_max_rows_and_a_task_at_most_its_quota(tmp_path, monkeypatch):
    """One legal 15.6 MB message of 1.2 million rows became a 118 MB CSV and a 1.1 GB
    learner; 1,200 demonstrations under distinct names were all stored."""
    from sctd_services.learner import store as store_module

    rows = [[float(k), 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0] for k in range(codec.MAX_DEMO_ROWS + 1)]
    data = codec.encode_demo("pour", "long", "mug", rows)
    with pytest.raises(codec.DecodeError, match=f"more than {codec.MAX_DEMO_ROWS} rows") as e:
        codec.decode_demo(data)
    assert e.value.reason == "bad_rows"
    s = Store(tmp_path / "store")
    monkeypatch.setattr(store_module, "MAX_DEMOS_PER_TASK", 3)
    for k in range(3):
        s.add_demo(_msg(f"d{k}", shift=0.001 * k))
    with pytest.raises(store_module.StoreFull, match="holds 3 demonstrations, the most a task may hold"):
        s.add_demo(_msg("d3", shift=0.01))
    assert s.add_demo(_msg("d0")).duplicate  # a duplicate needs no room
    s.add_demo(_msg("d0", task="drawer"))  # other tasks have their own
    monkeypatch.setattr(store_module, "MAX_DEMOS_PER_TASK", 1000)
    monkeypatch.setattr(store_module, "MAX_TASK_BYTES", 3 * (s.demos_dir / "pour" / "d0.csv").stat().st_size)
    with pytest.raises(store_module.StoreFull, match="bytes of demonstrations"):
        s.add_demo(_msg("d9", shift=0.02))


@pytest.mark.parametrize("method, name, value", [
    ("vf", "vf_spacing", -1), ("vf", "vf_spacing", 0), ("vf", "vf_spacing", 1e-7),
    ("vf", "n_fields", 10**7), ("linear", "max_n", 10**9), ("vf", "min_inliers", -1),
    ("linear", "radius", 0), ("vf", "em_iterations", 10**9), ("vf", "smooth", 10**9),
    ("vf", "n_fields", True), ("linear", "alpha", "abc"), ("vf", "selection", "best"),
    ("vf", "seed", -1), ("linear", "lambda", -0.5),
])
def test_hyperparameters_out_of_range_are_refused_naming_the_field(method, name, value):
    """The audit trained and stored vf_spacing -1, n_fields 1e7, max_n 1e9, min_inliers
    -1 and radius 0; em_iterations 1e9 never replied and smooth 1e9 grew the learner to
    4 GB; 'abc' failed with a message naming no field, and n_fields: true trained."""
    with pytest.raises(RequestError, match=f"^params.{name}: "):
        parse_request(_req(task="pour", method=method, params={name: value}))


def test_every_hyperparameter_declares_its_values_and_its_default_is_one_of_them():
    import dataclasses

    from sctd.learn import HyperparameterError, learn
    from sctd.learn.params import param_problem
    from sctd.learn.pipeline import _PARTS

    for method, parts in _PARTS.items():
        for part in parts:
            for f in dataclasses.fields(part):
                if f.init:
                    default = f.default_factory() if f.default is dataclasses.MISSING else f.default
                    assert param_problem(f, default) == "", (method, part.__name__, f.name)
    with pytest.raises(HyperparameterError, match=r"^em_iterations: ") as e:
        learn([], "vf", em_iterations=10**9)  # refused before any work (no demonstrations needed)
    assert e.value.name == "em_iterations"
