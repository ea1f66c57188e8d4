"""Background reference jobs: ``biaxial-full`` starts its long code runs at the beginning of a
validation run (validation.runner, ``Case.prefetch``) and collects them when its turn comes.

The jobs themselves are the real case's (checked by the default suite); here the scheduling is
checked with stand-ins for the code runs and the native runs: every job runs exactly once, a job
already running is collected (not run twice), a job not yet started moves to the case's own pool,
nothing starts early with one job allowed, and what a run leaves uncollected is cancelled.
"""

from __future__ import annotations

import threading
import time
from types import SimpleNamespace

import pytest

from validation import core, runner
from validation.cases import biaxial
from validation.core import CaseResult, Context


def _ctx(tmp_path, jobs=2):
    return Context(suite="default", results=tmp_path, jobs=jobs, liggghts=True, lammps=True)


@pytest.fixture
def fake_full(monkeypatch):
    """_full_setup, run_reference_job and run_native replaced by stand-ins that record calls."""
    calls = []
    lock = threading.Lock()
    release = threading.Event()

    class _Pk:
        n = 3

    def setup(ctx):
        jobs = {
            (e, lab): {"label": lab, "job_dir": ctx.results / e / lab}
            for e in ("liggghts", "lammps")
            for lab in ("reference", "perturbed", "p2")
        }
        return {
            "packing": _Pk(),
            "settings": SimpleNamespace(dt=1.0, to_dict=dict),
            "loading": None,
            "nsteps": 10,
            "velocities": None,
            "spins": None,
            "jobs": jobs,
            "np2": False,
            "job_common": {},
        }

    def job(engine, label, job_dir):
        with lock:
            calls.append((engine, label, threading.current_thread().name))
        release.wait(10)
        tr = SimpleNamespace(name=f"{engine}-{label}", steps=None, stress=None, lengths=None, frames=None)
        return (tr, {"manifest": label})

    monkeypatch.setattr(biaxial, "_full_setup", setup)
    monkeypatch.setattr(biaxial, "run_reference_job", job)
    monkeypatch.setattr(biaxial, "run_native", lambda *a, **k: "native")
    monkeypatch.setattr(biaxial, "_flavour", lambda settings, engine: settings)
    monkeypatch.setattr(biaxial, "trajectory_to_run_file", lambda *a, **k: "run.h5")
    monkeypatch.setattr(biaxial, "ensemble_labels", lambda n, np2: ["perturbed", "p2"])
    monkeypatch.setattr(biaxial, "lammps_ensemble_labels", lambda n, suite: ["perturbed", "p2"])
    monkeypatch.setattr(biaxial, "_FULL_CACHE", {})
    monkeypatch.setattr(biaxial, "_FULL_PENDING", {})
    return calls, release


def test_prefetched_jobs_are_collected_once_and_the_rest_moved(tmp_path, fake_full):
    calls, release = fake_full
    ctx = _ctx(tmp_path, jobs=2)
    biaxial.prefetch_full(ctx)
    time.sleep(0.2)
    # one background worker (jobs - 1): exactly one job running, five waiting
    assert len(calls) == 1 and calls[0][2].startswith("biaxial-full-prefetch")
    release.set()
    r = biaxial.full_runs(ctx)
    ran = sorted((e, lab) for e, lab, _ in calls)
    assert ran == sorted(
        biaxial_jobs := [(e, lab) for e in ("liggghts", "lammps") for lab in ("reference", "perturbed", "p2")]
    )
    assert len(ran) == len(set(ran)) == len(biaxial_jobs), "a job ran twice or not at all"
    assert r["liggghts"].name == "liggghts-reference" and r["lammps"]["reference"].name == "lammps-reference"
    assert set(r["ensemble"]) == {"perturbed", "p2"}
    assert not biaxial._FULL_PENDING


def test_nothing_starts_early_with_one_job(tmp_path, fake_full):
    calls, release = fake_full
    release.set()
    biaxial.prefetch_full(_ctx(tmp_path, jobs=1))
    assert not biaxial._FULL_PENDING and not calls


