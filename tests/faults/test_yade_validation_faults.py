"""Faults of YADE inside a validation run, as for LIGGGHTS and LAMMPS (test_validation_faults.py): a
fake ``yade`` on PATH (fakes.write_fake_yade) whose output is cut short, whose run lacks a particle,
which fails or which hangs holding a TCP port. Each gives a failing or ``incomplete`` verdict whose
message names the fault, never a pass on what remains, and leaves no process and no port behind.

LIGGGHTS and LAMMPS are taken as absent here (their stored outputs stand in), so only YADE runs live."""

from __future__ import annotations

import shutil
import socket

import pytest
from fakes import YADE_REAL_KINDS, fakes_on_path, write_fake_yade

import validation.runner as vrunner
from validation.cases import taylor
from validation.runner import run_validation

REAL_YADE = shutil.which("yade")


@pytest.fixture
def fake_yade(tmp_path_factory, monkeypatch):
    """``fake = fake_yade(kind)``: the fake first on PATH, LIGGGHTS and LAMMPS absent, the runner's
    SIGTERM-to-SIGKILL grace 0.5 s; at teardown whatever the fake left running is killed."""
    monkeypatch.setattr(vrunner, "liggghts_available", lambda: False)
    monkeypatch.setattr(vrunner, "lammps_available", lambda: False)

    def write(bindir, kind, real):
        return write_fake_yade(bindir, kind, real=real)

    yield from fakes_on_path(
        tmp_path_factory, monkeypatch, write, REAL_YADE, YADE_REAL_KINDS, "yade", "apt-get install yade"
    )


def _quiet(*a, **k):
    pass


def _taylor_yade(tmp_path, monkeypatch, timeout=None):
    """taylor-rve in the quick suite with its YADE column on one RVE (every 25th state): the case and
    its failing YADE records."""
    monkeypatch.setitem(taylor.YADE_SETTINGS, "quick", {"names": ["rve-70-1"], "stride": 25})
    ok, (res,) = run_validation("quick", tmp_path / "results", only=["taylor-rve"], log=_quiet, timeout=timeout)
    bad = [r for r in res.checks if r.pair == "native-yade" and not r.passed]
    return ok, res, bad


def _no_record_judged_on_what_remains(res):
    assert not [r for r in res.checks if r.pair == "native-yade" and r.quantity in ("stress", "tangent")]


def test_a_yade_output_cut_short_is_an_incomplete_verdict(tmp_path, monkeypatch, fake_yade):
    fake_yade("cut")
    ok, res, bad = _taylor_yade(tmp_path, monkeypatch)
    assert not ok and not res.passed and res.cell("native-yade")["state"] == "FAIL"
    assert bad[0].metric == "incomplete: expected 1 RVEs run by YADE, got 0 (missing: rve-70-1)"
    assert any(m.startswith("incomplete: YADE job failed: ") and "cut short" in m for m in (r.metric for r in bad))
    _no_record_judged_on_what_remains(res)


def test_a_yade_script_that_fails_is_a_failing_verdict_quoting_the_error(tmp_path, monkeypatch, fake_yade):
    fake_yade("error")
    ok, res, bad = _taylor_yade(tmp_path, monkeypatch)
    assert not ok and res.cell("native-yade")["state"] == "FAIL"
    failed = [r.metric for r in bad if r.metric.startswith("incomplete: YADE job failed: ")]
    assert failed and failed[0].endswith(
        "yade exited with status 1: RuntimeError: fake failure (the fake yade of kind 'error')"
    ), failed
    _no_record_judged_on_what_remains(res)


def test_a_hung_yade_job_is_killed_at_the_timeout_with_no_process_and_no_port_left(tmp_path, monkeypatch, fake_yade):
    fake = fake_yade("hang")
    ok, res, bad = _taylor_yade(tmp_path, monkeypatch, timeout=5)
    assert not ok and res.cell("native-yade")["state"] == "FAIL"
    assert any("timed out after 5 s" in r.metric for r in bad), [r.metric for r in bad]
    assert fake.pids("grandchild"), "the fake never started its grandchild"
    assert fake.wait_gone(5) == []  # the fake and its grandchild (which ignored SIGTERM)
    port = fake.port()
    assert port is not None
    with pytest.raises(ConnectionRefusedError):  # the port the hung job held is closed
        socket.create_connection(("127.0.0.1", port), timeout=2).close()
    _no_record_judged_on_what_remains(res)


def test_a_particle_missing_from_a_yade_run_stops_the_case_naming_it(tmp_path, fake_yade):
    """biaxial-short's YADE run (the 120-disk case, undamped) with the second particle of its first
    frame deleted: the job is refused as incomplete and the case is not run, saying which particle
    count fell short (a failure in the report, never a pass of the other columns' records alone)."""
    fake_yade("drop-particle")
    ok, (res,) = run_validation("quick", tmp_path / "results", only=["biaxial-short"], log=_quiet)
    assert not ok and not res.passed
    assert res.error is not None and "incomplete: " in res.error, res.error
    assert "frame of step 0 has 119 of 120 particles" in res.error, res.error
