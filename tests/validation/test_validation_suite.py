"""The validation layer end to end (quick suite) and its ability to fail.

The quick suite compares the native engine with stored (and, when installed, live) LIGGGHTS
runs: it must pass and write the documented outputs. Deliberately broken native inputs (1%
stiffer contacts; the lateral servo dropped) must make the step-for-step and void-cell cases
fail: a layer that cannot fail validates nothing.
"""

from __future__ import annotations

import dataclasses
import json

import h5py
import pytest

from gransim.dem import AxisControl, Loading
from validation import dem_compare
from validation.runner import run_validation

CASE_IDS = {"packings", "taylor-rve", "biaxial-short", "biaxial-full", "simple-shear", "voidcell", "slope", "impacts"}


def _quiet(*_a, **_k):
    pass


def test_quick_suite_passes_and_writes_outputs(tmp_path):
    ok, results = run_validation("quick", tmp_path, log=_quiet)
    assert ok, [(r.case, r.error, [x for x in r.records if not x.passed]) for r in results if not r.passed]
    assert {r.case for r in results} == {"taylor-rve", "biaxial-short", "simple-shear", "voidcell", "impacts"}
    doc = json.loads((tmp_path / "validation.json").read_text())
    for code, word in (("liggghts", "LIGGGHTS"), ("lammps", "LAMMPS")):  # each code as it reports itself
        if doc["header"][f"{code}_available"]:
            assert doc["header"][f"{code}_version"].startswith(word), doc["header"]
        else:
            assert doc["header"][f"{code}_version"] == "absent"
    assert doc["cases"] == {
        "taylor-rve": "pass",
        "biaxial-short": "pass",
        "simple-shear": "pass",
        "voidcell": "pass",
        "impacts": "pass",
    }
    assert doc["records"]
    for rec in doc["records"]:
        assert {"case", "quantity", "metric", "value", "tolerance", "pass"} <= set(rec)
        assert rec["case"].split("/")[0] in CASE_IDS
        assert rec["reason"], rec  # every tolerance carries its reason
    qty = {(r["case"].split("/")[0], r["quantity"]) for r in doc["records"]}
    for q in ("position", "velocity", "spin", "particle_force", "stress", "box"):
        assert ("biaxial-short", q) in qty
    for q in ("cell_list", "alpha", "w"):
        assert ("voidcell", q) in qty
    with h5py.File(tmp_path / "validation.h5", "r") as f:
        assert f.attrs["kind"] == "validation"
        assert len(f["value"]) == len(doc["records"])
        kinds = [k.decode() if isinstance(k, bytes) else k for k in f["kind"][()]]
        assert all(p for p, k in zip(f["pass"][()], kinds) if k == "check")
        assert "info" in kinds  # the raw cross-code differences are shown, not judged
        assert {"native-liggghts", "native-lammps", "liggghts-lammps"} <= {
            p.decode() if isinstance(p, bytes) else p for p in f["pair"][()]
        }
    html = (tmp_path / "report" / "index.html").read_text()
    assert html.index("<h2>Summary</h2>") < html.index("Validation matrix")
    assert "All 5 cases pass" in html
    for cid in ("taylor-rve", "biaxial-short", "voidcell"):
        assert f"id='{cid}'" in html
    assert (tmp_path / "report" / "figures" / "voidcell_stored120.png").stat().st_size > 0
    from validation.browser import check_report, chromium, problems

    if chromium() is not None:  # what a reader sees at 1400 px: every image loads, no section is empty
        seen = check_report(tmp_path / "report" / "index.html", width=1400)
        assert problems(seen) == [], problems(seen)
        assert len(seen["images"]) >= 3


def _failed(results, case_id):
    (res,) = [r for r in results if r.case == case_id]
    return res, {(x.case, x.quantity) for x in res.records if not x.passed}


def test_one_percent_stiffer_native_contacts_fail(tmp_path, monkeypatch):
    def stiffer(settings, loading):
        return dataclasses.replace(settings, kn=1.01 * settings.kn, kt=1.01 * settings.kt), loading

    monkeypatch.setattr(dem_compare, "native_setup", stiffer)
    ok, results = run_validation("quick", tmp_path, only=["biaxial-short", "voidcell"], log=_quiet)
    assert not ok
    res, bad = _failed(results, "biaxial-short")
    assert not res.passed and res.error is None
    for code in ("liggghts", "lammps"):
        assert (f"biaxial-short/stored-120/{code}", "position") in bad
        assert (f"biaxial-short/stored-120/{code}", "stress") in bad
    res, _ = _failed(results, "voidcell")
    assert not res.passed


def test_dropped_servo_fails(tmp_path, monkeypatch):
    def no_servo(settings, loading):
        fix = [AxisControl("fixed") if c.mode == "servo" else c for c in (loading.x, loading.y)]
        assert fix != [loading.x, loading.y]  # the deck has a servo to drop
        return settings, Loading(x=fix[0], y=fix[1])

    monkeypatch.setattr(dem_compare, "native_setup", no_servo)
    ok, results = run_validation("quick", tmp_path, only=["biaxial-short"], log=_quiet)
    assert not ok
    res, bad = _failed(results, "biaxial-short")
    for code in ("liggghts", "lammps"):
        assert (f"biaxial-short/stored-120/{code}", "box") in bad
        assert (f"biaxial-short/stored-120/{code}", "stress") in bad


