"""The rolling-resistance and flat-wall scenes of the ``impacts`` case (validation/cases/impacts.py,
docs/impacts.md "Rolling resistance", "Flat walls"): the closed forms (R1)-(R3) against an
independent ODE integration, the case failing on a 1% rolling coefficient and on a cut code
output, the energy bound catching a wall that gains energy, and the LAMMPS wall measured live."""

from __future__ import annotations

import math
import shutil

import numpy as np
import pytest

from validation.cases import impacts as I
from validation.core import Context

ROLL = ("roll-epsd2", "roll-epsd", "roll-cdt", "roll-sds")


def _ctx(tmp_path, lammps=False):
    return Context("default", tmp_path / "results", liggghts=False, lammps=lammps)


def _only(monkeypatch, *names):
    orig = I.scenes
    monkeypatch.setattr(I, "scenes", lambda suite="default": [s for s in orig("full") if s.name in names])


def _failed(res, quantity=None):
    return [r for r in res.checks if not r.passed and (quantity is None or r.quantity == quantity)]


def _ode_spin(cst, w0, t_end):
    """(R1)-(R3) integrated as a hybrid ODE (DOP853, rtol 1e-12): elastic I th'' = -(K th + C th'),
    sliding I w' = -sgn M_c, switched by events (the cap reached; the slider re-sticking at w = 0,
    resp. at w_u = C M_c/(I K) for sds); returns a dense w(t) on a grid and the first w = 0."""
    from scipy.integrate import solve_ivp

    K, C, Mc, I_, model = cst["K"], cst["C"], cst["Mc"], cst["I"], cst["model"]
    s = math.copysign(1.0, w0)
    ts, ws, stop = [], [], math.nan
    t, th, w = 0.0, 0.0, abs(w0)
    sliding = model == "cdt" or (model == "sds" and C * w > Mc)
    sg = 1.0
    while t < t_end * (1 - 1e-12):
        if sliding:
            if model == "cdt":
                w_end = 0.0
            else:
                w_end = sg * C * Mc / (I_ * K) if model == "sds" else 0.0
            ev = lambda tt, y, w_end=w_end: y[0] - w_end
            ev.terminal = True
            sol = solve_ivp(
                lambda tt, y, sg=sg: [-sg * Mc / I_],
                (t, t_end),
                [w],
                method="DOP853",
                rtol=1e-12,
                atol=1e-14,
                events=ev,
                dense_output=True,
            )
            grid = np.linspace(t, sol.t[-1], 200)
            ts += list(grid)
            ws += list(sol.sol(grid)[0])
            zero = solve_ivp(
                lambda tt, y, sg=sg: [-sg * Mc / I_],
                (t, t_end),
                [w],
                method="DOP853",
                rtol=1e-12,
                atol=1e-14,
                events=lambda tt, y: y[0],
            )
            if math.isnan(stop) and zero.t_events[0].size and zero.t_events[0][0] <= sol.t[-1] * (1 + 1e-12):
                stop = float(zero.t_events[0][0])
            if model == "cdt" or not sol.t_events[0].size:
                if model == "cdt" and sol.t_events[0].size:
                    ts.append(t_end)
                    ws.append(0.0)
                break
            t, w = float(sol.t_events[0][0]), w_end
            th = (sg * Mc - C * w) / K if model == "sds" else sg * Mc / K
            sliding = False
        else:

            def rhs(tt, y):
                return [y[1], -(K * y[0] + C * y[1]) / I_]

            def cap(tt, y):
                return abs(K * y[0] + (C * y[1] if model == "sds" else 0.0)) - Mc * (1 + 1e-12)

            def turn(tt, y):
                return y[1]

            cap.terminal = True
            sol = solve_ivp(
                rhs,
                (t, t_end),
                [th, w],
                method="DOP853",
                rtol=1e-12,
                atol=1e-15,
                events=(cap, turn),
                dense_output=True,
                max_step=(t_end - t) / 50,
            )
            grid = np.linspace(t, sol.t[-1], 400)
            ts += list(grid)
            ws += list(sol.sol(grid)[1])
            if math.isnan(stop) and sol.t_events[1].size:
                stop = float(sol.t_events[1][0])
            if not sol.t_events[0].size:
                break
            t = float(sol.t_events[0][0])
            th, w = (float(v) for v in sol.y_events[0][0])
            sg = 1.0 if K * th + (C * w if model == "sds" else 0.0) > 0 else -1.0
            sliding = True
    return np.array(ts), s * np.array(ws), stop


