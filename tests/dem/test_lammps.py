"""Step-for-step agreement of gransim.dem (``DEMSettings(flavour="lammps")``) with LAMMPS.

Stored reference: reference_runs/stored/biaxial-short-lammps (LAMMPS 29 Sep 2021 - Update 2,
Debian ``lmp``; README: provenance), the case of reference_runs/stored/biaxial-short run by
LAMMPS. Tolerances as for LIGGGHTS: positions within 1e-10 D50, stresses within 1e-8
relative (of the largest component at that step). Measured on this machine: exactly equal at
every step and dump over the 3000 steps (docs/lammps.md lists the arithmetic differences of the
two codes that the flavour reproduces).
"""

from __future__ import annotations

import dataclasses
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from gransim.contacts.hooke import hooke_history, hooke_history_lammps
from gransim.dem import DEMEngine, DEMSettings
from gransim.dem import kernels as K
from gransim.dem.lattice import lattice_packing
from gransim.dem.run import Phase, run_phases
from gransim.errors import InputError
from reference_runs.decks.biaxial import (
    SHORT_CASE_DUMP_EVERY,
    read_dump,
    read_thermo,
    run_deck,
    short_case,
    write_biaxial_deck,
)

ROOT = Path(__file__).resolve().parents[2] / "reference_runs" / "stored"
STORED = ROOT / "biaxial-short-lammps"
STORED_LIGGGHTS = ROOT / "biaxial-short"
POS_TOL = 1e-10  # of D50
STRESS_TOL = 1e-8  # relative


def _lammps_case():
    p, s, ld, n = short_case()
    return p, dataclasses.replace(s, flavour="lammps"), ld, n


def _compare(settings, thermo, dumps, nsteps, dump_every):
    """Run the short case natively with ``settings``; worst differences against a run's thermo and
    dumps: (positions / D50, velocities relative, spins relative, stress relative, box / D50)."""
    p, _, ld, _ = short_case()
    eng = DEMEngine(p, settings)
    box0 = (np.zeros(2), np.diag(p.cell).copy())
    stress, lengths = [], []
    wp = wv = ww = 0.0
    done = 0
    for stop in range(dump_every, nsteps + 1, dump_every):
        out = eng.advance(ld, stop - done, phase_step0=0, phase_box0=box0)
        done = stop
        stress.append(out["stress"])
        lengths.append(out["lengths"])
        fr = dumps[stop]
        L = eng.box_lengths
        d = eng.x - np.stack([fr["x"], fr["y"]], axis=1)
        d -= np.round(d / L) * L  # the code may have wrapped at another step
        wp = max(wp, np.abs(d).max() / p.d50)
        vref = np.stack([fr["vx"], fr["vy"]], axis=1)
        wv = max(wv, np.abs(eng.v - vref).max() / np.abs(vref).max())
        ww = max(ww, np.abs(eng.w - fr["omegaz"]).max() / np.abs(fr["omegaz"]).max())
    stress = np.concatenate(stress)
    lengths = np.concatenate(lengths)
    np.testing.assert_array_equal(thermo["step"][1 : nsteps + 1], np.arange(1, nsteps + 1))
    ref = np.stack([thermo["sxx"][1 : nsteps + 1], thermo["syy"][1 : nsteps + 1], thermo["sxy"][1 : nsteps + 1]], 1)
    mine = np.stack([stress[:, 0, 0], stress[:, 1, 1], stress[:, 0, 1]], 1)
    rel = np.abs(mine - ref).max(axis=1) / np.abs(ref).max(axis=1)
    dl = np.abs(lengths - np.stack([thermo["lx"], thermo["ly"]], 1)[1 : nsteps + 1]).max() / p.d50
    return wp, wv, ww, rel.max(), dl


def test_setup_masses_forces_and_stress_bit_for_bit():
    # masses pi r^2 rho (set density/disc), set-up forces and stress: only IEEE basic operations in
    # LAMMPS' order, so exactly equal
    thermo = read_thermo(STORED / "log.lammps")
    d0 = read_dump(STORED / "dump.atoms")[0]
    p, s, _, _ = _lammps_case()
    eng = DEMEngine(p, s)
    np.testing.assert_array_equal(d0["mass"], eng.m)
    np.testing.assert_allclose(d0["mass"], np.pi * p.radii**2 * p.density, rtol=1e-15)
    np.testing.assert_array_equal(eng.f[:, 0], d0["fx"])
    np.testing.assert_array_equal(eng.f[:, 1], d0["fy"])
    assert eng.stress[0, 0] == thermo["sxx"][0] and eng.stress[1, 1] == thermo["syy"][0]
    assert eng.stress[0, 1] == thermo["sxy"][0]


