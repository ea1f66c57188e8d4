"""YADE's columns in cases outside biaxial-short and simple-shear (which have their own tests): the
void cells of YADE's run judged against native in YADE's arithmetic on YADE's stored output when
YADE is absent (and failing when that output is cut short), and a case without a YADE run marking
every YADE column it has not declared as not applicable, with its reason."""

from __future__ import annotations

import gzip
import shutil
from pathlib import Path

import pytest

import validation.runner as vrunner
from reference_runs import store
from validation.codes import pairs
from validation.core import CaseResult, compare, in_pair
from validation.runner import run_validation


@pytest.fixture
def stored_copy(tmp_path, monkeypatch):
    dest = tmp_path / "stored"
    dest.mkdir()
    for name in ("biaxial-short", "biaxial-short-lammps", "biaxial-short-yade"):
        shutil.copytree(Path(store.STORED) / name, dest / name)
    monkeypatch.setattr(store, "STORED", dest)
    monkeypatch.setattr(vrunner, "liggghts_available", lambda: False)
    monkeypatch.setattr(vrunner, "lammps_available", lambda: False)
    monkeypatch.setattr(vrunner, "_available", lambda code: False)
    return dest


def _voidcell(tmp_path):
    ok, (res,) = run_validation("quick", tmp_path / "results", only=["voidcell"], log=lambda *a, **k: None)
    return ok, res


def test_voidcell_judges_yades_stored_cells_against_native_yade(stored_copy, tmp_path):
    ok, res = _voidcell(tmp_path)
    assert ok and res.passed, [r for r in res.records if not r.passed]
    assert res.cell("native-yade")["state"] == "pass"
    assert res.cell("liggghts-yade")["state"] == res.cell("lammps-yade")["state"] == "n/a"
    assert "undamped" in res.not_applicable["liggghts-yade"]
    yade = {r.quantity: r for r in res.checks if r.case == "voidcell/yade-120/yade"}
    assert {"cell_list", "alpha", "w", "evidence"} <= set(yade)
    assert "of 6)" in yade["cell_list"].metric and yade["cell_list"].value == 0.0  # 6 frames with cells
    assert all(r.pair == "native-yade" for r in yade.values())


def test_voidcell_fails_on_a_cut_yade_output(stored_copy, tmp_path):
    gz = stored_copy / "biaxial-short-yade" / "dem.out.gz"
    gz.write_bytes(gzip.compress(gzip.decompress(gz.read_bytes())[:-5000]))
    ok, res = _voidcell(tmp_path)
    assert not ok and res.cell("native-yade")["state"] == "FAIL"
    bad = [r.metric for r in res.records if r.pair == "native-yade" and not r.passed]
    assert any(m.startswith("incomplete: stored YADE output: incomplete:") for m in bad), bad
    assert any(m.startswith("incomplete: expected 7 YADE frames, got 0") for m in bad), bad


def test_skip_code_marks_only_the_undeclared_columns_of_the_code():
    res = CaseResult("c", "t", "d")
    res.declare("native-yade", "declared")
    res.records += in_pair([compare("c", "x", "m", 0.0, 0.0, "r")], "native-yade")
    res.skip_code("yade", "no such run")
    assert res.cell("native-yade")["state"] == "pass"
    yade_cols = [p for p in pairs() if "yade" in p.split("-")]
    assert {p: res.not_applicable.get(p) for p in yade_cols} == {
        "native-yade": None,
        "liggghts-yade": "no such run",
        "lammps-yade": "no such run",
    }
    assert "liggghts-lammps" not in res.not_applicable


@pytest.fixture
def taylor_stored(tmp_path, monkeypatch):
    dest = tmp_path / "stored"
    dest.mkdir()
    for p in Path(store.STORED).iterdir():
        if p.name.startswith("taylor-"):
            shutil.copytree(p, dest / p.name)
    monkeypatch.setattr(store, "STORED", dest)
    monkeypatch.setattr(vrunner, "liggghts_available", lambda: False)
    monkeypatch.setattr(vrunner, "lammps_available", lambda: False)
    monkeypatch.setattr(vrunner, "_available", lambda code: False)
    return dest


