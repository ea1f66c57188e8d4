"""Step-for-step agreement of gransim.dem with LIGGGHTS 3.8.0 on the same deck.

Stored reference: reference_runs/stored/biaxial-short (README: provenance). Tolerances (those of
every step-for-step comparison, docs/validation.md): positions within 1e-10 D50, stresses within
1e-8 relative (of the largest stress component at that step: sigma_xy passes through zero). The
engine does the same floating-point operations in the same order as LIGGGHTS, including its
neighbour-list order (ghosts, bins, stencil), so the measured difference is exactly zero over the
3000 steps on this machine; the tolerances leave room for another CPU or compiler (round-off then
grows with the dynamics: docs/liggghts.md, "How fast round-off grows").
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from gransim.dem import DEMEngine
from reference_runs.decks.biaxial import (
    SHORT_CASE_DUMP_EVERY,
    read_dump,
    read_thermo,
    run_liggghts,
    short_case,
    write_biaxial_deck,
)

STORED = Path(__file__).resolve().parents[2] / "reference_runs" / "stored" / "biaxial-short"
POS_TOL = 1e-10  # of D50
STRESS_TOL = 1e-8  # relative


def _compare(thermo, dumps, nsteps, dump_every):
    p, s, ld, _ = short_case()
    eng = DEMEngine(p, s)
    box0 = (np.zeros(2), np.diag(p.cell).copy())
    st0 = eng.stress
    assert abs(st0[0, 0] - thermo["sxx"][0]) <= STRESS_TOL * abs(thermo["sxx"][0])
    stress = []
    lengths = []
    worst_pos = 0.0
    done = 0
    for stop in range(dump_every, nsteps + 1, dump_every):
        out = eng.advance(ld, stop - done, phase_step0=0, phase_box0=box0)
        done = stop
        stress.append(out["stress"])
        lengths.append(out["lengths"])
        if stop in dumps:
            fr = dumps[stop]
            L = eng.box_lengths
            d = eng.x - np.stack([fr["x"], fr["y"]], axis=1)
            d -= np.round(d / L) * L  # LIGGGHTS may have wrapped at another step (same rebuilds)
            worst_pos = max(worst_pos, np.abs(d).max() / p.d50)
    stress = np.concatenate(stress)
    lengths = np.concatenate(lengths)
    ref = np.stack([thermo["sxx"][1 : nsteps + 1], thermo["syy"][1 : nsteps + 1], thermo["sxy"][1 : nsteps + 1]], 1)
    mine = np.stack([stress[:, 0, 0], stress[:, 1, 1], stress[:, 0, 1]], 1)
    scale = np.abs(ref).max(axis=1)
    rel = np.abs(mine - ref).max(axis=1) / scale
    np.testing.assert_array_equal(thermo["step"][1 : nsteps + 1], np.arange(1, nsteps + 1))
    dl = np.abs(lengths - np.stack([thermo["lx"], thermo["ly"]], 1)[1 : nsteps + 1]).max() / p.d50
    return worst_pos, rel.max(), dl


def test_setup_forces_and_stress_bit_for_bit():
    # only IEEE basic operations in LIGGGHTS' order: the set-up evaluation is exactly equal
    thermo = read_thermo(STORED / "log.liggghts")
    d0 = read_dump(STORED / "dump.atoms")[0]
    p, s, _, _ = short_case()
    eng = DEMEngine(p, s)
    np.testing.assert_array_equal(eng.f[:, 0], d0["fx"])
    np.testing.assert_array_equal(eng.f[:, 1], d0["fy"])
    assert eng.stress[0, 0] == thermo["sxx"][0] and eng.stress[1, 1] == thermo["syy"][0]
    assert eng.stress[0, 1] == thermo["sxy"][0]


def test_stored_liggghts_run_step_for_step():
    thermo = read_thermo(STORED / "log.liggghts")
    dumps = read_dump(STORED / "dump.atoms")
    p, _, _, n = short_case()
    # the stored data file is the case's packing (guards against a changed generator)
    assert len(thermo["step"]) == n + 1
    np.testing.assert_allclose(dumps[0]["radius"], p.radii, rtol=0, atol=0)
    worst_pos, worst_stress, dl = _compare(thermo, dumps, n, SHORT_CASE_DUMP_EVERY)
    assert worst_pos < POS_TOL
    assert worst_stress < STRESS_TOL
    assert dl < POS_TOL


@pytest.mark.liggghts
def test_live_liggghts_run_step_for_step(tmp_path):
    if shutil.which("liggghts") is None:
        pytest.skip("liggghts binary not installed")
    p, s, ld, _ = short_case()
    n = 1000
    deck = write_biaxial_deck(tmp_path, p, s, ld, n, thermo_every=1, dump_every=250)
    log = run_liggghts(deck)
    worst_pos, worst_stress, dl = _compare(read_thermo(log), read_dump(tmp_path / "dump.atoms"), n, 250)
    assert worst_pos < POS_TOL
    assert worst_stress < STRESS_TOL
    assert dl < POS_TOL


def test_deck_mirrors_engine_settings(tmp_path):
    p, s, ld, _ = short_case()
    deck = write_biaxial_deck(tmp_path, p, s, ld, 10).read_text()
    for line in (
        "newton off",
        "atom_modify map array sort 0 0.0",
        "neigh_modify delay 0 every 1 check yes",
        f"neighbor {s.skin:.17g} bin",
        f"timestep {s.dt:.17g}",
        "pair_style gran model hooke/stiffness tangential history",
        "remap x",
    ):
        assert line in deck
    # the servo stress is a fix ave/time defined before fix deform (evaluated first in end_of_step)
    assert deck.index("fix avsx") < deck.index("fix deform")
    # the rate literal is c = rate L0 dt, the exact double the engine uses
    c = ld.y.rate * p.cell[1, 1] * s.dt
    assert f"variable dy equal {c:.17g}*step" in deck