def test_stored_lammps_run_step_for_step():
    thermo = read_thermo(STORED / "log.lammps")
    dumps = read_dump(STORED / "dump.atoms")
    p, s, _, n = _lammps_case()
    assert len(thermo["step"]) == n + 1
    np.testing.assert_array_equal(dumps[0]["radius"], p.radii)  # the stored run is this case
    wp, wv, ww, wst, dl = _compare(s, thermo, dumps, n, SHORT_CASE_DUMP_EVERY)
    assert wp < POS_TOL
    assert wv < STRESS_TOL and ww < STRESS_TOL
    assert wst < STRESS_TOL
    assert dl < POS_TOL


def test_flavours_differ_and_liggghts_flavour_misses_lammps():
    # the option is not a no-op: on the same case the LIGGGHTS arithmetic is far outside the
    # tolerance against LAMMPS (lever arms, the Coulomb cap), and LAMMPS' far from LIGGGHTS
    n = 500
    _, s_lig, _, _ = short_case()
    s_lmp = dataclasses.replace(s_lig, flavour="lammps")
    for settings, stored, log in ((s_lig, STORED, "log.lammps"), (s_lmp, STORED_LIGGGHTS, "log.liggghts")):
        thermo = read_thermo(stored / log)
        dumps = read_dump(stored / "dump.atoms")
        wp, _, _, wst, _ = _compare(settings, thermo, dumps, n, SHORT_CASE_DUMP_EVERY)
        assert wst > 1e-5
        assert wp > 1e-6


@pytest.mark.skipif(shutil.which("lmp") is None, reason="LAMMPS binary lmp not installed")
def test_live_lammps_run_step_for_step(tmp_path):
    p, s, ld, _ = _lammps_case()
    n = 1000
    deck = write_biaxial_deck(tmp_path, p, s, ld, n, thermo_every=1, dump_every=250, engine="lammps")
    assert deck.name == "in.lammps"
    log = run_deck(deck, "lammps")
    text = Path(log).read_text()
    assert "WARNING" not in text
    wp, wv, ww, wst, dl = _compare(s, read_thermo(log), read_dump(tmp_path / "dump.atoms"), n, 250)
    assert wp < POS_TOL and wst < STRESS_TOL and dl < POS_TOL
    assert wv < STRESS_TOL and ww < STRESS_TOL
    # the same neighbour-list builds: LAMMPS counts those of the run, the engine also its set-up
    builds = int(text.split("Neighbor list builds =")[1].split()[0])
    eng = DEMEngine(p, s)
    eng.advance(ld, n, phase_step0=0, phase_box0=(np.zeros(2), np.diag(p.cell).copy()))
    assert eng.n_rebuilds == builds + 1


def test_lammps_deck_lines(tmp_path):
    p, s, ld, _ = _lammps_case()
    deck = write_biaxial_deck(tmp_path, p, s, ld, 10, engine="lammps").read_text()
    for line in (
        "newton off",
        "atom_modify map array sort 0 0.0",
        "comm_modify mode single vel yes",
        "neigh_modify delay 0 every 1 check yes",
        f"neighbor {s.skin:.17g} bin",
        f"timestep {s.dt:.17g}",
        "pair_style gran/hooke/history 100000 100000 50 50 0.5 1",
        "fix integr all nve/sphere disc",
        f"set group all density/disc {p.density:.17g}",
        "compute pt all pressure NULL virial",
        "remap x",
        "thermo_modify format float %.17g",
    ):
        assert line in deck
    # masses: set density/disc must come after read_data (which reads the column as 3D)
    assert deck.index("read_data") < deck.index("set group all density/disc")
    assert deck.index("fix avsx") < deck.index("fix deform")
    with pytest.raises(ValueError, match="engine"):
        write_biaxial_deck(tmp_path, p, s, ld, 10, engine="lamps")


def _pair(ri=1e-3, rj=1.2e-3, overlap=2e-5, vty=0.0, wi=0.0):
    d = ri + rj - overlap
    return d, {
        "delx": d,
        "dely": 0.0,
        "rsq": d * d,
        "radi": ri,
        "radj": rj,
        "vix": 0.0,
        "viy": vty,
        "vjx": 0.0,
        "vjy": 0.0,
        "wi": wi,
        "wj": 0.0,
        "mi": 8e-3,
        "mj": 1.2e-2,
    }


def _call(law, kw, kn=1e5, kt=1e5, gn=0.0, gt=0.0, mu=0.5, dt=1e-5, s0=0.0, s1=0.0, update=True):
    return law(
        kw["delx"],
        kw["dely"],
        kw["rsq"],
        kw["radi"],
        kw["radj"],
        kw["vix"],
        kw["viy"],
        kw["vjx"],
        kw["vjy"],
        kw["wi"],
        kw["wj"],
        kw["mi"],
        kw["mj"],
        kn,
        kt,
        gn,
        gt,
        mu,
        dt,
        s0,
        s1,
        update,
    )