@pytest.mark.parametrize("name", ROLL)
def test_spin_decay_closed_form_against_ode(name):
    """The piecewise closed form (damped oscillator, constant-torque slide, brentq switches) equals
    an independent event-driven DOP853 integration of the same equations: w(t) to 1e-7 |w0|, the
    first w = 0 to 1e-7 relative, for every column of the scene."""
    sc = next(s for s in I.rolling_scenes() if s.name == name)
    cst = I.roll_constants(sc.law)
    for sp in sc.spins:
        an = I.spin_decay(cst, sp.w0, sc.t_end)
        t, w, stop = _ode_spin(cst, sp.w0, sc.t_end)
        inside = t < sc.t_end * (1 - 1e-9)
        assert np.max(np.abs(an["w"](t[inside]) - w[inside])) < 1e-7 * abs(sp.w0), (name, sp.label)
        assert stop == pytest.approx(an["stop time"], rel=1e-7), (name, sp.label)


def test_spin_decay_regimes():
    """The regimes (R3) names: epsd2 w0 = 2 stays elastic (w0 < M_c/sqrt(K I_r)) and keeps its
    amplitude; w0 = 10 slides at M_c/I_r and then oscillates with amplitude M_c/sqrt(K I_r); cdt
    stops at |w0| I_r/M_c; sds slides from the start when C w0 > M_c and re-sticks at C M_c/(I_r K)."""
    sc = {s.name: s for s in I.rolling_scenes()}
    c = I.roll_constants(sc["roll-epsd2"].law)
    amp = c["Mc"] / math.sqrt(c["K"] * c["I"])
    assert 2.0 < amp < 10.0
    el = I.spin_decay(c, 2.0, 0.01)
    assert not el["capped"] and np.max(np.abs(el["w"](np.linspace(0, 0.01, 2001)))) == pytest.approx(2.0, rel=1e-5)
    sl = I.spin_decay(c, 10.0, 0.03)
    late = np.linspace(sl["stop time"] + 1e-6, 0.03, 8001)
    assert np.max(np.abs(sl["w"](late))) == pytest.approx(amp, rel=1e-4)
    cd = I.roll_constants(sc["roll-cdt"].law)
    assert I.spin_decay(cd, -6.0, 0.01)["stop time"] == pytest.approx(6.0 * cd["I"] / cd["Mc"], rel=1e-14)
    cs = I.roll_constants(sc["roll-sds"].law)
    an = I.spin_decay(cs, 10.0, 0.01)
    assert an["capped"][0][0] == 0.0 and 10.0 * cs["C"] > cs["Mc"]
    tb = an["capped"][0][1]
    assert an["w"](np.array([tb]))[0] == pytest.approx(cs["C"] * cs["Mc"] / (cs["I"] * cs["K"]), rel=1e-12)


def test_rolling_and_wall_scenes_pass_on_stored_outputs(tmp_path, monkeypatch):
    _only(monkeypatch, *ROLL, "wall-lammps", "wall-liggghts", "grazing")
    res = I.impacts(_ctx(tmp_path))
    assert res.error is None
    assert res.passed, [(r.case, r.quantity, r.metric, r.value) for r in _failed(res)]
    for pair in ("native-liggghts", "native-lammps"):
        assert res.pair_checks(pair)
    qs = {r.quantity for r in res.checks if r.pair == ""}
    assert {"spin trajectory", "stop time", "deceleration", "energy gain"} <= qs
    assert any("PR #5007" in r.quantity for r in res.records)


@pytest.mark.parametrize(
    ("scene", "key", "field"),
    [("roll-epsd2", "mu_r", "mu_r"), ("roll-sds", "muroll", "muroll"), ("roll-cdt", "mu_r", "mu_r")],
)
def test_fails_when_rolling_coefficient_is_off_by_one_percent(tmp_path, monkeypatch, scene, key, field):
    """1% in the rolling coefficient of the native law: the deceleration (1e-2 > 1e-9) and the
    step-for-step comparison with the code fail."""
    _only(monkeypatch, scene)
    orig = I.native_roll_law
    monkeypatch.setattr(I, "native_roll_law", lambda law: orig(law)._replace(**{field: 1.01 * law.p[key]}))
    res = I.impacts(_ctx(tmp_path))
    assert not res.passed
    assert _failed(res, "deceleration")
    assert [r for r in _failed(res) if r.pair.startswith("native-")]