def test_unknown_case_is_a_clear_error(tmp_path):
    from gransim.errors import InputError

    with pytest.raises(InputError, match="case"):
        run_validation("quick", tmp_path, only=["no-such-case"], log=_quiet)


def test_without_liggghts_biaxial_full_uses_the_stored_series(tmp_path, monkeypatch):
    # a machine without LIGGGHTS: the report says so and the full loading is compared with the
    # stored stress/box series of the reference and perturbed LIGGGHTS runs
    import validation.runner as runner

    monkeypatch.setattr(runner, "liggghts_available", lambda: False)
    monkeypatch.setattr(runner, "lammps_available", lambda: False)
    ok, results = run_validation("default", tmp_path, only=["biaxial-full"], log=_quiet)
    (res,) = results
    assert ok, [(r.case, r.quantity, r.value, r.tolerance) for r in res.records if not r.passed]
    assert {r.quantity for r in res.checks} == {"evidence", "stress", "deviator", "volumetric_strain"}
    ev = [r for r in res.records if r.quantity == "evidence"]
    assert all(r.passed and r.metric.startswith("complete") for r in ev), ev
    for pair in ("native-liggghts", "native-lammps", "liggghts-lammps"):
        assert res.cell(pair)["state"] == "pass", pair
    assert sum("stored series" in n for n in res.notes) == 2  # one per code
    html = (tmp_path / "report" / "index.html").read_text()
    assert "LIGGGHTS is not installed" in html and "LAMMPS is not installed" in html


def test_packings_case_checks_the_saved_files_and_can_fail(tmp_path, monkeypatch):
    """The packings case recomputes balance, overlaps and the sieve curve from the files: a
    generated RVE passes; the same RVE with one disk moved by 1e-5 of its radius (a few percent of a
    contact overlap) fails the balance and the bitwise comparison with the regenerated RVE, and
    nothing else."""
    import gransim.generation as gen
    from gransim.io import load_packing, read_provenance, save_packing

    real = gen.standard_packings
    monkeypatch.setattr(gen, "standard_packings", lambda out, names=None, force=False: real(out, names=["rve-70-1"]))
    ok, results = run_validation("default", tmp_path, only=["packings"], log=_quiet)
    assert ok, [x for r in results for x in r.records if not x.passed]
    (res,) = results
    regen = "regenerated"
    assert {x.quantity for x in res.records} == {"sieve curve", "force balance", "mean overlap", regen}

    path = tmp_path / "packings" / "rve-70-1.h5"
    p = load_packing(path)
    x = p.positions.copy()
    x[0, 0] += 1e-5 * p.radii[0]
    save_packing(path, p.replace(positions=x), parameters=read_provenance(path)["parameters"])
    monkeypatch.setattr(gen, "standard_packings", lambda out, names=None, force=False: {"rve-70-1": path})
    ok, results = run_validation("default", tmp_path, only=["packings"], log=_quiet)
    res, failed = _failed(results, "packings")
    assert not ok and failed == {("packings/rve-70-1", "force balance"), ("packings/rve-70-1", regen)}


def test_biaxial_full_with_a_stored_series_cut_short_makes_no_envelope_verdict(tmp_path, monkeypatch):
    """The stored LAMMPS series of biaxial-full cut to its first half (an interrupted store): the
    LAMMPS column fails as incomplete, without an envelope or curve verdict on what remains, the
    LIGGGHTS-LAMMPS column fails as incomplete too (no band without complete runs), and the LIGGGHTS
    column still passes."""
    import shutil
    from pathlib import Path

    import numpy as np

    import validation.runner as runner
    from reference_runs import store

    dest = tmp_path / "stored"
    shutil.copytree(Path(store.STORED) / "biaxial-full", dest / "biaxial-full")
    path = dest / "biaxial-full" / "strain0.005-lammps.npz"
    z = dict(np.load(path))
    half = len(z["steps"]) // 2
    np.savez_compressed(path, **{k: (v[:half] if v.ndim else v) for k, v in z.items()})
    monkeypatch.setattr(store, "STORED", dest)
    monkeypatch.setattr(runner, "liggghts_available", lambda: False)
    monkeypatch.setattr(runner, "lammps_available", lambda: False)
    ok, results = run_validation("default", tmp_path / "results", only=["biaxial-full"], log=_quiet)
    (res,) = results
    assert not ok and not res.passed and res.error is None
    assert res.cell("native-lammps")["state"] == "FAIL" and res.cell("native-liggghts")["state"] == "pass"
    cross = [r for r in res.checks if r.pair == "liggghts-lammps"]
    assert [r.metric.split(" (")[0] for r in cross] == ["incomplete: expected 1 complete runs of both codes"]
    lammps = [r for r in res.checks if r.pair == "native-lammps"]
    bad = [r.metric for r in lammps if not r.passed]
    assert bad and all(m.startswith("incomplete: expected") for m in bad), bad
    assert not any(r.case.startswith(("biaxial-full/divergence/lammps", "biaxial-full/curve/lammps")) for r in lammps)
    assert any("Incomplete evidence" in n and "LAMMPS" in n for n in res.notes)
