"""Hertz-Mindlin laws of gransim.contacts.hertz: potential, Mindlin stiffness, impact theory,
restitution, and bit-for-bit agreement with LIGGGHTS 3.8.0 and LAMMPS 29Sep2021 (stored runs,
reference_runs/stored/hertz-*/README.md; live runs when the binaries are installed)."""

from __future__ import annotations

import math
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gransim.contacts import hertz
from gransim.contacts.material import (
    HertzLiggghts,
    HertzMaterialLammps,
    beta_liggghts,
    effective_shear,
    effective_youngs,
    tsuji_alpha_lammps,
)
from gransim.errors import InputError
from reference_runs.decks import hertz as decks

sys.path.insert(0, str(Path(__file__).parent))
import hertz_replay

ROOT = Path(__file__).resolve().parents[2]
STORED = {
    "liggghts": ROOT / "reference_runs/stored/hertz-liggghts",
    "gran-hertz-history": ROOT / "reference_runs/stored/hertz-lammps/gran-hertz-history",
    "granular": ROOT / "reference_runs/stored/hertz-lammps/granular",
}

E, NU = 7.0e8, 0.3
R1, R2 = 1.0e-3, 0.8e-3
M1, M2 = 7.85e-5, 5.0e-5
REFF = R1 * R2 / (R1 + R2)
MEFF = M1 * M2 / (M1 + M2)
Y = effective_youngs(E, NU, E, NU)
G = effective_shear(E, NU, E, NU)


def _laws(e=1.0, mu=0.5):
    """The three laws, undamped when e = 1 (LAMMPS gran/hertz/history: gamma 0), as
    (name, function, parameters)."""
    lig = HertzLiggghts(E, NU, e, mu).coefficients()
    ghh = (4.0 / 3.0 * Y, 8.0 * G, 0.0, 0.0, mu)
    gra = HertzMaterialLammps(E, NU, 0.0, mu, damping="viscoelastic").coefficients()
    return [
        ("liggghts", hertz.hertz_history_liggghts, lig),
        ("gran-hertz-history", hertz.hertz_history_lammps, ghh),
        ("granular", hertz.hertz_mindlin_granular_lammps, gra),
    ]


def _call(f, params, delta, vt=0.0, vn=0.0, dt=1e-7, s=(0.0, 0.0), update=True, ang=0.3):
    """Pair along n = (cos ang, sin ang) with overlap delta; j moves with relative tangential
    velocity vt (along t = (-sin, cos)) and normal velocity vn (v_i - v_j = vn n + vt t)."""
    r = R1 + R2 - delta
    n = (math.cos(ang), math.sin(ang))
    t = (-n[1], n[0])
    vi = (vn * n[0] + vt * t[0], vn * n[1] + vt * t[1])
    return f(
        r * n[0], r * n[1], r * r, R1, R2, vi[0], vi[1], 0.0, 0.0, 0.0, 0.0, M1, M2, *params, dt, s[0], s[1], update
    )


def test_effective_properties_and_bad_inputs():
    # identical materials: Y* = E/(2(1-nu^2)), G* = G/(2(2-nu)) with G = E/(2(1+nu)) (Johnson 1985)
    assert Y == pytest.approx(E / (2 * (1 - NU * NU)), rel=1e-15)
    assert G == pytest.approx(E / (2 * (1 + NU)) / (2 * (2 - NU)), rel=1e-15)
    assert beta_liggghts(1.0) == 0.0
    # LIGGGHTS' beta inverts the linear-oscillator restitution e = exp(pi beta/sqrt(1 - beta^2))
    for e in (0.1, 0.5, 0.9):
        b = beta_liggghts(e)
        assert math.exp(math.pi * b / math.sqrt(1 - b * b)) == pytest.approx(e, rel=1e-14)
    with pytest.raises(InputError, match="coefficientRestitution"):
        HertzLiggghts(E, NU, 0.01, 0.3)
    with pytest.raises(InputError, match="poissonsRatio"):
        HertzLiggghts(E, 0.7, 0.5, 0.3)
    with pytest.raises(InputError, match="youngsModulus"):
        HertzLiggghts(-1.0, 0.3, 0.5, 0.3)
    with pytest.raises(InputError, match="coefficientFriction"):
        HertzLiggghts(E, 0.3, 0.5, -0.1)
    with pytest.raises(InputError, match="damping"):
        HertzMaterialLammps(E, 0.3, 0.5, 0.3, damping="coeff_restitution")
    with pytest.raises(InputError, match="DAMP"):
        HertzMaterialLammps(E, 0.3, 1.5, 0.3, damping="tsuji")


