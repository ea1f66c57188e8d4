"""biaxial-short as a declaration (validation.cases.biaxial.short_plan, yade_plan): on the stored runs
(codes reported absent) it fills its columns and passes, native vs YADE on YADE's stored output
bit for bit, the LIGGGHTS vs YADE and LAMMPS vs YADE columns not applicable (their undamped decks
need the codes); a LAMMPS log cut short fails both LAMMPS columns as incomplete (native vs LAMMPS,
LIGGGHTS vs LAMMPS) and leaves native vs LIGGGHTS passing; YADE's stored output cut short, or
stored for another input, fails native vs YADE; the raw LIGGGHTS-LAMMPS difference is shown with
the words that explain it."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

import validation.runner as vrunner
from reference_runs import store
from validation.codes import pairs
from validation.runner import run_validation

CASE = "biaxial-short"


def _quiet(*_a, **_k):
    pass


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


def _run(tmp_path):
    ok, results = run_validation("quick", tmp_path / "results", only=[CASE], log=_quiet)
    (res,) = results
    return ok, res


def test_stored_runs_fill_the_three_columns(stored_copy, tmp_path):
    ok, res = _run(tmp_path)
    assert ok and res.passed, [r for r in res.records if not r.passed]
    assert {p: res.cell(p)["state"] for p in pairs()} == {
        "native-liggghts": "pass",
        "native-lammps": "pass",
        "liggghts-lammps": "pass",
        "native-yade": "pass",
        "liggghts-yade": "n/a",
        "lammps-yade": "n/a",
    }
    yade = [r for r in res.records if r.pair == "native-yade" and r.kind != "info"]
    assert {r.quantity for r in yade} >= {"evidence", "position", "velocity", "stress", "box"}
    assert all(r.value == 0.0 and r.tolerance == 0.0 for r in yade)  # YADE's stored run, bit for bit
    assert any("stored YADE output against its manifest (YADE 2023.02a)" in r.metric for r in yade)
    raw = [r for r in res.records if r.kind == "info" and r.pair == "liggghts-lammps"]
    assert {r.quantity for r in raw} == {"stress", "position"}
    assert all(r.value > 1e-3 for r in raw)  # the codes differ beyond round-off ...
    assert all("lever arm" in r.reason and "pair_gran_hooke_history.cpp" in r.reason for r in raw)  # ... and why
    assert any("Why LIGGGHTS and LAMMPS differ" in n for n in res.notes)
    # each code's live runs, not made: live-120 of LIGGGHTS and LAMMPS, yade-120 of the three codes
    assert sum("is absent" in n for n in res.notes) == 5
    assert "its stored output yade-120/yade-stored is compared instead" in " ".join(res.notes)
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


def _yade_failures(res):
    return [r for r in res.records if r.pair == "native-yade" and not r.passed]


def test_yade_stored_output_cut_short_fails_native_vs_yade_as_incomplete(stored_copy, tmp_path):
    import gzip

    gz = stored_copy / "biaxial-short-yade" / "dem.out.gz"
    text = gzip.decompress(gz.read_bytes())
    gz.write_bytes(gzip.compress(text[: len(text) // 2]))
    ok, res = _run(tmp_path)
    assert not ok and res.error is None
    assert res.cell("native-yade")["state"] == "FAIL"
    assert res.cell("native-liggghts")["state"] == "pass"
    bad = _yade_failures(res)
    assert any(r.metric.startswith("incomplete: stored YADE output: incomplete:") for r in bad), bad
    assert any(r.metric.startswith("incomplete: expected 301 YADE series steps, got 0") for r in bad), bad


def test_yade_stored_output_of_another_input_fails(stored_copy, tmp_path):
    import json

    p = stored_copy / "biaxial-short-yade" / "manifest.json"
    man = json.loads(p.read_text())
    man["inputs"]["input.json"] = "0" * 64  # the output of another input
    p.write_text(json.dumps(man))
    ok, res = _run(tmp_path)
    assert not ok and res.cell("native-yade")["state"] == "FAIL"
    (bad,) = _yade_failures(res)
    assert "against its manifest" in bad.metric and "input sha256" in bad.metric and bad.value == 1.0
