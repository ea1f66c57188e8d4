"""The sheared-cell engine's box origin, its xy styles (erate, trate, vel, final, delta), fix deform N > 1
and the per-step virial (gransim.dem.sheared). LAMMPS' own numbers for these are checked in
tests/replay/test_replay_tilt.py (tilt, every style and N) and tests/replay/test_replay_shear.py
(decks with contacts: trate with N = 2, vel with N = 3)."""

import math

import numpy as np
import pytest

from gransim.dem.sheared import ShearEngine, ShearLoading, simple_shear
from gransim.errors import InputError
from reference_runs.decks.shear import short_case

N = 120


@pytest.fixture(scope="module")
def case():
    p, s, _, _ = short_case("constant-volume")
    return p, s


def test_box_origin_is_used_as_given(case):
    p, s = case
    lo = np.array([0.25, -0.0417])
    cell = p.cell.copy()
    cell[0, 1] = 1.5e-3
    q = p.replace(positions=p.positions + lo, cell=cell)
    box = (lo, lo + np.diag(cell), 1.5e-3)
    eng = ShearEngine(q, s, box=box)
    assert eng.box.tolist() == [0.25, -0.0417, 0.25 + 0.02, -0.0417 + cell[1, 1], 1.5e-3]
    # the same physics as the cell at the origin: positions follow the translated run to round-off
    ref = ShearEngine(p.replace(cell=cell), s)
    ld = ShearLoading(erate=2.5)
    eng.start_run(ld, 400)
    ref.start_run(ld, 400)
    a, b = eng.advance(400), ref.advance(400)
    d = eng.x - lo - ref.x
    lam = np.linalg.solve(eng.cell, d.T).T
    d -= np.round(lam) @ eng.cell.T
    assert np.abs(d).max() < 1e-10 * p.d50
    np.testing.assert_allclose(a["stress"], b["stress"], rtol=0, atol=1e-8 * np.abs(b["stress"]).max())
    assert eng.box[0] == 0.25 and eng.box[1] == -0.0417  # the origin stays (y fixed)


@pytest.mark.parametrize(
    "which, match",
    [
        ("long", "differs from the cell's side lengths"),
        ("tilt", "differs from the cell's tilt"),
        ("short", "expected \\(lo, hi\\) or \\(lo, hi, xy\\)"),
        ("nan", "expected finite lo < hi"),
    ],
)
def test_bad_box_is_refused(case, which, match):
    p, s = case
    lo, hi = np.zeros(2), np.diag(p.cell).copy()
    box = {
        "long": (lo, hi + [0.01, 0.0]),
        "tilt": (lo, hi, 1e-3),
        "short": (lo[:1], hi),
        "nan": (lo, [hi[0], float("nan")]),
    }[which]
    with pytest.raises(InputError, match=match):
        ShearEngine(p, s, box=box)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"xy": "wiggle", "value": 1.0}, "unknown xy style 'wiggle'"),
        ({"xy": "final"}, "value: xy final needs its number \\(m\\)"),
        ({"xy": "vel", "value": 0.1, "erate": 2.0}, "erate: only for xy erate"),
        ({"erate": 2.0, "value": 3.0}, "xy erate given twice"),
        ({"erate": 2.0, "every": 0}, "every: expected an integer >= 1"),
        ({"xy": "delta", "value": "far"}, "value: expected a number"),
    ],
)
def test_loading_styles_reject_bad_values(kwargs, match):
    with pytest.raises(InputError, match=match):
        ShearLoading(**kwargs)


def test_trate_needs_a_tilt(case):
    p, s = case
    with pytest.raises(InputError, match="xy trate on a cell without tilt"):
        ShearEngine(p, s).start_run(ShearLoading(xy="trate", value=10.0), 10)


def test_advance_returns_the_per_step_virial(case):
    p, s = case
    eng = ShearEngine(p, s)
    eng.start_run(ShearLoading(erate=2.5, y="servo", target=1000.0, gain=1e-2), 300)
    out = eng.advance(300)
    vir = out["virial"]
    assert vir.shape == (300, 4) and np.all(vir[:, 0] > 0)
    np.testing.assert_array_equal(vir[-1], eng.virial)
    # the stress of a step is its virial times 1/area of the box after the step, bit for bit
    inv = 1.0 / (out["box"][:, 0] * out["box"][:, 1])
    np.testing.assert_array_equal(out["stress"][:, 0, 0], vir[:, 0] * inv)
    np.testing.assert_array_equal(out["stress"][:, 1, 1], vir[:, 1] * inv)
    np.testing.assert_array_equal(out["stress"][:, 0, 1], vir[:, 2] * inv)
    np.testing.assert_array_equal(out["stress"][:, 1, 0], vir[:, 3] * inv)
    assert np.unique(out["box"][:, 1]).size > 10  # the servo moves y, so the area matters