@pytest.mark.parametrize("name", ["liggghts", "gran-hertz-history", "granular"])
def test_normal_force_is_gradient_of_hertz_potential(name):
    """F_n = dU/d delta with U = 8/15 Y* sqrt(R*) delta^(5/2) (central differences, h = 1e-4 delta:
    truncation ~1e-8 relative), and dF_n/d delta = 2 Y* sqrt(R* delta) (the S_n of LIGGGHTS'
    damping)."""
    _, f, p = next(x for x in _laws() if x[0] == name)
    for delta in (1e-7, 3e-6, 2e-5):
        fn = _call(f, p, delta, update=False)[7]
        h = 1e-4 * delta
        dU = (
            hertz.elastic_normal_potential(delta + h, REFF, Y) - hertz.elastic_normal_potential(delta - h, REFF, Y)
        ) / (2 * h)
        assert fn == pytest.approx(dU, rel=1e-7)
        dF = (_call(f, p, delta + h, update=False)[7] - _call(f, p, delta - h, update=False)[7]) / (2 * h)
        assert dF == pytest.approx(2 * Y * math.sqrt(REFF * delta), rel=1e-7)


@pytest.mark.parametrize("name", ["liggghts", "gran-hertz-history", "granular"])
def test_tangential_spring_is_mindlin_stiffness(name):
    """From xi = 0, one step of relative tangential velocity vt gives F_t = -8 G* a vt dt
    (Mindlin 1949 initial stiffness, a = sqrt(R* delta)), undamped, below the Coulomb cap; the
    increment is linear in xi (two steps: twice the force) and the spring holds xi = vt dt t."""
    _, f, p = next(x for x in _laws() if x[0] == name)
    delta, vt, dt, ang = 5e-6, 0.01, 1e-7, 0.3
    t = np.array([-math.sin(ang), math.cos(ang)])
    kt = 8 * G * math.sqrt(REFF * delta)
    out = _call(f, p, delta, vt=vt, dt=dt, ang=ang)
    assert not out[6]
    ft = np.array(out[:2]) - out[7] * np.array([math.cos(ang), math.sin(ang)])
    assert ft @ t == pytest.approx(-kt * vt * dt, rel=1e-9)
    assert abs(ft @ np.array([math.cos(ang), math.sin(ang)])) < 1e-12 * abs(ft @ t)
    assert np.array(out[4:6]) == pytest.approx(vt * dt * t, rel=1e-12)
    two = _call(f, p, delta, vt=vt, dt=dt, s=out[4:6], ang=ang)
    ft2 = np.array(two[:2]) - two[7] * np.array([math.cos(ang), math.sin(ang)])
    assert ft2 @ t == pytest.approx(2 * (ft @ t), rel=1e-9)
    # above the cap the tangential force is mu |F_n|
    big = _call(f, p, delta, vt=1e3, dt=dt, ang=ang)
    assert big[6]
    ftb = np.array(big[:2]) - big[7] * np.array([math.cos(ang), math.sin(ang)])
    assert np.linalg.norm(ftb) == pytest.approx(0.5 * abs(big[7]), rel=1e-12)


