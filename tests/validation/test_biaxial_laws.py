"""The ``biaxial-laws`` case (validation/cases/biaxial_laws.py): its job list, parameters and decks,
without running a code (the case itself runs under ``gransim validate --suite full``)."""

from __future__ import annotations

import math
import shutil

import pytest

from gransim.contacts.laws import law_code, law_names, law_spec
from gransim.dem.biaxial import default_settings, hertz_equivalent_stiffness
from gransim.dem.lattice import lattice_packing
from validation.cases import biaxial_laws as B
from validation.core import Context


@pytest.fixture(scope="module")
def setup():
    pk = lattice_packing(6, 6, seed=4, spread=0.1, compression=0.04)
    dem, bi = default_settings(pk)
    return pk, dem, bi


def test_case_is_in_the_full_suite_only():
    from validation.core import registered_cases as cases_for

    assert "biaxial-laws" in [c.id for c in cases_for("full")]
    assert "biaxial-laws" not in [c.id for c in cases_for("default")]
    assert "biaxial-laws" not in [c.id for c in cases_for("quick")]


def test_law_table_keeps_the_protocol_scales(setup):
    """Hertz: the equivalent stiffness of the chosen E is the protocol's kn; the restitution is
    exp(-pi zeta/sqrt(1 - zeta^2)) of the protocol's zeta = gamma_n/(2 sqrt(kn/m_eff)) = 0.3."""
    pk, dem, _ = setup
    t = B.law_table(pk, dem)
    assert list(t) == list(law_names())
    for name in ("hertz-liggghts", "hertz-granular-lammps", "hertz-lammps"):
        assert hertz_equivalent_stiffness(pk, name, t[name]) == pytest.approx(dem.kn, rel=1e-12)
    z = 0.3
    assert t["hertz-liggghts"]["restitution"] == pytest.approx(math.exp(-math.pi * z / math.sqrt(1 - z * z)), rel=1e-9)
    assert t["hooke-liggghts"] == {
        "kn": dem.kn,
        "kt": dem.kt,
        "gamma_n": dem.gamma_n,
        "gamma_t": dem.gamma_t,
        "mu": dem.mu,
    }


@pytest.mark.parametrize("ligg, lmp", [(True, True), (True, False), (False, True)])
def test_job_list(tmp_path, setup, ligg, lmp):
    pk, dem, _ = setup
    ctx = Context("full", tmp_path / "results", liggghts=ligg, lammps=lmp)
    jobs = B.law_jobs(ctx, pk, dem)
    want = [n for n in law_names() if (law_code(n) == "liggghts" and ligg) or (law_code(n) == "lammps" and lmp)]
    assert sorted({k[0] for k in jobs}) == sorted(want)
    labels = {"reference", *(p[0] for p in B.PERTURB)}
    for name in want:
        assert {k[1] for k in jobs if k[0] == name} == labels
    assert len({str(j["job_dir"]) for j in jobs.values()}) == len(jobs)
    for (name, label), j in jobs.items():
        assert j["engine"] == law_code(name) == j["settings"].flavour
        law_spec(j["law"])  # a registered plug-in
        moved = (j["packing"].positions != pk.positions).sum()
        assert moved == (0 if label == "reference" else 1)


def test_every_law_writes_its_own_deck(tmp_path, setup):
    """Each job's deck carries its law's pair style (no job silently falls back to Hooke)."""
    from gransim.dem import AxisControl, Loading

    pk, dem, bi = setup
    ctx = Context("full", tmp_path / "results", liggghts=True, lammps=True)
    jobs = B.law_jobs(ctx, pk, dem)
    servo = AxisControl("servo", target=bi.confining, gain=bi.servo_gain)
    loading = Loading(x=servo, y=AxisControl("rate", rate=-bi.strain_rate))
    marks = {
        "hooke-liggghts": "hooke/stiffness",
        "hooke-lammps": "gran/hooke/history",
        "hertz-liggghts": "model hertz",
        "hertz-lammps": "gran/hertz/history",
        "hertz-granular-lammps": "hertz/material",
        "hooke-epsd2-liggghts": "epsd2",
        "hooke-epsd-liggghts": "rolling_friction epsd",
        "hooke-cdt-liggghts": "cdt",
        "hooke-sds-lammps": "rolling sds",
    }
    for name in law_names():
        d = tmp_path / name
        d.mkdir()
        deck, files = B.write_job_deck(d, jobs[(name, "reference")], loading, 20, None, None, 10, 1)
        assert marks[name] in deck.read_text(), name
        assert files


@pytest.mark.skipif(not (shutil.which("liggghts") and shutil.which("lmp")), reason="LIGGGHTS and LAMMPS needed")
def test_the_case_declares_each_law_against_its_codes_envelope(tmp_path, monkeypatch, setup):
    """The case on a 36-disk lattice, 600 steps, two laws (one per code): each native run within its
    code's envelope in its column; LAMMPS absent, its column is not applicable and LIGGGHTS' still
    judged; a member job cut short (its dump without the last frame) fails as incomplete evidence
    with no envelope verdict."""
    import numpy as np

    from gransim.dem import AxisControl, Loading

    pk, dem, bi = setup
    servo = AxisControl("servo", target=bi.confining, gain=bi.servo_gain)
    start = {
        "packing": pk, "settings": dem, "biaxial": bi, "nsteps": 600,
        "loading": Loading(x=servo, y=AxisControl("rate", rate=-bi.strain_rate)),
        "velocities": np.zeros((pk.n, 2)), "spins": np.zeros(pk.n),
    }  # fmt: skip
    monkeypatch.setattr(B, "common_start", lambda ctx: start)
    real_table = B.law_table
    monkeypatch.setattr(
        B,
        "law_table",
        lambda p, d: {k: v for k, v in real_table(p, d).items() if k in ("hooke-liggghts", "hooke-lammps")},
    )
    monkeypatch.setattr(B, "FULL_DUMP_EVERY", 200)
    monkeypatch.setattr(B, "FULL_THERMO_EVERY", 10)
    ctx = Context("full", tmp_path / "results", liggghts=True, lammps=True)
    res = B.biaxial_laws(ctx)
    assert res.passed, [(r.case, r.quantity, r.metric) for r in res.checks if not r.passed]
    assert res.cell("native-liggghts")["state"] == "pass" and res.cell("native-lammps")["state"] == "pass"
    judged = {(r.case, r.quantity) for r in res.checks if r.tolerance == B.FULL_RULE.factor}
    assert judged == {(f"biaxial-laws/hooke-{c}", q) for c in ("liggghts", "lammps") for q in ("position", "stress")}

    res = B.biaxial_laws(Context("full", tmp_path / "results", liggghts=True, lammps=False))
    assert res.cell("native-lammps")["state"] == "n/a" and res.cell("native-liggghts")["state"] == "pass"

    real_job = B.run_code_job

    def cut(job, *a, **k):
        tr, man = real_job(job, *a, **k)
        if "perturbed" in str(job["job_dir"]) and job["engine"] == "liggghts":
            tr = type(tr)(tr.steps, tr.stress, tr.lengths, {s: f for s, f in tr.frames.items() if s < 600})
        return tr, man

    monkeypatch.setattr(B, "run_code_job", cut)
    res = B.biaxial_laws(ctx)
    bad = [r for r in res.checks if not r.passed]
    assert bad and {r.quantity for r in bad} == {"evidence"} and all("liggghts" in r.case for r in bad)
    assert not any(r.case == "biaxial-laws/hooke-liggghts" and r.tolerance == B.FULL_RULE.factor for r in res.records)
