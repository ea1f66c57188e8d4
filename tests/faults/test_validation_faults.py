"""Faults injected into the validation layer: cut reference evidence and perturbed native paths.

Each fault must end in a failing verdict (an ``incomplete`` evidence record or a failing
comparison) or in a case that did not run with a clear error: never in "pass".
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

import validation.runner as vrunner
from reference_runs import store
from validation.runner import run_validation

STORED = Path(store.STORED)
REPO = Path(__file__).resolve().parents[2]


def _quiet(*_a, **_k):
    pass


@pytest.fixture
def stored_copy(tmp_path, monkeypatch):
    """A copy of reference_runs/stored that the cases read instead (to be damaged by the test);
    LIGGGHTS and LAMMPS are reported absent so only the stored evidence is compared."""
    dest = tmp_path / "stored"
    shutil.copytree(STORED, dest)
    monkeypatch.setattr(store, "STORED", dest)
    monkeypatch.setattr(vrunner, "liggghts_available", lambda: False)
    monkeypatch.setattr(vrunner, "lammps_available", lambda: False)
    return dest


def _result(results, case_id):
    (res,) = [r for r in results if r.case == case_id]
    return res


def _incomplete(res) -> list[str]:
    return [r.metric for r in res.records if r.quantity == "evidence" and not r.passed]


def _cut_log(path: Path, last_step: int) -> None:
    """Keep the log up to the thermo row of ``last_step``; drop the rest (a killed job)."""
    out = []
    for line in path.read_text().splitlines():
        out.append(line)
        f = line.split()
        if f and f[0].isdigit() and int(f[0]) == last_step:
            break
    path.write_text("\n".join(out) + "\n")


def _first_frame_only(path: Path) -> None:
    """Keep only the first ITEM: TIMESTEP block of a dump (a full disk, a changed dump interval)."""
    lines = path.read_text().splitlines()
    starts = [k for k, line in enumerate(lines) if line.startswith("ITEM: TIMESTEP")]
    path.write_text("\n".join(lines[: starts[1]]) + "\n")


def test_stored_log_cut_to_12_steps_fails(stored_copy, tmp_path):
    _cut_log(stored_copy / "biaxial-short" / "log.liggghts", 12)
    ok, results = run_validation("quick", tmp_path / "results", only=["biaxial-short"], log=_quiet)
    res = _result(results, "biaxial-short")
    assert not ok and not res.passed
    assert any("incomplete: expected 3001 LIGGGHTS series steps, got 13" in m for m in _incomplete(res)), _incomplete(
        res
    )


def test_stored_dump_with_only_the_first_frame_fails(stored_copy, tmp_path):
    _first_frame_only(stored_copy / "biaxial-short" / "dump.atoms")
    ok, results = run_validation("quick", tmp_path / "results", only=["biaxial-short", "voidcell"], log=_quiet)
    assert not ok
    for cid in ("biaxial-short", "voidcell"):
        res = _result(results, cid)
        assert not res.passed, cid
        assert any("incomplete: expected 7 LIGGGHTS frames, got 1" in m for m in _incomplete(res)), (
            cid,
            _incomplete(res),
        )
    html = (tmp_path / "results" / "report" / "index.html").read_text()
    assert "incomplete: expected 7 LIGGGHTS frames, got 1" in html


def test_native_path_dropping_half_the_contacts_fails_taylor(stored_copy, tmp_path, monkeypatch):
    """The contact comparison is two-sided: native contacts dropped leave LIGGGHTS rows unmatched."""
    import gransim.rve as rve

    real = rve.contact_state

    def half(packing, F, kn):
        cs = real(packing, F, kn)
        return type(cs)(**{f.name: getattr(cs, f.name)[::2] for f in dataclasses.fields(cs)})

    monkeypatch.setattr(rve, "contact_state", half)
    ok, results = run_validation("quick", tmp_path / "results", only=["taylor-rve"], log=_quiet)
    res = _result(results, "taylor-rve")
    assert not ok and not res.passed
    bad = {r.quantity for r in res.records if not r.passed}
    assert bad == {"contact_count", "contact_unmatched"}, bad
    unmatched = [r for r in res.records if r.quantity == "contact_unmatched" and not r.passed]
    for code, pair in (("LIGGGHTS", "native-liggghts"), ("LAMMPS", "native-lammps")):
        mine = [r for r in unmatched if r.pair == pair]
        assert mine and all(r.metric.startswith(f"{code} contact ends without a partner: disk") for r in mine), code
    assert res.cell("native-lammps")["state"] == "FAIL" and res.cell("liggghts-lammps")["state"] == "pass"


@pytest.mark.parametrize("engine", ["liggghts", "lammps"])
def test_a_stored_taylor_state_missing_fails(stored_copy, tmp_path, engine):
    """states.json and the log cut consistently by one state: the Taylor series is incomplete."""
    import json

    d = stored_copy / store.taylor_case(store.RVE_CASE, engine)
    meta = json.loads((d / "states.json").read_text())
    meta["states"] = meta["states"][:-1]
    (d / "states.json").write_text(json.dumps(meta))
    log = (d / "log.lammps").read_text()
    cut = log.rfind("\nrun 0")  # drop the last state's run
    if cut < 0:
        cut = log.rfind("\nrun ")
    (d / "log.lammps").write_text(log[:cut] + "\n")
    ok, results = run_validation("quick", tmp_path / "results", only=["taylor-rve"], log=_quiet)
    res = _result(results, "taylor-rve")
    assert not res.passed
    if res.error is None:
        code = {"liggghts": "LIGGGHTS", "lammps": "LAMMPS"}[engine]
        assert any(f"incomplete: expected 6 {code} states, got 5" in m for m in _incomplete(res)), _incomplete(res)
    else:
        assert "states" in res.error or "runs" in res.error


# --------------------------------------------------------------------- live LIGGGHTS faults
def _live(res) -> str:
    """What the case says about its live job: the error, or the failing records' metrics."""
    return (res.error or "") + " | " + " | ".join(r.metric for r in res.records if not r.passed)