def _head_on(f, p, v0, dt):
    """Head-on impact of the two disks (no spin), velocity Verlet with the law (nve/sphere order):
    returns (restitution, max overlap, contact time, max relative energy error during contact)."""
    x1, x2 = 0.0, R1 + R2
    v1, v2 = v0 * M2 / (M1 + M2), -v0 * M1 / (M1 + M2)
    F = 0.0
    e0 = 0.5 * M1 * v1 * v1 + 0.5 * M2 * v2 * v2
    dmax, t_in, t_out, step, err = 0.0, None, None, 0, 0.0
    while t_out is None:
        step += 1
        v1 += 0.5 * dt * F / M1
        v2 -= 0.5 * dt * F / M2
        x1 += dt * v1
        x2 += dt * v2
        d = x1 - x2
        delta = R1 + R2 - abs(d)
        if delta > 0:
            t_in = step * dt if t_in is None else t_in
            F = f(d, 0.0, d * d, R1, R2, v1, 0.0, v2, 0.0, 0.0, 0.0, M1, M2, *p, dt, 0.0, 0.0, True)[0]
            dmax = max(dmax, delta)
        else:
            F = 0.0
            if t_in is not None:
                t_out = step * dt
        v1 += 0.5 * dt * F / M1
        v2 -= 0.5 * dt * F / M2
        if delta > 0:
            ek = 0.5 * M1 * v1 * v1 + 0.5 * M2 * v2 * v2
            err = max(err, abs(ek + hertz.elastic_normal_potential(delta, REFF, Y) - e0) / e0)
    return (v2 - v1) / v0, dmax, t_out - t_in, err


@pytest.mark.parametrize("name", ["liggghts", "gran-hertz-history", "granular"])
def test_undamped_impact_against_hertz_theory(name):
    """Undamped head-on impact: restitution 1 and energy conserved to O(dt^2) (halving dt divides
    the error by about 4), peak overlap delta_max = (15 m* v^2/(16 Y* sqrt(R*)))^(2/5) and contact
    time t_c = 2 (delta_max/v) int_0^1 (1 - x^(5/2))^(-1/2) dx = 2.943 delta_max/v (Hertz theory
    with m* the disk effective mass: both codes apply the sphere law to disks; 2.87 (m*^2/(R* Y*^2
    v))^(1/5) in the brief's form). Tolerances: the discretisation, measured with dt = t_c/400."""
    _, f, p = next(x for x in _laws() if x[0] == name)
    v0 = 1.0
    dth = (15 * MEFF * v0**2 / (16 * Y * math.sqrt(REFF))) ** 0.4
    tc = 2 * dth / v0 * 0.4 * math.gamma(0.4) * math.gamma(0.5) / math.gamma(0.9)
    assert tc == pytest.approx(2.87 * (MEFF**2 / (REFF * Y**2 * v0)) ** 0.2, rel=2e-3)
    res = [_head_on(f, p, v0, tc / n) for n in (400, 800)]
    for (e, dmax, t, err), n in zip(res, (400, 800)):
        assert abs(e - 1) < 40.0 / n**2
        assert err < 40.0 / n**2
        assert dmax == pytest.approx(dth, rel=1e-4)
        assert t == pytest.approx(tc, abs=2 * tc / n)
    ratio = res[0][3] / res[1][3]
    assert 3.0 < ratio < 5.0


def _restitution_ode(alpha):
    """Restitution of x'' + alpha x^(1/4) x' + x^(3/2) = 0, x(0) = 0, x'(0) = 1 (the Hertz
    contact with damping coefficient alpha sqrt(m* K) delta^(1/4), K = 4/3 Y* sqrt(R*), made
    dimensionless: e depends on alpha alone); DOP853 at rtol 1e-12."""

    def rhs(_, y):
        x = max(y[0], 0.0)
        return [y[1], -(x**1.5) - alpha * x**0.25 * y[1]]

    def out(_, y):
        return y[0]

    out.terminal, out.direction = True, -1
    sol = solve_ivp(rhs, (0.0, 50.0), [0.0, 1.0], events=out, rtol=1e-12, atol=1e-14, method="DOP853")
    return -sol.y_events[0][0][1]


E_GRID = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95)