@pytest.mark.parametrize(
    ("scene", "code"), [("roll-epsd", "liggghts"), ("roll-sds", "lammps"), ("wall-lammps", "lammps")]
)
def test_truncated_code_output_fails_as_incomplete(tmp_path, monkeypatch, scene, code):
    """A dump cut in half: the evidence record fails as incomplete and the code's analytic records
    are NaN (failures), never a pass on the frames that remain."""
    from reference_runs import store

    _only(monkeypatch, scene)
    dest = tmp_path / "stored"
    shutil.copytree(store.STORED / f"impacts-{code}" / scene, dest / f"impacts-{code}" / scene)
    dump = dest / f"impacts-{code}" / scene / "dump.atoms"
    lines = dump.read_text().splitlines()
    dump.write_text("\n".join(lines[: len(lines) // 2]) + "\n")
    monkeypatch.setattr(store, "STORED", dest)
    res = I.impacts(_ctx(tmp_path))
    bad = _failed(res, "evidence")
    assert bad and any("incomplete" in r.metric for r in bad)
    assert [r for r in _failed(res) if r.pair == "" and not math.isfinite(r.value)]
    assert not res.passed


def test_wall_analytic_is_the_two_body_limit():
    """(W1) is the two-body rigid limit (5)-(6) with the wall mass -> infinity."""
    m = I._mass(I.R)
    for im in I.wall_scenes()[0].impacts:
        an = I.wall_analytic(im)
        vn, vt = I.V * math.cos(math.radians(im.angle)), I.V * math.sin(math.radians(im.angle))
        rb = I.oblique_rigid(m, 1e12 * m, I.R, 1.0, vn, vt, I.MU_WALL, 2.0 * m * vn)
        assert rb["sliding"] is an["sliding"] is (im.kind == "sliding")
        assert an["exit slip"] == pytest.approx(rb["exit slip"], rel=1e-9, abs=1e-15)
        assert an["w1'"] == pytest.approx(rb["dw1"], rel=1e-9)
        if an["sliding"]:
            assert an["energy ratio"] < 1.0


def test_a_wall_that_gains_energy_fails(tmp_path, monkeypatch):
    """Fault injection: the LAMMPS wall's exit velocities scaled by 1.05 (10% more kinetic
    energy, the kind of defect lammps/lammps PR #5007 fixed) fail the energy bound and the
    comparison with the native wall."""
    _only(monkeypatch, "wall-lammps")
    orig = I.run_code

    def gaining(ctx, scene, engine):
        frames, job, live = orig(ctx, scene, engine)
        last = max(frames)
        frames[last] = dict(frames[last], v=1.05 * frames[last]["v"])
        return frames, job, live

    monkeypatch.setattr(I, "run_code", gaining)
    res = I.impacts(_ctx(tmp_path))
    assert not res.passed
    assert _failed(res, "energy gain")
    assert [r for r in _failed(res) if r.pair == "native-lammps"]


@pytest.mark.lammps
def test_lammps_wall_energy_live(tmp_path):
    """/usr/bin/lmp's ``fix wall/gran hooke/history`` (29 Sep 2021): the kinetic-energy ratio at
    every angle 30-85 deg (mu 0.5, no damping) is below 1 (no gain: the defect of PR #5007 is
    not in this build), equals the rigid-body limit in gross sliding (76 deg: 0.70611) and the
    native integrator of the build's wall arithmetic (fix_wall_gran.cpp:847-967) bit for bit
    on every frame."""
    if shutil.which("lmp") is None:
        pytest.skip("lmp not installed")
    sc = next(s for s in I.wall_scenes() if s.name == "wall-lammps")
    frames, _, live = I.run_code(_ctx(tmp_path, lammps=True), sc, "lammps")
    assert live
    meas = I.wall_measure(frames, sc, I.DT)
    nat = I.run_native_wall(sc)
    for im, q in zip(sc.impacts, meas):
        an = I.wall_analytic(im)
        assert q["energy ratio"] < 1.0 - 1e-3, im.label
        if im.kind == "sliding":
            assert q["energy ratio"] == pytest.approx(an["energy ratio"], abs=1e-6), im.label
    ke = {im.angle: q["energy ratio"] for im, q in zip(sc.impacts, meas)}
    assert ke[76.0] == pytest.approx(0.70611, abs=1e-5)
    assert sorted(frames) == sorted(nat)
    for s, fr in frames.items():
        for k in ("x", "v", "w", "f", "t"):
            assert np.array_equal(fr[k], nat[s][k]), (s, k)