def _taylor(tmp_path):
    ok, (res,) = run_validation("quick", tmp_path / "results", only=["taylor-rve"], log=lambda *a, **k: None)
    return ok, res


def test_taylor_rve_judges_yades_stored_states(taylor_stored, tmp_path):
    ok, res = _taylor(tmp_path)
    assert ok and res.passed, [r for r in res.records if not r.passed]
    assert res.cell("native-yade")["state"] == "pass"
    yade = [r for r in res.checks if r.pair == "native-yade"]
    labels = {r.case for r in yade}
    for rve in ("70-1", "70-2", "70-3"):
        for path in ("compression11", "compression22", "shear12", "shear21"):
            assert f"taylor-rve/yade/{rve}/{path}" in labels
    tangent = [r for r in yade if r.quantity == "tangent"]
    assert len(tangent) == 12 and all(0.0 < r.value <= r.tolerance == 1e-12 for r in tangent)
    assert "triangle inequality" in res.not_applicable["lammps-yade"]


def test_taylor_rve_fails_on_a_cut_yade_output(taylor_stored, tmp_path):
    gz = taylor_stored / "taylor-rve-yade" / "rve-70-2" / "taylor.out.gz"
    gz.write_bytes(gzip.compress(gzip.decompress(gz.read_bytes())[:-3000]))
    ok, res = _taylor(tmp_path)
    assert not ok and res.cell("native-yade")["state"] == "FAIL"
    bad = [r for r in res.records if r.pair == "native-yade" and not r.passed]
    assert any(r.case == "taylor-rve/yade/70-2" and "is not this job's: output sha256" in r.metric for r in bad), bad
    assert any(r.metric.startswith("incomplete: expected 3 RVEs run by YADE") for r in bad), bad
    assert not any("70-1" in r.case or "70-3" in r.case for r in bad)


@pytest.fixture
def impacts_stored(tmp_path, monkeypatch):
    dest = tmp_path / "stored"
    shutil.copytree(Path(store.STORED), dest)
    monkeypatch.setattr(store, "STORED", dest)
    monkeypatch.setattr(vrunner, "liggghts_available", lambda: False)
    monkeypatch.setattr(vrunner, "lammps_available", lambda: False)
    monkeypatch.setattr(vrunner, "_available", lambda code: False)
    return dest


def _impacts(tmp_path):
    ok, (res,) = run_validation("quick", tmp_path / "results", only=["impacts"], log=lambda *a, **k: None)
    return ok, res


def test_impacts_judge_yades_stored_runs_against_the_closed_forms(impacts_stored, tmp_path):
    ok, res = _impacts(tmp_path)
    assert ok and res.passed, [r for r in res.records if not r.passed]
    assert res.cell("native-yade")["state"] == "pass" and "clipped" in res.not_applicable["liggghts-yade"]
    analytic = [r for r in res.checks if r.case.endswith("/yade") and r.case.count("/") == 3]
    assert {r.quantity for r in analytic} >= {"contact time", "restitution", "peak overlap"}
    assert all(r.pair == "" and r.value <= r.tolerance for r in analytic)
    frames = [r for r in res.checks if r.pair == "native-yade" and r.quantity == "position"]
    assert frames and all(r.value == 0.0 for r in frames)  # undamped linear scenes: YADE's positions to the bit


def test_impacts_fail_on_a_cut_yade_output(impacts_stored, tmp_path):
    gz = impacts_stored / "impacts-yade" / "normal-z0.35" / "impact.out.gz"
    gz.write_bytes(gzip.compress(gzip.decompress(gz.read_bytes())[:-2000]))
    ok, res = _impacts(tmp_path)
    assert not ok and res.cell("native-yade")["state"] == "FAIL"
    bad = [r for r in res.records if not r.passed]
    assert {r.case for r in bad} == {"impacts/normal-z0.35/yade"}, bad
    assert any(r.metric.startswith("incomplete: stored YADE output") for r in bad)