@pytest.mark.liggghts
def test_live_liggghts_leaving_only_the_first_dump_frame_fails(tmp_path, fake_liggghts):
    """A LIGGGHTS that runs normally but leaves one frame per dump (full disk, killed job)."""
    fake_liggghts("cut-dumps")
    ok, results = run_validation("quick", tmp_path, only=["biaxial-short"], log=_quiet)
    res = _result(results, "biaxial-short")
    assert not ok and not res.passed
    assert "dump.atoms: expected 5 frames, got 1" in _live(
        res
    ) or "incomplete: expected 5 LIGGGHTS frames, got 1" in _live(res), _live(res)


@pytest.mark.liggghts
def test_live_liggghts_with_a_truncated_log_fails(tmp_path, fake_liggghts):
    fake_liggghts("truncate-log")
    ok, results = run_validation("quick", tmp_path, only=["biaxial-short"], log=_quiet)
    res = _result(results, "biaxial-short")
    assert not ok and not res.passed and res.error and "incomplete" in res.error, _live(res)


@pytest.mark.parametrize("kind, words", [("error", "ERROR"), ("silent", "log"), ("warning", "WARNING")])
def test_live_liggghts_failures_fail_the_case(tmp_path, fake_liggghts, kind, words):
    fake_liggghts(kind)
    ok, results = run_validation("quick", tmp_path, only=["biaxial-short"], log=_quiet)
    res = _result(results, "biaxial-short")
    assert not ok and res.error and words in res.error, _live(res)


def test_hung_liggghts_times_out_names_the_job_and_leaves_no_process(tmp_path, fake_liggghts):
    fake = fake_liggghts("hang")
    ok, results = run_validation("quick", tmp_path, only=["biaxial-short"], log=_quiet, timeout=2)
    res = _result(results, "biaxial-short")
    assert not ok and res.error and "timed out after 2 s" in res.error
    assert "live-120" in res.error  # which job
    assert fake.wait_gone(2) == []
    html = (tmp_path / "report" / "index.html").read_text()
    assert "timed out after 2 s" in html


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_to_validate_leaves_no_liggghts(tmp_path, fake_liggghts, sig):
    fake = fake_liggghts("hang")
    env = {**os.environ}
    cmd = [
        sys.executable,
        "-m",
        "gransim",
        "validate",
        "--suite",
        "quick",
        "--case",
        "biaxial-short",
        "--results",
        str(tmp_path / "results"),
    ]
    py = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not fake.pids("grandchild") and time.monotonic() < deadline and py.poll() is None:
            time.sleep(0.1)
        assert fake.pids("grandchild"), py.communicate()[1][-2000:] if py.poll() is not None else "no job"
        py.send_signal(sig)
        _, err = py.communicate(timeout=30)
    finally:
        if py.poll() is None:
            py.kill()
    assert py.returncode != 0
    assert "Traceback" not in err, err[-2000:]
    assert fake.wait_gone(2) == []


def test_second_validate_into_the_same_results_fails_at_once(tmp_path):
    from gransim.cli import main
    from reference_runs.locks import DirectoryLock

    with DirectoryLock(tmp_path):  # another validation run holds the directory
        rc = main(["validate", "--suite", "quick", "--case", "biaxial-short", "--results", str(tmp_path)])
    assert rc == 2
    assert not (tmp_path / "validation.json").exists()


def test_stray_temporaries_of_a_killed_run_are_removed(tmp_path):
    (tmp_path / "report").mkdir()
    stray = [tmp_path / ".validation.json.abc123.json.tmp", tmp_path / "report" / ".index.html.x1y2.html.tmp"]
    for p in stray:
        p.write_text("half")
    run_validation("quick", tmp_path, only=["biaxial-short"], log=_quiet)
    assert not any(p.exists() for p in stray)