@pytest.mark.parametrize("every", [2, 3, 7])
def test_fix_deform_n_changes_the_box_on_multiples_of_n_only(case, every):
    p, s = case
    n = 210
    one = simple_shear(p, s, ShearLoading(erate=2.5), n)
    ev = simple_shear(p, s, ShearLoading(erate=2.5, every=every), n)
    xy1, xyn = one["box"][:, 2], ev["box"][:, 2]
    steps = ev["step"]
    on = steps % every == 0
    # a linear style's tilt depends only on the step: equal bit for bit where the box changes, held
    # (the value of the last change) in between; h_rate is the constant of init in both
    np.testing.assert_array_equal(xyn[on], xy1[on])
    last = np.where(on, steps, (steps // every) * every)
    held = np.concatenate([[0.0], xy1])[last]
    np.testing.assert_array_equal(xyn, held)
    assert ev["engine"].h_rate[2] == one["engine"].h_rate[2] == pytest.approx(2.5 * p.cell[1, 1], rel=1e-13)
    # the runs differ (the images move with h_rate while the box waits)
    assert np.abs(ev["stress"] - one["stress"]).max() > 1e-9 * np.abs(one["stress"]).max()


def test_trate_tilt_and_h_rate_follow_lammps_end_of_step(case):
    p, s = case
    cell = p.cell.copy()
    cell[0, 1] = 2e-3
    q = p.replace(cell=cell)
    rate, every, n = 40.0, 4, 120
    eng = ShearEngine(q, s)
    eng.start_run(ShearLoading(xy="trate", value=rate, every=every), n)
    assert eng.h_rate[2] == 0.0  # init cannot set h_rate for trate
    before = eng.box[4]
    for k in range(1, n + 1):
        eng.advance(1)
        if k % every == 0:
            # h_rate[5] = rate * the tilt before the change; the tilt xy0 exp(rate k dt) (then wrapped)
            assert eng.h_rate[2] == rate * before
            assert eng.box[4] == pytest.approx(2e-3 * math.exp(rate * k * s.dt), rel=1e-15, abs=0)
            before = eng.box[4]
        else:
            assert eng.box[4] == before


@pytest.mark.parametrize("style", ["vel", "final", "delta"])
def test_linear_styles_reach_their_end_tilt(case, style):
    p, s = case
    n = 300
    ly = p.cell[1, 1]
    end = 2.5 * n * s.dt * ly  # the tilt of xy erate 2.5 at the end of the run
    value = {"vel": end / (n * s.dt), "final": end, "delta": end}[style]
    out = simple_shear(p, s, ShearLoading(xy=style, value=value), n)
    ref = simple_shear(p, s, ShearLoading(erate=2.5), n)
    assert out["box"][-1, 2] == pytest.approx(end, rel=1e-14)
    np.testing.assert_allclose(out["box"][:, 2], ref["box"][:, 2], rtol=1e-13, atol=1e-18)
    assert out["engine"].h_rate[2] == pytest.approx(end / (n * s.dt), rel=1e-13)
    np.testing.assert_allclose(out["stress"], ref["stress"], rtol=0, atol=1e-9 * np.abs(ref["stress"]).max())


@pytest.mark.lammps
def test_deck_writer_styles_against_live_lammps(case, tmp_path):
    # the shear deck with xy vel and fix deform 3 (and the servo), run by lmp, against the engine
    import shutil

    from reference_runs.decks.shear import read_thermo, run_lammps, write_shear_deck

    if shutil.which("lmp") is None:
        pytest.skip("lmp (LAMMPS) binary not installed")
    p, s = case
    n = 300
    ld = ShearLoading(xy="vel", value=0.05, every=3, y="servo", target=1000.0, gain=1e-2)
    deck = write_shear_deck(tmp_path, p, s, ld, n, thermo_every=1, dump_every=100)
    assert "fix def all deform 3 xy vel 0.050000000000000003 y variable v_dy v_ry remap v" in deck.read_text()
    th = read_thermo(run_lammps(deck))
    out = simple_shear(p, s, ld, n)
    np.testing.assert_array_equal(out["box"][:, 2], th["xy"][1:])
    np.testing.assert_allclose(out["box"][:, 1], th["ly"][1:], rtol=1e-13)
    ref = np.stack([th["sxx"], th["syy"], th["sxy"]], 1)[1:]
    mine = np.stack([out["stress"][:, 0, 0], out["stress"][:, 1, 1], out["stress"][:, 0, 1]], 1)
    assert (np.abs(mine - ref).max(axis=1) / np.abs(ref).max(axis=1)).max() < 1e-8


#: a general velocity gradient of the upper-triangular cell: stretch x, compress y, shear xy
GENERAL = {"x_erate": 1.5, "y": "erate", "y_erate": -2.0, "erate": 2.5}


@pytest.mark.parametrize("remap", ["x", "v"])
def test_general_velocity_gradient_box_follows_fix_deform_init(case, remap):
    # Lx(n) = Lx0 (1 + R_x n dt) and Ly likewise, lo and hi moving by half each (FixDeform::init
    # lo_stop = lo_start - 0.5 delt R L0, end_of_step linear in between); the tilt as xy erate
    p, s = case
    n = 400
    ld = ShearLoading(**GENERAL, remap=remap)
    out = simple_shear(p, s, ld, n)
    t = np.arange(1, n + 1) * s.dt
    lx0, ly0 = p.cell[0, 0], p.cell[1, 1]
    np.testing.assert_allclose(out["box"][:, 0], lx0 * (1 + 1.5 * t), rtol=1e-13)
    np.testing.assert_allclose(out["box"][:, 1], ly0 * (1 - 2.0 * t), rtol=1e-13)
    np.testing.assert_allclose(out["box"][:, 2], 2.5 * ly0 * t, rtol=1e-10)  # delta (stop - start), delta = k/n
    eng = out["engine"]
    if remap == "x":
        # remap x: no velocity jumps, the positions follow the cell (all inside it after a step)
        assert np.all(eng.h_rate == 0.0)
    else:
        # remap v: the image velocity jumps are the box rates
        assert eng.h_rate[0] == pytest.approx(1.5 * lx0, rel=1e-12)
        assert eng.h_rate[1] == pytest.approx(-2.0 * ly0, rel=1e-12)


def test_remap_x_is_lamda_in_the_old_box_then_x_in_the_new(case):
    # remap x (FixDeform::end_of_step): x2lamda with the old box, lamda2x with the new one, the
    # same operations as the rebuild's Domain::x2lamda / lamda2x (bit for bit), and affine
    from gransim.dem import sheared_kernels as SK

    p, _ = case
    rng = np.random.default_rng(3)
    x = p.positions + rng.normal(scale=1e-4, size=p.positions.shape)
    old = np.array([-1e-3, 2e-3, 0.019, 0.0228, 1.5e-3])
    new = np.array([-1.2e-3, 2.1e-3, 0.0193, 0.0226, 1.9e-3])
    got = x.copy()
    SK.remap_positions(got, old, new)
    lam = np.zeros_like(x)
    SK.x2lamda(x, old, lam)
    want = np.zeros_like(x)
    SK.lamda2x(lam, new, want)
    np.testing.assert_array_equal(got, want)
    h_old = np.array([[old[2] - old[0], old[4]], [0.0, old[3] - old[1]]])
    h_new = np.array([[new[2] - new[0], new[4]], [0.0, new[3] - new[1]]])
    affine = (h_new @ np.linalg.solve(h_old, (x - old[:2]).T)).T + new[:2]
    np.testing.assert_allclose(got, affine, rtol=0, atol=1e-15)


def test_general_loading_checks():
    with pytest.raises(InputError, match="y_erate: a y strain rate needs y='erate'"):
        ShearLoading(y_erate=1.0)
    with pytest.raises(InputError, match="unknown remap"):
        ShearLoading(remap="w")


@pytest.mark.lammps
@pytest.mark.parametrize("remap", ["x", "v"])
def test_general_velocity_gradient_against_live_lammps(case, tmp_path, remap):
    # x erate, y erate and xy erate together, remap x (an affine F(t), a material point) or remap
    # v, run by lmp from the deck writer: the box equal, stresses and positions to round-off
    import shutil

    from reference_runs.decks.shear import read_dump, read_thermo, run_lammps, write_shear_deck

    if shutil.which("lmp") is None:
        pytest.skip("lmp (LAMMPS) binary not installed")
    p, s = case
    n = 400
    ld = ShearLoading(**GENERAL, remap=remap)
    deck = write_shear_deck(tmp_path, p, s, ld, n, thermo_every=1, dump_every=200)
    text = deck.read_text()
    assert f"fix def all deform 1 x erate 1.5 y erate -2 xy erate 2.5 remap {remap}" in text
    th = read_thermo(run_lammps(deck))
    dumps = read_dump(tmp_path / "dump.atoms")
    frames = {}

    def keep(e):
        frames[e.step] = e.x.copy()

    out = simple_shear(p, s, ld, n, every=200, callback=keep)
    np.testing.assert_array_equal(out["box"][:, 0], th["lx"][1:])
    np.testing.assert_array_equal(out["box"][:, 1], th["ly"][1:])
    np.testing.assert_array_equal(out["box"][:, 2], th["xy"][1:])
    ref = np.stack([th["sxx"], th["syy"], th["sxy"]], 1)[1:]
    mine = np.stack([out["stress"][:, 0, 0], out["stress"][:, 1, 1], out["stress"][:, 0, 1]], 1)
    assert (np.abs(mine - ref).max(axis=1) / np.abs(ref).max(axis=1)).max() < 1e-8
    for step, x in frames.items():
        fr = dumps[step]
        d = x - np.stack([fr["x"], fr["y"]], 1)
        cell = np.array([[th["lx"][step], th["xy"][step]], [0.0, th["ly"][step]]])
        lam = np.linalg.solve(cell, d.T).T
        assert np.abs(d - np.round(lam) @ cell.T).max() < 1e-10 * p.d50