def test_cancel_stops_the_jobs_not_yet_started(tmp_path, fake_full):
    calls, release = fake_full
    biaxial.prefetch_full(_ctx(tmp_path, jobs=2))
    time.sleep(0.2)
    t = threading.Timer(0.3, release.set)
    t.start()
    biaxial.cancel_prefetch()
    assert len(calls) == 1, "jobs not yet started must not run after a cancel"
    assert not biaxial._FULL_PENDING


def test_runner_prefetches_first_and_cancels_what_a_failing_case_left(tmp_path, monkeypatch):
    order = []

    def pre(ctx):
        order.append("prefetch")

    def cancel():
        order.append("cancel")

    def first(ctx):
        order.append("first")
        return CaseResult("a", "A", "")

    def second(ctx):
        order.append("second")
        raise RuntimeError("the case broke")

    def bad_prefetch(ctx):
        raise OSError("no room")

    cases = [
        core.Case("a", "A", ("default",), first, 1),
        core.Case("b", "B", ("default",), second, 2, pre, cancel),
        core.Case("c", "C", ("default",), first, 3, bad_prefetch, None),
    ]
    monkeypatch.setattr(runner, "registered_cases", lambda suite: cases)
    logs = []
    ok, out = runner._run_cases(_ctx(tmp_path), "default", None, logs.append, None)
    assert order == ["prefetch", "first", "second", "first", "cancel"]
    assert not ok and out[1].error.startswith("RuntimeError")
    assert any("could not start its jobs early (OSError: no room)" in m for m in logs)
    assert any("Wall time of this case" in n and "at the start of the run" in n for n in out[1].notes)


def test_native_runs_made_in_the_background_are_collected_not_rerun(tmp_path, fake_full, monkeypatch):
    calls, release = fake_full
    natives = []
    monkeypatch.setattr(biaxial, "run_native", lambda *a, **k: natives.append(threading.current_thread().name) or "n")
    release.set()
    ctx = _ctx(tmp_path, jobs=2)
    biaxial.prefetch_full(ctx)
    _, futures, _ = biaxial._FULL_PENDING[biaxial._full_key(ctx)]
    for f in futures.values():  # every job and both native runs done in the background
        f.result(timeout=10)
    r = biaxial.full_runs(ctx)
    assert len(natives) == 2 and all(n.startswith("biaxial-full-prefetch") for n in natives)
    assert r["native"] == "n" and r["lammps"]["native"] == "n"


def test_native_runs_not_started_run_in_the_case_side_by_side(tmp_path, fake_full, monkeypatch):
    _, release = fake_full
    natives = []
    monkeypatch.setattr(biaxial, "run_native", lambda *a, **k: natives.append(threading.current_thread().name) or "n")
    ctx = _ctx(tmp_path, jobs=2)
    biaxial.prefetch_full(ctx)  # the one worker waits in the first job: the native runs never start there
    threading.Timer(0.3, release.set).start()
    r = biaxial.full_runs(ctx)
    assert len(natives) == 2 and len(set(natives)) == 2, "each native run once, in two threads"
    assert not any(n.startswith("biaxial-full-prefetch") for n in natives)
    assert r["native"] == "n" and r["lammps"]["native"] == "n"


@pytest.fixture
def fake_long(monkeypatch):
    """simple-shear's long horizon with stand-ins for its LAMMPS jobs and its native run."""
    from validation.cases import shear

    calls = []
    release = threading.Event()

    def plan(ctx):
        jobs = {lab: {"label": lab} for lab in ("reference", "perturbed")}
        return {"packing": None}, jobs, {}

    def job(label):
        calls.append((label, threading.current_thread().name))
        release.wait(10)
        return (f"lammps-{label}", {"manifest": label})

    def native(s):
        calls.append(("native", threading.current_thread().name))
        return "native"

    monkeypatch.setattr(shear, "_long_plan", plan)
    monkeypatch.setattr(shear, "run_shear_job", job)
    monkeypatch.setattr(shear, "_long_native", native)
    monkeypatch.setattr(shear, "_LONG_CACHE", {})
    monkeypatch.setattr(shear, "_LONG_PENDING", {})
    return shear, calls, release