def test_liggghts_restitution_is_the_requested_one():
    """LIGGGHTS' gamma_n = -2 sqrt(5/6) beta sqrt(S_n m*) is alpha = -sqrt(5) beta in the
    dimensionless equation; the restitution it gives equals coefficientRestitution over
    e in [0.3, 0.95] to the ODE solver's accuracy (measured 1e-11), and the law itself in a
    velocity-Verlet loop (dt = t_c/2000) gives it to O(dt) (measured 1.5e-5 at e = 0.3)."""
    for e in E_GRID:
        assert _restitution_ode(-math.sqrt(5.0) * beta_liggghts(e)) == pytest.approx(e, abs=1e-9)
    v0 = 1.0
    dth = (15 * MEFF * v0**2 / (16 * Y * math.sqrt(REFF))) ** 0.4
    for e in (0.3, 0.6, 0.9):
        p = HertzLiggghts(E, NU, e, 0.5).coefficients()
        got = _head_on(hertz.hertz_history_liggghts, p, v0, 3 * dth / v0 / 2000)[0]
        assert got == pytest.approx(e, abs=1e-4)


def test_lammps_tsuji_restitution_is_the_polynomial_one():
    """LAMMPS ``damping tsuji`` with DAMP = e uses alpha(e) of its polynomial on sqrt(m* E a),
    the same dimensionless equation: the law reproduces the ODE's restitution for alpha(e)
    (dt = t_c/2000, O(dt)), and that restitution is *not* e: it is higher by 0.14 at e = 0.3 and
    0.015 at e = 0.95 (docs/laws.md); LIGGGHTS' alpha = -sqrt(5) beta(e) does give e."""
    v0 = 1.0
    dth = (15 * MEFF * v0**2 / (16 * Y * math.sqrt(REFF))) ** 0.4
    for e in (0.3, 0.6, 0.9):
        p = HertzMaterialLammps(E, NU, e, 0.5, damping="tsuji").coefficients()
        got = _head_on(hertz.hertz_mindlin_granular_lammps, p, v0, 3 * dth / v0 / 2000)[0]
        assert got == pytest.approx(_restitution_ode(tsuji_alpha_lammps(e)), abs=1e-4)
    dev = [_restitution_ode(tsuji_alpha_lammps(e)) - e for e in E_GRID]
    assert min(dev) > 0.01


def _compare(law, dump_path):
    d = decks.read_impact_dump(dump_path)
    case = decks.impact_case()
    masses = d[0]["mass"]
    # the codes' masses are pi r^2 rho (LIGGGHTS 2D data; LAMMPS set density/disc)
    assert masses == pytest.approx(math.pi * np.array(case["radii"]) ** 2 * case["density"], rel=1e-15)
    rep = hertz_replay.replay(law, case, list(masses))
    assert sorted(d) == list(range(case["nsteps"] + 1))
    touching = sliding = 0
    for step, fr in d.items():
        for k in ("x", "y", "vx", "vy", "omegaz", "fx", "fy", "tqz"):
            assert np.array_equal(fr[k], np.array(rep[step][k])), (law, step, k)
        touching += fr["fx"][0] != 0.0
        sliding += rep[step]["sliding"]
    # the run exercises the contact, its sticking and its sliding phases
    assert touching > 100 and 0 < sliding < touching


@pytest.mark.parametrize("law", list(decks.LAWS))
def test_bit_for_bit_with_stored_run(law):
    """The test-local integrator with the native law reproduces every step of the stored run
    (positions, velocities, spins, forces, torques: exactly, 0 difference)."""
    _compare(law, STORED[law] / decks.DUMP_NAME)


@pytest.mark.parametrize("law", list(decks.LAWS))
def test_bit_for_bit_with_live_binary(law, tmp_path):
    """The same against a fresh run of the installed binary (skipped without it); the stored deck
    is the one the writer writes today."""
    engine = decks.LAWS[law][0]
    if shutil.which("liggghts" if engine == "liggghts" else "lmp") is None:
        pytest.skip(f"{engine} binary not installed")
    res = decks.run_impact(tmp_path / law, law)
    assert (STORED[law] / decks.LAWS[law][1]).read_text() == decks.deck_text(decks.impact_case(), law)
    _compare(law, res.path(decks.DUMP_NAME))
