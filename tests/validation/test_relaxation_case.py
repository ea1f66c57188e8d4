"""The relaxation case (relaxed RVE vs frictionless damped DEM at rest, native / LIGGGHTS / LAMMPS) passes on
the stored runs, and fails when kn is 1% off (in the DEM or in the relaxed material), when a stored log or
dump is cut, and when the DEM never comes to rest."""

from __future__ import annotations

import dataclasses
import shutil

import pytest

import validation.cases.relaxation as R
from gransim.rve.relaxed import RelaxedMaterial
from validation import dem_compare
from validation.core import Context


def _ctx(tmp_path):
    return Context("default", tmp_path / "results", liggghts=False, lammps=False)


def _only(monkeypatch, *states):
    monkeypatch.setattr(R, "STATES", {k: R.STATES[k] for k in states})
    monkeypatch.setattr(R, "ENGINE_STATES", {e: tuple(s for s in v if s in states) for e, v in R.ENGINE_STATES.items()})


def _failing(res, quantity=None, pair=None):
    return [
        r
        for r in res.checks
        if not r.passed and (quantity is None or r.quantity == quantity) and (pair is None or r.pair == pair)
    ]


def test_stored_runs_pass_and_tell_relaxed_from_taylor(tmp_path):
    res = R.relaxation(_ctx(tmp_path))
    assert res.passed, [r for r in res.checks if not r.passed]
    assert not res.empty_cells and set(res.matrix) == {"native-liggghts", "native-lammps", "liggghts-lammps"}
    stress = [r for r in res.checks if r.quantity == "stress"]
    # every side in every state: native x2 flavours (+ warm Newton), LIGGGHTS 2 states, LAMMPS 3 states, cross
    assert len(stress) >= 2 * 5 + 2 * 5 + 2
    taylor = min(r.value for r in res.records if r.quantity == "taylor_vs_relaxed")
    # the affine stress is decades outside every tolerance: a check that passes saw relaxed fluctuations
    assert all(r.tolerance < 1e-3 * taylor for r in stress)
    assert {r.case.split("/")[1] for r in res.checks if r.pair == "native-lammps"} == {
        "iso",
        "compression-22",
        "shear-12",
    }


def test_one_percent_stiffer_dem_fails(tmp_path, monkeypatch):
    _only(monkeypatch, "iso")

    def stiffer(settings, loading):
        return dataclasses.replace(settings, kn=settings.kn * 1.01), loading

    monkeypatch.setattr(dem_compare, "native_setup", stiffer)
    res = R.relaxation(_ctx(tmp_path))
    assert not res.passed
    bad = _failing(res, "stress")
    assert any("native DEM at rest vs Newton" in r.metric for r in bad)
    assert any("vs native DEM" in r.metric and r.pair == "native-liggghts" for r in bad)
    assert any("vs native DEM" in r.metric and r.pair == "native-lammps" for r in bad)
    assert all(r.value > 1e-3 for r in bad)  # a 1% stiffness moves the stress by ~1%
    # the codes still agree with Newton and with each other
    assert not [r for r in bad if "vs relaxed" in r.metric or r.pair == "liggghts-lammps"]


def test_one_percent_stiffer_relaxed_material_fails(tmp_path, monkeypatch):
    _only(monkeypatch, "iso")
    monkeypatch.setattr(R, "relaxed_material", lambda p: RelaxedMaterial(p, R.KN * 1.01))
    res = R.relaxation(_ctx(tmp_path))
    assert not res.passed
    for pair in ("native-liggghts", "native-lammps"):
        assert any("vs relaxed (Newton" in r.metric for r in _failing(res, "stress", pair))
    assert any("native DEM at rest vs Newton" in r.metric for r in _failing(res, "stress", ""))


@pytest.mark.parametrize("job, name", [("liggghts-iso", "log.lammps"), ("lammps-iso", "dump.atoms")])
def test_cut_stored_output_is_incomplete(tmp_path, monkeypatch, job, name):
    _only(monkeypatch, "iso")
    src = R.stored_dir(R.STORED_CASE)
    cut = tmp_path / "stored" / R.STORED_CASE
    shutil.copytree(src, cut)
    f = cut / job / name
    text = f.read_text()
    f.write_text(text[: len(text) // 2])
    monkeypatch.setattr(R, "stored_dir", lambda _name: cut)
    res = R.relaxation(_ctx(tmp_path))
    assert not res.passed
    pair = "native-" + job.split("-")[0]
    bad = _failing(res, "evidence", pair)
    assert bad and all("incomplete" in r.metric for r in bad)
    # no verdict on the stress of the cut job rests on what was left
    assert not [r for r in res.checks if r.quantity == "stress" and f"/{job.split('-')[0]}/stored" in r.case]


def test_a_dem_that_never_settles_fails_at_rest(tmp_path, monkeypatch):
    _only(monkeypatch, "iso")

    def undamped(settings, loading):
        return dataclasses.replace(settings, gamma_n=0.0), loading

    monkeypatch.setattr(dem_compare, "native_setup", undamped)
    res = R.relaxation(_ctx(tmp_path))
    assert not res.passed
    rest = _failing(res, "at_rest", "")
    assert rest and all("not at rest" in r.metric and r.value > 1e3 * R.KE_REST for r in rest)


def test_store_cli_without_binaries_exits_2_and_writes_nothing(tmp_path):
    import subprocess
    import sys

    from reference_runs.store import STORED

    before = sorted(p.name for p in STORED.iterdir())
    out = subprocess.run(
        [sys.executable, "-m", "reference_runs.store", "--case", "relaxation"],
        env={"PATH": str(tmp_path), "HOME": str(tmp_path), "PYTHONPATH": str(STORED.parents[1])},
        capture_output=True,
        text=True,
        timeout=300,
        cwd=str(STORED.parents[1]),
    )
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr and "not found on PATH" in out.stderr
    assert sorted(p.name for p in STORED.iterdir()) == before
