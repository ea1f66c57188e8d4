"""True periodic simple shear (gransim.dem.sheared): the sheared cell with LAMMPS' ``remap v``
(Lees-Edwards) convention, step for step against LAMMPS 29 Sep 2021, and its physics.

Stored reference: reference_runs/stored/shear-short-lammps (README: provenance). Tolerances (those
of every step-for-step comparison, docs/validation.md): positions within 1e-10 D50, stress within
1e-8 relative (of the largest component at that step). Measured on this machine over the 3000
steps: constant volume 2.5e-13 D50 / 3.1e-13, servo 7e-14 D50 / 1.3e-13 (summation order of the
neighbour list differs from LAMMPS').
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from gransim.dem import DEMEngine, DEMSettings, Loading
from gransim.dem import sheared_kernels as SK
from gransim.dem.sheared import ShearEngine, ShearLoading, simple_shear
from gransim.errors import InputError
from gransim.geometry import Packing
from reference_runs.decks.shear import (
    SHORT_CASES,
    SHORT_DUMP_EVERY,
    read_dump,
    read_thermo,
    run_lammps,
    short_case,
    write_shear_deck,
)

STORED = Path(__file__).resolve().parents[2] / "reference_runs" / "stored" / "shear-short-lammps"
POS_TOL = 1e-10  # of D50
STRESS_TOL = 1e-8  # relative


def _reduce(d, cell):
    """d minus the nearest lattice vector of ``cell`` (columns a1, a2)."""
    lam = np.linalg.solve(cell, d.T).T
    return d - np.round(lam) @ cell.T


def _compare(name, thermo, dumps, nsteps, dump_every):
    p, s, ld, _ = short_case(name)
    frames = {}

    def keep(e):
        frames[e.step] = (e.x.copy(), e.v.copy(), e.cell)

    out = simple_shear(p, s, ld, nsteps, every=dump_every, callback=keep)
    np.testing.assert_array_equal(thermo["step"][: nsteps + 1], np.arange(nsteps + 1))
    ref = np.stack([thermo["sxx"], thermo["syy"], thermo["sxy"]], 1)[: nsteps + 1]
    st = np.concatenate([out["setup_stress"][None], out["stress"]])
    mine = np.stack([st[:, 0, 0], st[:, 1, 1], st[:, 0, 1]], 1)
    stress = (np.abs(mine - ref).max(axis=1) / np.abs(ref).max(axis=1)).max()
    box = np.stack([thermo["lx"], thermo["ly"], thermo["xy"]], 1)[1 : nsteps + 1]
    dbox = np.abs(out["box"][:, :3] - box).max() / p.d50
    pos = vel = 0.0
    for step, (x, v, cell) in frames.items():
        fr = dumps[step]
        pos = max(pos, np.abs(_reduce(x - np.stack([fr["x"], fr["y"]], 1), cell)).max() / p.d50)
        vel = max(vel, np.abs(v - np.stack([fr["vx"], fr["vy"]], 1)).max())
    return pos, stress, dbox, vel, out


@pytest.mark.parametrize("name", SHORT_CASES)
def test_stored_lammps_run_step_for_step(name):
    thermo = read_thermo(STORED / name / "log.lammps")
    dumps = read_dump(STORED / name / "dump.atoms")
    p, _, ld, n = short_case(name)
    # the stored run is of this case's assembly (guards against a changed generator)
    assert len(thermo["step"]) == n + 1
    np.testing.assert_array_equal(dumps[0]["radius"], p.radii)
    np.testing.assert_allclose(np.stack([dumps[0]["x"], dumps[0]["y"]], 1), p.positions, rtol=1e-15, atol=0)
    np.testing.assert_array_equal(dumps[0]["mass"], np.pi * p.radii * p.radii * p.density)
    # LAMMPS' set-up maps x -> lamda -> x (Domain::x2lamda/lamda2x), moving some centres by an
    # ulp: the engine's set-up does the same arithmetic, so the positions of step 0 are equal
    eng = ShearEngine(p, short_case(name)[1])
    eng.start_run(ld, n)
    np.testing.assert_array_equal(eng.x, np.stack([dumps[0]["x"], dumps[0]["y"]], 1))
    f0 = np.stack([dumps[0]["fx"], dumps[0]["fy"]], 1)  # summed in another order: round-off
    assert np.abs(eng.f - f0).max() < 1e-13 * np.abs(f0).max()
    pos, stress, dbox, vel, out = _compare(name, thermo, dumps, n, SHORT_DUMP_EVERY)
    assert pos < POS_TOL
    assert stress < STRESS_TOL
    assert dbox < POS_TOL
    assert vel < POS_TOL * p.d50 / (n * 2e-6)  # a position tolerance over the run time
    # the case really shears (1.5% strain) and, with the servo, really moves y
    assert out["shear_strain"][-1] == pytest.approx(0.015, rel=1e-12)
    if ld.y == "servo":
        assert abs(thermo["ly"][-1] - thermo["ly"][0]) > 100 * POS_TOL * p.d50


def test_live_lammps_run_step_for_step(tmp_path):
    if shutil.which("lmp") is None:
        pytest.skip("lmp (LAMMPS) binary not installed")
    p, s, ld, _ = short_case("servo")
    n = 600
    deck = write_shear_deck(tmp_path, p, s, ld, n, thermo_every=1, dump_every=200)
    log = run_lammps(deck)
    pos, stress, dbox, _, _ = _compare("servo", read_thermo(log), read_dump(tmp_path / "dump.atoms"), n, 200)
    assert pos < POS_TOL and stress < STRESS_TOL and dbox < POS_TOL


def test_deck_mirrors_engine_settings(tmp_path):
    p, s, ld, _ = short_case("servo")
    deck = write_shear_deck(tmp_path, p, s, ld, 10).read_text()
    for line in (
        "newton off",
        "atom_modify map array sort 0 0.0",
        "neigh_modify delay 0 every 1 check yes",
        "comm_modify mode single vel yes",
        "change_box all triclinic",
        f"set group all density/disc {p.density:.17g}",
        "fix integr all nve/sphere disc",
        (f"pair_style gran/hooke/history {s.kn:.17g} {s.kt:.17g} {s.gamma_n:.17g} {s.gamma_t:.17g} {s.mu:.17g} 1"),
        "fix def all deform 1 xy erate 2.5 y variable v_dy v_ry remap v",
    ):
        assert line in deck
    # density/disc after read_data (which reads the column as 3D); the servo's stress is a fix
    # ave/time defined before fix deform (evaluated first in end_of_step)
    assert deck.index("read_data") < deck.index("density/disc")
    assert deck.index("fix avsy") < deck.index("fix def ")
    assert f"+{s.dt * ld.gain:.17g}*(f_avsy-(1000))*ly" in deck


# ---------------------------------------------------------------------------------- physics


def _relaxing(p, seed=3):
    rng = np.random.default_rng(seed)
    return 0.05 * rng.standard_normal((p.n, 2)), 20.0 * rng.standard_normal(p.n)


@pytest.mark.parametrize("flavour", ["liggghts", "lammps"])
def test_zero_tilt_reproduces_orthogonal_engine(flavour):
    # a fixed untilted box with random initial velocities: the dense assembly rearranges, lists
    # are rebuilt and particles wrap; the sheared cell must follow the orthogonal engine
    p, s, _, _ = short_case("constant-volume")
    v0, w0 = _relaxing(p)
    if flavour == "lammps":
        if "flavour" not in DEMSettings.__dataclass_fields__:
            pytest.skip("DEMSettings has no flavour (the orthogonal LAMMPS variant is not there)")
        s_orth = DEMSettings(**{**s.to_dict(), "flavour": "lammps"})
    else:
        s_orth = s
    orth = DEMEngine(p, s_orth, velocities=v0, spins=w0)
    shear = ShearEngine(p, s, velocities=v0, spins=w0, flavour=flavour)
    shear.start_run(ShearLoading(), 1500)
    a = orth.advance(Loading(), 1500)
    b = shear.advance(1500)
    assert orth.n_rebuilds > 5 and shear.n_rebuilds == orth.n_rebuilds + 1  # + the run's set-up
    d = _reduce(shear.x - orth.x, shear.cell)
    assert np.abs(d).max() / p.d50 < POS_TOL
    ref = a["stress"].reshape(-1, 4)
    rel = np.abs(b["stress"].reshape(-1, 4) - ref).max(axis=1) / np.abs(ref).max(axis=1)
    assert rel.max() < STRESS_TOL
    np.testing.assert_array_equal(b["n_contacts"], a["n_contacts"])


@pytest.mark.parametrize("name", ["hertz-lammps", "hooke-sds-lammps", "hertz-liggghts", "hooke-epsd2-liggghts"])
def test_zero_tilt_reproduces_orthogonal_engine_with_any_law(name):
    # the sheared cell on a plug-in law (history widths 2-4, flips -1/+1, reset apart or kept):
    # the same rearranging assembly as above with the law of the biaxial short case in its code's
    # bookkeeping must follow the orthogonal engine running that law
    from gransim.contacts.laws import law_code
    from reference_runs.decks.biaxial import short_case_law

    p, s, _, _ = short_case("constant-volume")
    v0, w0 = _relaxing(p)
    law = short_case_law(name)
    code = law_code(name)
    orth = DEMEngine(
        p, DEMSettings(**{**s.to_dict(), "flavour": code}), velocities=v0, spins=w0, law=law, check_dt=False
    )
    shear = ShearEngine(p, s, velocities=v0, spins=w0, flavour=code, law=law, check_dt=False)
    assert shear.xi.shape[1] == orth.xi.shape[1]
    shear.start_run(ShearLoading(), 1000)
    a = orth.advance(Loading(), 1000)
    b = shear.advance(1000)
    assert orth.n_rebuilds > 3 and np.any(shear.xi != 0.0)
    d = _reduce(shear.x - orth.x, shear.cell)
    assert np.abs(d).max() / p.d50 < POS_TOL
    ref = a["stress"].reshape(-1, 4)
    rel = np.abs(b["stress"].reshape(-1, 4) - ref).max(axis=1) / np.abs(ref).max(axis=1)
    assert rel.max() < STRESS_TOL
    np.testing.assert_array_equal(b["n_contacts"], a["n_contacts"])
    assert shear.elastic_energy() == pytest.approx(orth.elastic_energy(), rel=1e-8)


def _gas(n=20, L=0.02, r=2e-5, seed=5):
    rng = np.random.default_rng(seed)
    pos = rng.uniform(0.05 * L, 0.95 * L, (n, 2))
    return Packing(positions=pos, radii=np.full(n, r), cell=np.diag([L, L]), density=2650.0)


def test_gas_under_shear_follows_lees_edwards_images():
    # a non-touching gas in affine shear flow u = (hr5 y/Ly, 0) plus random peculiar velocities:
    # each disk moves ballistically in the infinite sheared lattice, and the cell's state must be
    # that motion seen through the images x - n a1 - m a2, velocity v - m (dxy/dt, 0)
    p = _gas()
    s = DEMSettings(kn=1e-3, kt=1e-3, mu=0.5, dt=2e-6, skin=2e-5)
    erate, nsteps = 50.0, 2000
    L = p.cell[0, 0]
    rng = np.random.default_rng(7)
    V0 = rng.uniform(-1.0, 1.0, (p.n, 2)) * [1.0, 2.5]
    V0[:, 0] += erate * p.positions[:, 1]
    eng = ShearEngine(p, s, velocities=V0)
    eng.start_run(ShearLoading(erate=erate), nsteps)
    out = eng.advance(nsteps)
    assert np.all(out["n_contacts"] == 0) and eng.n_rebuilds > 50
    hr5 = eng.h_rate[2]
    assert hr5 == pytest.approx(erate * L, rel=1e-12)
    t = nsteps * s.dt
    X = p.positions + V0 * t
    cell = eng.cell
    assert cell[0, 1] == pytest.approx(hr5 * t, rel=1e-12)
    # LAMMPS wraps (and the forces see the images) with the box of the step before, fix deform
    # moving it at the end of the step: the images are those of a2(t - dt)
    cell[0, 1] -= hr5 * s.dt
    lam = np.linalg.solve(cell, (X - eng.x).T).T
    n_img = np.round(lam)
    assert np.abs(lam - n_img).max() < 1e-9
    m = n_img[:, 1]
    assert (m > 0).sum() >= 2 and (m < 0).sum() >= 2  # crossings through the top and the bottom
    v_expected = V0 - np.stack([m * hr5, np.zeros(p.n)], 1)
    assert np.abs(eng.v - v_expected).max() < 1e-12
    # momentum: lab momentum changes only by the Lees-Edwards jumps of the crossing disks
    P = (eng.m[:, None] * eng.v).sum(0) + np.array([hr5 * (eng.m * m).sum(), 0.0])
    np.testing.assert_allclose(P, (eng.m[:, None] * V0).sum(0), rtol=1e-12, atol=1e-18)


def test_y_wrap_keeps_peculiar_velocity():
    # LAMMPS' Domain::pbc in lamda with deform_vremap: crossing the top (bottom) of the sheared
    # cell maps x -> x - a2 (x + a2) and v_x -> v_x - h_rate[5] (+): the velocity relative to the
    # shear flow u_x = h_rate[5] (y - ylo)/Ly is kept
    box = np.array([0.0, 0.0, 0.02, 0.021, 0.0013])
    hr = np.array([0.0, 0.0, 0.37])
    x = np.array([[0.011, 0.021 + 3e-7], [0.004, -2e-7], [0.01, 0.01]])
    v = np.array([[0.1, 0.2], [-0.3, -0.1], [0.05, 0.0]])
    pec = v[:, 0] - hr[2] * (x[:, 1] - box[1]) / (box[3] - box[1])
    lam = np.empty_like(x)
    SK.x2lamda(x, box, lam)
    v2 = v.copy()
    assert SK.pbc_lamda(lam, v2, hr, True) == -1
    x2 = np.empty_like(x)
    SK.lamda2x(lam, box, x2)
    pec2 = v2[:, 0] - hr[2] * (x2[:, 1] - box[1]) / (box[3] - box[1])
    np.testing.assert_allclose(pec2, pec, rtol=0, atol=1e-15)
    np.testing.assert_allclose(x2[0], x[0] - [box[4], box[3]], atol=1e-15)
    np.testing.assert_allclose(x2[1], x[1] + [box[4], box[3]], atol=1e-15)
    np.testing.assert_array_equal(v2[2], v[2])  # no crossing, no change
    np.testing.assert_array_equal(v2[:, 1], v[:, 1])  # h_rate[1] = 0: y velocity kept
    # without remap v the velocity is not touched
    v3 = v.copy()
    SK.x2lamda(x, box, lam)
    SK.pbc_lamda(lam, v3, hr, False)
    np.testing.assert_array_equal(v3, v)


def test_constant_volume_shear_builds_shear_stress():
    # positive simple shear of the dense assembly: the cell area stays, sigma_xy (compression
    # positive) turns negative, i.e. a positive shear stress in the tension-positive convention
    p, s, ld, _ = short_case("constant-volume")
    out = simple_shear(p, s, ld, 1500)
    area = out["box"][:, 0] * out["box"][:, 1]
    assert np.all(area == area[0])
    sxy = out["stress"][:, 0, 1]
    assert sxy[-1] < 4 * sxy[0] < 0


# ---------------------------------------------------------------------------------- inputs


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"erate": "fast"}, "erate: expected a number"),
        ({"y": "free"}, "unknown y control 'free'"),
        ({"y": "servo", "target": 10.0}, "gain: the y servo needs a gain > 0"),
        ({"erate": float("nan")}, "erate: expected a finite number"),
    ],
)
def test_loading_rejects_bad_values(kwargs, match):
    with pytest.raises(InputError, match=match):
        ShearLoading(**kwargs)


def test_engine_rejects_bad_inputs():
    p, s, _, _ = short_case("constant-volume")
    L = p.cell[0, 0]
    with pytest.raises(InputError, match="tilt xy .* beyond Lx/2"):
        ShearEngine(p.replace(cell=np.array([[L, 0.6 * L], [0.0, p.cell[1, 1]]])), s)
    with pytest.raises(InputError, match=r"cell\[1, 0\] must be 0"):
        ShearEngine(p.replace(cell=np.array([[L, 0.0], [1e-3, p.cell[1, 1]]])), s)
    with pytest.raises(InputError, match="unknown flavour"):
        ShearEngine(p, s, flavour="pfc")
    with pytest.raises(InputError, match="settings.mode"):
        ShearEngine(p, DEMSettings(**{**s.to_dict(), "mode": "parallel"}))
    with pytest.raises(InputError, match="stability limit"):
        ShearEngine(p, DEMSettings(**{**s.to_dict(), "dt": 1e-3}))
    eng = ShearEngine(p, s)
    with pytest.raises(InputError, match="call start_run"):
        eng.advance(10)
    eng.start_run(ShearLoading(erate=1.0), 20)
    with pytest.raises(InputError, match="the run ends at step 20"):
        eng.advance(21)
    with pytest.raises(InputError, match="only a fixed box"):
        ShearEngine(p, s, flavour="liggghts").start_run(ShearLoading(erate=1.0), 10)
    with pytest.raises(InputError, match="loading: expected a ShearLoading"):
        eng.start_run(Loading(), 10)
