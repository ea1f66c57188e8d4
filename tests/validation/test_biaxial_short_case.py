"""biaxial-short as a declaration (validation.cases.biaxial.short_plan): on the stored runs (codes
reported absent) it fills its three columns and passes; a LAMMPS log cut short fails both LAMMPS
columns as incomplete (native vs LAMMPS, LIGGGHTS vs LAMMPS) and leaves native vs LIGGGHTS passing;
the raw LIGGGHTS-LAMMPS difference is shown with the words that explain it."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import validation.runner as vrunner
from reference_runs import store
from validation.runner import run_validation

CASE = "biaxial-short"


def _quiet(*_a, **_k):
    pass


@pytest.fixture
def stored_copy(tmp_path, monkeypatch):
    dest = tmp_path / "stored"
    dest.mkdir()
    for name in ("biaxial-short", "biaxial-short-lammps"):
        shutil.copytree(Path(store.STORED) / name, dest / name)
    monkeypatch.setattr(store, "STORED", dest)
    monkeypatch.setattr(vrunner, "liggghts_available", lambda: False)
    monkeypatch.setattr(vrunner, "lammps_available", lambda: False)
    return dest


def _run(tmp_path):
    ok, results = run_validation("quick", tmp_path / "results", only=[CASE], log=_quiet)
    (res,) = results
    return ok, res


def test_stored_runs_fill_the_three_columns(stored_copy, tmp_path):
    ok, res = _run(tmp_path)
    assert ok and res.passed, [r for r in res.records if not r.passed]
    assert {p: res.cell(p)["state"] for p in res.matrix} == {
        "native-liggghts": "pass",
        "native-lammps": "pass",
        "liggghts-lammps": "pass",
    }
    raw = [r for r in res.records if r.kind == "info" and r.pair == "liggghts-lammps"]
    assert {r.quantity for r in raw} == {"stress", "position"}
    assert all(r.value > 1e-3 for r in raw)  # the codes differ beyond round-off ...
    assert all("lever arm" in r.reason and "pair_gran_hooke_history.cpp" in r.reason for r in raw)  # ... and why
    assert any("Why LIGGGHTS and LAMMPS differ" in n for n in res.notes)
    assert sum("is absent" in n for n in res.notes) == 2  # each code's live run, not made
    runs = {r[0]: r for r in res.runs}
    assert runs["stored-120/lammps"] == ("stored-120/lammps", "LAMMPS", "LAMMPS", "stored biaxial-short-lammps", "made")
    assert runs["native/stored-120/lammps"][1:3] == ("native", "LAMMPS")  # native in LAMMPS' arithmetic
    assert runs["live-120/liggghts"][4] == "not made (LIGGGHTS absent)"
    html = (tmp_path / "results" / "report" / "index.html").read_text()
    for words in ("Why LIGGGHTS and LAMMPS differ", "The matrix by quantity", "Runs declared by this case"):
        assert words in html, words


def test_a_lammps_log_cut_short_fails_both_lammps_columns(stored_copy, tmp_path):
    log = stored_copy / "biaxial-short-lammps" / "log.lammps"
    out = []
    for line in log.read_text().splitlines():
        out.append(line)
        f = line.split()
        if f and f[0].isdigit() and int(f[0]) == 1200:
            break
    log.write_text("\n".join(out) + "\n")
    ok, res = _run(tmp_path)
    assert not ok and not res.passed and res.error is None
    assert res.cell("native-lammps")["state"] == "FAIL"
    assert res.cell("liggghts-lammps")["state"] == "FAIL"
    assert res.cell("native-liggghts")["state"] == "pass"
    bad = {(r.pair, r.metric) for r in res.records if r.quantity == "evidence" and not r.passed}
    for pair in ("native-lammps", "liggghts-lammps"):
        assert any(
            p == pair and m.startswith("incomplete: expected 3001 LAMMPS series steps, got 1201") for p, m in bad
        )
