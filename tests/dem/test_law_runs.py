"""Each contact law of gransim.contacts, native vs its code, step for step on a periodic assembly:
the biaxial short case (reference_runs.decks.biaxial.short_case(): 120 disks,
servo on x, compression on y, contacts across the boundary, neighbour-list rebuilds) with the law
of reference_runs.decks.biaxial.short_case_law(name), 3000 steps at dt = 2e-6 s (every law).
Stored runs: reference_runs/stored/biaxial-short-<name>/ (README: code, command, date).
Tolerances as for Hooke (tests/dem/test_liggghts.py): positions and box 1e-10 D50 at every dump
(500 steps), velocities and spins 1e-8 relative, the virial stress of every step 1e-8 relative
(of its largest component)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from gransim.contacts.laws import law_code
from gransim.dem import DEMEngine, DEMSettings
from gransim.errors import InputError
from reference_runs.decks.biaxial import (
    SHORT_CASE_DUMP_EVERY,
    SHORT_CASE_LAWS,
    law_pair_lines,
    read_dump,
    read_thermo,
    run_deck,
    short_case,
    short_case_law,
    write_biaxial_deck,
)

STORED = Path(__file__).resolve().parents[2] / "reference_runs" / "stored"
POS_TOL = 1e-10  # of D50
REL_TOL = 1e-8


def _native(name):
    p, s, ld, n = short_case()
    s = DEMSettings(**{**s.to_dict(), "flavour": law_code(name)})
    return p, DEMEngine(p, s, law=short_case_law(name), check_dt=False), ld, n


def _compare(name, job: Path):
    """Worst differences of the native run against the run in ``job``: (positions / D50,
    velocities rel, spins rel, stress rel, box / D50)."""
    thermo = read_thermo(next(job.glob("log.*")))
    dumps = read_dump(job / "dump.atoms")
    p, eng, ld, n = _native(name)
    np.testing.assert_array_equal(dumps[0]["radius"], p.radii)
    np.testing.assert_array_equal(dumps[0]["mass"], eng.m)
    box0 = (np.zeros(2), np.diag(p.cell).copy())
    stress, lengths, wp, wv, ww, done = [], [], 0.0, 0.0, 0.0, 0
    for stop in range(SHORT_CASE_DUMP_EVERY, n + 1, SHORT_CASE_DUMP_EVERY):
        out = eng.advance(ld, stop - done, phase_step0=0, phase_box0=box0)
        done = stop
        stress.append(out["stress"])
        lengths.append(out["lengths"])
        fr = dumps[stop]
        L = eng.box_lengths
        d = eng.x - np.stack([fr["x"], fr["y"]], axis=1)
        d -= np.round(d / L) * L
        wp = max(wp, np.abs(d).max() / p.d50)
        vref = np.stack([fr["vx"], fr["vy"]], axis=1)
        wv = max(wv, np.abs(eng.v - vref).max() / np.abs(vref).max())
        ww = max(ww, np.abs(eng.w - fr["omegaz"]).max() / np.abs(fr["omegaz"]).max())
    stress, lengths = np.concatenate(stress), np.concatenate(lengths)
    np.testing.assert_array_equal(thermo["step"][1 : n + 1], np.arange(1, n + 1))
    ref = np.stack([thermo["sxx"][1 : n + 1], thermo["syy"][1 : n + 1], thermo["sxy"][1 : n + 1]], 1)
    mine = np.stack([stress[:, 0, 0], stress[:, 1, 1], stress[:, 0, 1]], 1)
    rel = np.abs(mine - ref).max(axis=1) / np.abs(ref).max(axis=1)
    dl = np.abs(lengths - np.stack([thermo["lx"], thermo["ly"]], 1)[1 : n + 1]).max() / p.d50
    return wp, wv, ww, rel.max(), dl, eng


def _check(name, job):
    wp, wv, ww, wst, dl, eng = _compare(name, job)
    assert wp < POS_TOL and dl < POS_TOL, (name, wp, dl)
    assert wv < REL_TOL and ww < REL_TOL, (name, wv, ww)
    assert wst < REL_TOL, (name, wst)
    assert eng.n_rebuilds > 0  # the history went through list rebuilds and hand-overs
    return wp, wst


@pytest.mark.parametrize("name", SHORT_CASE_LAWS)
def test_stored_run_step_for_step(name):
    wp, wst = _check(name, STORED / f"biaxial-short-{name}")
    # measured: every law, hooke-sds-lammps included since its rolling torque is added to the
    # particle after the tangential one as LAMMPS does (LawSpec.split_torque), is bit for bit
    assert (wp, wst) == (0.0, 0.0), (name, wp, wst)


@pytest.mark.parametrize("name", ["hertz-liggghts", "hooke-epsd2-liggghts"])
def test_law_changes_the_run(name):
    """Not a no-op: the Hooke law of the same settings misses the stored run of ``name`` far
    outside the tolerance (first 500 steps)."""
    p, s, ld, _ = short_case()
    thermo = read_thermo(next((STORED / f"biaxial-short-{name}").glob("log.*")))
    eng = DEMEngine(p, s)
    out = eng.advance(ld, 500, phase_step0=0, phase_box0=(np.zeros(2), np.diag(p.cell).copy()))
    ref = np.stack([thermo["sxx"][1:501], thermo["syy"][1:501]], 1)
    mine = np.stack([out["stress"][:, 0, 0], out["stress"][:, 1, 1]], 1)
    assert (np.abs(mine - ref).max(axis=1) / np.abs(ref).max(axis=1)).max() > 1e-5


def test_deck_refuses_law_of_other_code(tmp_path):
    p, s, ld, _n = short_case()
    with pytest.raises(InputError, match="is a lammps law, the deck is for liggghts"):
        write_biaxial_deck(tmp_path, p, s, ld, 10, law=short_case_law("hooke-sds-lammps"))
    with pytest.raises(InputError, match="is a liggghts law, the deck is for lammps"):
        law_pair_lines(short_case_law("hertz-liggghts"), s, "lammps")


@pytest.mark.parametrize("name", SHORT_CASE_LAWS)
def test_stored_deck_is_todays_writer(name, tmp_path):
    """The stored deck is the one write_biaxial_deck writes today for the law."""
    p, s, ld, n = short_case()
    engine = law_code(name)
    deck = write_biaxial_deck(
        tmp_path, p, s, ld, n, thermo_every=1, dump_every=SHORT_CASE_DUMP_EVERY, engine=engine, law=short_case_law(name)
    )
    assert deck.read_text() == (STORED / f"biaxial-short-{name}" / deck.name).read_text()


def _live(name, tmp_path):
    engine = law_code(name)
    if shutil.which("liggghts" if engine == "liggghts" else "lmp") is None:
        pytest.skip(f"{engine} binary not installed")
    p, s, ld, n = short_case()
    deck = write_biaxial_deck(
        tmp_path, p, s, ld, n, thermo_every=1, dump_every=SHORT_CASE_DUMP_EVERY, engine=engine, law=short_case_law(name)
    )
    run_deck(deck, engine)
    _check(name, tmp_path)


@pytest.mark.liggghts
@pytest.mark.parametrize("name", [n for n in SHORT_CASE_LAWS if law_code(n) == "liggghts"])
def test_live_liggghts(name, tmp_path):
    _live(name, tmp_path)


@pytest.mark.lammps
@pytest.mark.parametrize("name", [n for n in SHORT_CASE_LAWS if law_code(n) == "lammps"])
def test_live_lammps(name, tmp_path):
    _live(name, tmp_path)