def test_lammps_coulomb_cap_includes_tangential_damping():
    # pair along x, i sliding along y at vty: spring after one step kt vty dt = 0.1 N < mu F_n = 1 N,
    # damping meff gt vty = 0.96 N: LAMMPS caps spring + damping (1.06 N > 1 N), LIGGGHTS only the
    # spring (no cap, |F_t| = 1.06 N)
    kn, kt, mu, dt, gt = 1e5, 1e5, 0.5, 1e-5, 2000.0
    ri, rj, ov, vty = 1e-3, 1.2e-3, 2e-5, 1e-1
    _, kw = _pair(ri, rj, ov, vty=vty)
    meff = 8e-3 * 1.2e-2 / (8e-3 + 1.2e-2)
    fn = kn * ov  # 2 N, no normal motion
    fx, fy, ti, tj, s0, s1, sliding, fnorm = _call(hooke_history_lammps, kw, kn, kt, 0.0, gt, mu, dt)
    assert sliding
    assert math.isclose(fnorm, fn, rel_tol=1e-12)
    assert math.isclose(fx, fn, rel_tol=1e-12)
    assert math.isclose(fy, -mu * fn, rel_tol=1e-12)  # capped: |F_t| = mu F_n
    # the spring that gives the capped force with the damping: xi = (mu F_n - meff gt v)/kt
    assert math.isclose(s1, (mu * fn - meff * gt * vty) / kt, rel_tol=1e-12)
    assert s0 == 0.0
    # torques with the full radii, same sign on both: -r (n x F_t)_z
    assert math.isclose(ti, ri * mu * fn, rel_tol=1e-12)
    assert math.isclose(tj, rj * mu * fn, rel_tol=1e-12)
    # LIGGGHTS on the same pair: spring alone below the cap, force = spring + damping
    fx, fy, ti, tj, s0, s1, sliding, _ = _call(hooke_history, kw, kn, kt, 0.0, gt, mu, dt)
    assert not sliding
    assert math.isclose(fy, -(kt * vty * dt + meff * gt * vty), rel_tol=1e-12)
    assert math.isclose(s1, vty * dt, rel_tol=1e-12)


def test_lammps_lever_arm_is_the_radius():
    # pure spin of i: v_t,rel = -r_i w_i in LAMMPS (LIGGGHTS: -(r_i - delta/2) w_i)
    kt, dt, wi, ri, ov = 1e5, 1e-5, 10.0, 1e-3, 2e-5
    _, kw = _pair(ri=ri, overlap=ov, wi=wi)
    *_, s1, sliding, _ = _call(hooke_history_lammps, kw, kt=kt, dt=dt)
    assert not sliding
    assert math.isclose(s1, -ri * wi * dt, rel_tol=1e-12)
    *_, s1, _, _ = _call(hooke_history, kw, kt=kt, dt=dt)
    assert math.isclose(s1, -(ri - 0.5 * ov) * wi * dt, rel_tol=1e-12)


def test_lammps_spring_reset_when_a_pair_opens():
    # one list entry whose disks do not touch, with a stored spring: LAMMPS zeroes it
    # (PairGranHookeHistory::compute), LIGGGHTS keeps it until the next list build
    x = np.array([[0.0, 0.0], [2.5e-3, 0.0]])
    r = np.array([1e-3, 1e-3])
    for lammps, expect in ((True, 0.0), (False, 3e-7)):
        xi = np.array([[0.0, 3e-7]])
        args = (
            x,
            np.zeros((2, 2)),
            np.zeros(2),
            r,
            np.ones(2),
            np.array([0], np.int32),
            np.array([1], np.int32),
            np.zeros(1),
            np.zeros(1),
            np.ones(1, np.bool_),
            xi,
            1.0,
            1.0,
            1e5,
            1e5,
            0.0,
            0.0,
            0.5,
            1e-6,
            True,
            np.zeros((2, 2)),
            np.zeros(2),
            np.zeros(4),
            np.zeros(1, np.bool_),
            np.zeros((1, 2)),
            True,
        )
        nc, _ = K.forces_half(*args, lammps)
        assert nc == 0.0
        assert xi[0, 1] == expect


def test_flavour_option_checked_and_recorded():
    with pytest.raises(InputError, match="flavour"):
        DEMSettings(flavour="lamps")
    assert DEMSettings().to_dict()["flavour"] == "liggghts"
    assert DEMSettings(flavour="lammps").to_dict()["flavour"] == "lammps"


def test_resume_with_another_flavour_refused(tmp_path):
    p = lattice_packing(8, 8, seed=2, spread=0.1, compression=0.04)
    _, s, ld, _ = short_case()
    out = tmp_path / "run.h5"
    phases = [Phase("load", ld, 200)]
    run_phases(p, s, phases, out, stop_at_step=100, show_progress=False)
    with pytest.raises(InputError, match="flavour = 'lammps' differs from flavour = 'liggghts'"):
        run_phases(p, dataclasses.replace(s, flavour="lammps"), phases, out, resume=True, show_progress=False)
    # the same flavour resumes
    run_phases(p, s, phases, out, resume=True, show_progress=False)
