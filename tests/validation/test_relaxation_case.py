"""The relaxation case (relaxed RVE vs frictionless damped DEM at rest, native / LIGGGHTS / LAMMPS) passes on
the stored runs of both RVEs (the jammed lattice and the standard random RVE rve-70-1), and fails when kn is 1%
off (in the DEM or in the relaxed material), when a stored log or dump is cut, when the stored RVE is not the
standard one, and when the DEM never comes to rest."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

import validation.cases.relaxation as R
from gransim.rve.relaxed import RelaxedMaterial
from validation import dem_compare
from validation.core import Context


def _ctx(tmp_path):
    return Context("default", tmp_path / "results", liggghts=False, lammps=False)


def _only(monkeypatch, *states):
    """The lattice RVE alone, with these of its states."""
    monkeypatch.setattr(R, "VARIANTS", ("lattice",))
    monkeypatch.setattr(R, "STATES", {k: R.STATES[k] for k in states})
    monkeypatch.setattr(R, "ENGINE_STATES", {e: tuple(s for s in v if s in states) for e, v in R.ENGINE_STATES.items()})


def _only_rve(monkeypatch, *states):
    """The standard random RVE alone, with these of its states."""
    monkeypatch.setattr(R, "VARIANTS", (R.RVE_NAME,))
    monkeypatch.setattr(R, "RVE_STATES", {k: R.RVE_STATES[k] for k in states})
    monkeypatch.setattr(
        R, "RVE_ENGINE_STATES", {e: tuple(s for s in v if s in states) for e, v in R.RVE_ENGINE_STATES.items()}
    )


def _failing(res, quantity=None, pair=None):
    return [
        r
        for r in res.checks
        if not r.passed and (quantity is None or r.quantity == quantity) and (pair is None or r.pair == pair)
    ]


def _rve_of(label):
    """The RVE of a record label: relaxation/<state>/... (lattice) or relaxation/rve-70-1/<state>/..."""
    return R.RVE_NAME if label.split("/")[1] == R.RVE_NAME else "lattice"


def _state_of(label):
    """The state of a record label: relaxation/<state>/... (lattice) or relaxation/rve-70-1/<state>/..."""
    parts = label.split("/")
    return parts[2] if parts[1] == R.RVE_NAME else parts[1]


def test_stored_runs_pass_and_tell_relaxed_from_taylor(tmp_path):
    res = R.relaxation(_ctx(tmp_path))
    assert res.passed, [r for r in res.checks if not r.passed]
    assert not res.empty_cells and set(res.matrix) == {"native-liggghts", "native-lammps", "liggghts-lammps"}
    for rve, states in (("lattice", R.STATES), (R.RVE_NAME, R.RVE_STATES)):
        stress = [r for r in res.checks if r.quantity == "stress" and _rve_of(r.case) == rve]
        # every side in every state: native x2 flavours (+ warm Newton), LIGGGHTS 2 states, LAMMPS 3 states, cross
        assert len(stress) >= 2 * 5 + 2 * 5 + 2
        taylor = min(r.value for r in res.records if r.quantity == "taylor_vs_relaxed" and _rve_of(r.case) == rve)
        # the affine stress is decades outside every tolerance: a check that passes saw relaxed fluctuations
        assert all(r.tolerance < 1e-3 * taylor for r in stress)
        cases = [r.case for r in res.checks if r.pair == "native-lammps" and _rve_of(r.case) == rve]
        assert {_state_of(c) for c in cases} == set(states)
    # rve-70-1 is the standard RVE, with rattlers: the DEM's free disks are reported, the disks in contact rest
    assert any(r.quantity == "evidence" and "shipped standard RVE rve-70-1" in r.metric for r in res.checks)
    free = [r for r in res.records if r.quantity == "free_disks"]
    assert free and all(_rve_of(r.case) == R.RVE_NAME for r in free)


@pytest.mark.parametrize("only, state", [(_only, "iso"), (_only_rve, "compression-22")], ids=["lattice", "rve-70-1"])
def test_one_percent_stiffer_dem_fails(tmp_path, monkeypatch, only, state):
    only(monkeypatch, state)

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
    # the (stored) codes still agree with Newton and with each other
    assert not [r for r in bad if "vs relaxed" in r.metric or r.pair == "liggghts-lammps"]


def test_one_percent_stiffer_relaxed_material_fails(tmp_path, monkeypatch):
    _only(monkeypatch, "iso")
    monkeypatch.setattr(R, "relaxed_material", lambda p: RelaxedMaterial(p, R.KN * 1.01))
    res = R.relaxation(_ctx(tmp_path))
    assert not res.passed
    for pair in ("native-liggghts", "native-lammps"):
        assert any("vs relaxed (Newton" in r.metric for r in _failing(res, "stress", pair))
    assert any("native DEM at rest vs Newton" in r.metric for r in _failing(res, "stress", ""))


def _run_with_half_of(tmp_path, monkeypatch, case, job, name):
    """Run the case on a copy of stored ``case`` whose ``job/name`` is cut to its first half."""
    cut = tmp_path / "stored" / case
    shutil.copytree(R.stored_dir(case), cut)
    f = cut / job / name
    text = f.read_text()
    f.write_text(text[: len(text) // 2])
    monkeypatch.setattr(R, "stored_dir", lambda _name: cut)
    return R.relaxation(_ctx(tmp_path))


@pytest.mark.parametrize("job, name", [("liggghts-iso", "log.lammps"), ("lammps-iso", "dump.atoms")])
def test_cut_stored_output_is_incomplete(tmp_path, monkeypatch, job, name):
    _only(monkeypatch, "iso")
    res = _run_with_half_of(tmp_path, monkeypatch, R.STORED_CASE, job, name)
    assert not res.passed
    pair = "native-" + job.split("-")[0]
    bad = _failing(res, "evidence", pair)
    assert bad and all("incomplete" in r.metric for r in bad)
    # the stored job's check against its deck names the cut file too
    assert any("incomplete stored job" in r.metric and name in r.metric for r in bad)
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


@pytest.mark.parametrize("store_case", ["relaxation", "relaxation-rve"])
def test_store_cli_without_binaries_exits_2_and_writes_nothing(tmp_path, store_case):
    import subprocess
    import sys

    from reference_runs.store import STORED

    before = sorted(p.name for p in STORED.iterdir())
    out = subprocess.run(
        [sys.executable, "-m", "reference_runs.store", "--case", store_case],
        env={"PATH": str(tmp_path), "HOME": str(tmp_path), "PYTHONPATH": str(STORED.parents[1])},
        capture_output=True,
        text=True,
        timeout=300,
        cwd=str(STORED.parents[1]),
    )
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr and "not found on PATH" in out.stderr
    assert sorted(p.name for p in STORED.iterdir()) == before


def test_standard_rve_one_percent_stiffer_relaxed_material_fails(tmp_path, monkeypatch):
    _only_rve(monkeypatch, "iso-shear-12")
    monkeypatch.setattr(R, "relaxed_material", lambda p: RelaxedMaterial(p, R.KN * 1.01))
    res = R.relaxation(_ctx(tmp_path))
    assert not res.passed
    assert any("vs relaxed (Newton" in r.metric for r in _failing(res, "stress", "native-lammps"))
    assert any("native DEM at rest vs Newton" in r.metric for r in _failing(res, "stress", ""))


@pytest.mark.parametrize(
    "state, job, name",
    [
        ("compression-22", "liggghts-compression-22", "log.lammps"),
        ("iso-shear-12", "lammps-iso-shear-12", "dump.atoms"),
    ],
)
def test_standard_rve_cut_stored_output_is_incomplete(tmp_path, monkeypatch, state, job, name):
    _only_rve(monkeypatch, state)
    res = _run_with_half_of(tmp_path, monkeypatch, R.RVE_STORED_CASE, job, name)
    assert not res.passed
    engine = job.split("-")[0]
    bad = _failing(res, "evidence", "native-" + engine)
    assert bad and all("incomplete" in r.metric for r in bad)
    # no verdict on the stress of the cut job rests on what was left
    assert not [r for r in res.checks if r.quantity == "stress" and f"/{engine}/stored" in r.case]
    # nothing else failed but the evidence of the cut job (and of the LIGGGHTS-LAMMPS pair it belongs to)
    allowed = ("native-" + engine, "liggghts-lammps")
    assert all(r.quantity == "evidence" and r.pair in allowed for r in res.checks if not r.passed)


def test_a_look_alike_of_the_standard_rve_fails_its_identity(tmp_path, monkeypatch):
    from gransim.io import load_packing, save_packing

    _only_rve(monkeypatch, "compression-22")
    src = R.stored_dir(R.RVE_STORED_CASE)
    fake = tmp_path / "stored" / R.RVE_STORED_CASE
    shutil.copytree(src, fake)
    p = load_packing(fake / "packing.h5")
    x = p.positions.copy()
    x[0, 0] += 1e-9 * p.radii[0]  # far below anything the stresses see
    save_packing(fake / "packing.h5", p.replace(positions=x))
    monkeypatch.setattr(R, "stored_dir", lambda _name: fake)
    res = R.relaxation(_ctx(tmp_path))
    bad = [r for r in res.checks if not r.passed]
    assert bad and all("shipped standard RVE" in r.metric for r in bad)


def test_standard_rve_dem_that_never_settles_fails_at_rest(tmp_path, monkeypatch):
    _only_rve(monkeypatch, "compression-22")

    def undamped(settings, loading):
        return dataclasses.replace(settings, gamma_n=0.0), loading

    monkeypatch.setattr(dem_compare, "native_setup", undamped)
    res = R.relaxation(_ctx(tmp_path))
    rest = _failing(res, "at_rest", "")
    assert rest and all("not at rest" in r.metric and r.value > 1e3 * R.KE_REST for r in rest)


def test_network_kinetic_energy_is_that_of_the_disks_in_contact_in_their_centre_of_mass_frame():
    from gransim.geometry import Packing

    rng = np.random.default_rng(3)
    n = 6
    p = Packing(rng.random((n, 2)), 0.1 + 0.05 * rng.random(n), np.eye(2), density=2.0)
    m = np.pi * p.radii**2 * p.density
    v = rng.standard_normal((n, 2))
    w = rng.standard_normal(n)
    touching = np.array([True, True, True, False, True, False])
    net, free = R.network_kinetic_energy(p, v, w, touching)
    # the free disks' energy plus the network's (about its centre of mass) plus the drift's is the total
    c = touching
    vcm = (m[c, None] * v[c]).sum(axis=0) / m[c].sum()
    assert net + free + 0.5 * m[c].sum() * vcm @ vcm == pytest.approx(R.kinetic_energy(p, v, w), rel=1e-13)
    # a common velocity of the disks in contact (a drift of the network) changes nothing; any other does
    v2 = v.copy()
    v2[c] += np.array([3.0, -2.0])
    assert R.network_kinetic_energy(p, v2, w, touching) == pytest.approx((net, free), rel=1e-12)
    v3 = v.copy()
    v3[0] += np.array([3.0, -2.0])
    assert R.network_kinetic_energy(p, v3, w, touching)[0] > net * (1 + 1e-3)
    # the free disks' energy is theirs, in the lab frame
    assert free == pytest.approx(
        0.5 * np.sum(m[~c] * (v[~c] ** 2).sum(axis=1)) + 0.25 * np.sum((m * p.radii**2 * w**2)[~c])
    )


def test_a_live_job_that_fails_is_failing_evidence_naming_it_and_the_case_goes_on(tmp_path, monkeypatch):
    from gransim.errors import GransimError

    _only(monkeypatch, "iso")

    def broken(job, *args, **kw):
        raise GransimError(f"lmp exited with status 1 in {job}")

    monkeypatch.setattr(R, "run_relaxation_job", broken)
    res = R.relaxation(Context("default", tmp_path / "results", liggghts=False, lammps=True))
    assert res.error is None
    bad = [r for r in res.checks if not r.passed]
    # every comparison of the live run (at rest, vs Newton, vs native) says why it has no verdict
    assert {r.case for r in bad} == {f"relaxation/iso/lammps/live{s}" for s in ("", "/vs-newton", "/vs-native")}
    assert all(r.quantity == "evidence" and r.pair == "native-lammps" for r in bad)
    assert all("live LAMMPS job failed: lmp exited with status 1" in r.metric for r in bad)
    # the stored jobs are still judged, and pass
    stored = [r for r in res.checks if "/stored" in r.case and r.quantity == "stress"]
    assert stored and all(r.passed for r in stored)
    # the report's run table says the run failed, and why
    assert any(
        r[0] == "relaxation/iso/lammps/live" and r[4].startswith("failed: live LAMMPS job failed") for r in res.runs
    )