def test_long_horizon_queues_behind_the_shared_pool_and_is_collected_once(tmp_path, fake_long):
    from concurrent.futures import ThreadPoolExecutor

    shear, calls, release = fake_long
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="validate-background") as bg:
        ctx = Context(suite="default", results=tmp_path, jobs=2, lammps=True, background=bg)
        shear.prefetch_long(ctx)
        time.sleep(0.2)
        assert [c[0] for c in calls] == ["reference"], "one worker: the first job runs, the rest wait"
        threading.Timer(0.3, release.set).start()
        r = shear.long_runs(ctx)
    ran = sorted(c[0] for c in calls)
    assert ran == ["native", "perturbed", "reference"], "each run exactly once"
    assert r["native"] == "native" and r["reference"] == "lammps-reference" and set(r["ensemble"]) == {"perturbed"}
    assert not shear._LONG_PENDING


def test_long_horizon_queues_nothing_without_a_shared_pool(tmp_path, fake_long):
    shear, calls, release = fake_long
    release.set()
    shear.prefetch_long(_ctx(tmp_path, jobs=2))
    assert not shear._LONG_PENDING and not calls


def test_runner_shares_one_background_pool_and_shuts_it_down(tmp_path, monkeypatch):
    seen = []

    def pre(ctx):
        seen.append(ctx.background)

    def first(ctx):
        return CaseResult("a", "A", "")

    cases = [core.Case("a", "A", ("default",), first, 1, pre, None), core.Case("b", "B", ("default",), first, 2, pre)]
    monkeypatch.setattr(runner, "registered_cases", lambda suite: cases)
    runner._run_cases(_ctx(tmp_path), "default", None, lambda m: None, None)
    assert len(seen) == 2 and seen[0] is seen[1] and seen[0] is not None
    with pytest.raises(RuntimeError):  # shut down at the end of the run
        seen[0].submit(print)
    seen.clear()
    runner._run_cases(_ctx(tmp_path, jobs=1), "default", None, lambda m: None, None)
    assert seen == [None, None], "one job at a time: no background pool"


def test_cases_with_background_work_and_their_readers_run_last_and_report_in_the_suites_order(tmp_path, monkeypatch):
    """The short cases run while the background pool makes the long runs (a short case after them
    would run alone at the end); a case reading a prefetching case's runs (``uses``) waits with it.
    The report keeps the suite's order. Without a background pool (one job) the suite's order."""
    ran = []

    def make(case_id):
        def func(ctx):
            ran.append(case_id)
            return CaseResult(case_id, case_id, "")

        return func

    def pre(ctx):
        pass

    ids = ["packings", "full", "reader", "reader-of-reader", "slope"]
    cases = [
        core.Case("packings", "P", ("default",), make("packings"), 5),
        core.Case("full", "F", ("default",), make("full"), 30, pre, None),
        core.Case("reader", "R", ("default",), make("reader"), 40, uses=("full",)),
        core.Case("reader-of-reader", "RR", ("default",), make("reader-of-reader"), 45, uses=("reader",)),
        core.Case("slope", "S", ("default",), make("slope"), 50),
    ]
    assert [c.id for c in runner.execution_order(cases)] == ["packings", "slope", "full", "reader", "reader-of-reader"]
    monkeypatch.setattr(runner, "registered_cases", lambda suite: cases)
    _, out = runner._run_cases(_ctx(tmp_path), "default", None, lambda m: None, None)
    assert ran == ["packings", "slope", "full", "reader", "reader-of-reader"]
    assert [r.case for r in out] == ids
    ran.clear()
    _, out = runner._run_cases(_ctx(tmp_path, jobs=1), "default", None, lambda m: None, None)
    assert ran == ids and [r.case for r in out] == ids


def test_voidcell_reads_biaxial_fulls_runs_and_says_so():
    """voidcell compares biaxial-full's snapshots (validation.cases.voidcell: full_runs), so it is
    made after biaxial-full, whose runs start in the background."""
    from validation.core import registered_cases

    by_id = {c.id: c for c in registered_cases("default")}
    assert by_id["voidcell"].uses == ("biaxial-full",) and by_id["biaxial-full"].prefetch is not None
    order = [c.id for c in runner.execution_order(registered_cases("default"))]
    assert order.index("voidcell") > order.index("biaxial-full")
    assert order[-3:] == ["biaxial-full", "simple-shear", "voidcell"]
