"""The impact scenes of the validation case ``impacts`` in YADE (reference_runs.yade.impacts), judged
against the case's own closed forms and tolerances (validation.cases.impacts: analytic, measure,
errors, TOL, TOL_HERTZ), with YADE's laws where they differ:

* undamped linear and Hertz scenes: the case's closed forms unchanged; and in the undamped Hooke
  scene YADE's positions equal the native engine's (LIGGGHTS arithmetic) in every frame: an
  independent integrator and contact geometry reach the same numbers;
* damped linear scenes: YADE clips the dashpot to repulsion (ViscoelasticPM.cpp:129-139), so the
  restitution and contact time are Schwager & Poeschel's (reference_runs.yade.impacts.
  clipped_dashpot, checked here against a DOP853 integration of the clipped equation), and the
  sticking tangential oscillator of eq (8) is released where the force ends, not at delta = 0;
* sticking Hertz scenes: YADE's tangential force is incremental (HertzMindlin.cpp:372-382) and
  slides out at the end of the contact (mindlin_incremental_stick).

Each check fails when the law is perturbed (the damped restitution against the unclipped eq (3)
fails by far: the clip is real)."""

import math
import shutil

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from gransim.errors import InputError
from reference_runs.yade.impacts import clipped_dashpot, mindlin_incremental_stick, yade_impacts, yade_law
from validation.cases import impacts as I

needs_yade = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)
SCENES = ("normal-z0.5", "oblique", "stick", "hertz-liggghts", "hertz-liggghts-stick")


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    root = tmp_path_factory.mktemp("yade-impacts")
    out = {}
    for sc in I.scenes("full"):
        if sc.name in SCENES:
            p, v, w, n, pairs = I.layout(sc)
            frames, manifest = yade_impacts(root / sc.name, p, v, w, sc.law, I.DT, n, I.EVERY)
            out[sc.name] = (sc, frames, manifest, pairs, n)
    return out


@needs_yade
def test_every_frame_is_there_and_the_job_is_yades(runs):
    for sc, frames, m, _, n in runs.values():
        assert m["status"] == "ok" and m["engine_version"] == "YADE 2023.02a" and m["servers"] == "not started"
        assert sorted(frames) == list(range(0, n + 1, I.EVERY)), sc.name
        assert all(fr["x"].shape == (2 * len(sc.impacts), 2) for fr in frames.values())


@needs_yade
@pytest.mark.parametrize("name", SCENES)
def test_yade_meets_the_closed_forms_within_the_cases_tolerances(runs, name):
    sc, frames, _, pairs, _ = runs[name]
    tols = I.tolerances(sc)
    meas = I.measure(frames, sc, pairs, I.DT)
    checked = 0
    for k, im in enumerate(sc.impacts):
        for q, err in I.errors(meas[k], I.yade_analytic(sc, im), im).items():
            tol, _why = tols[q]
            assert math.isfinite(err) and err <= tol, (name, im.label, q, err, tol)
            checked += 1
    assert checked >= 3 * len(sc.impacts)


@needs_yade
def test_undamped_hooke_positions_equal_the_native_engines(runs):
    """Leapfrog (YADE) and velocity Verlet (native, LIGGGHTS arithmetic) give the same positions in
    exact arithmetic for forces that do not depend on velocity; the shear spring of both laws is
    incremented with the same mid-step velocity. Measured: equal bit for bit in every frame of the
    34 disks of the oblique scene (round-off bound: 1e-12 of r)."""
    sc, frames, _, _, _ = runs["oblique"]
    nat = I.run_native(sc, "liggghts")
    assert sorted(nat) == sorted(frames)
    dx = max(np.abs(frames[k]["x"] - nat[k]["x"]).max() for k in nat)
    assert dx <= 1e-12 * I.R
    dv = max(np.abs(frames[k]["v"] - nat[k]["v"]).max() for k in nat)
    assert dv <= 1e-12 * I.V


@needs_yade
def test_the_clip_of_yades_dashpot_is_real(runs):
    """Against the unclipped closed form (3) (LIGGGHTS and LAMMPS) YADE's damped restitution fails by
    far (zeta 0.5 on the wall: e = 0.163 unclipped, 0.298 clipped)."""
    sc, frames, _, pairs, _ = runs["normal-z0.5"]
    meas = I.measure(frames, sc, pairs, I.DT)
    for k, im in enumerate(sc.impacts):
        err = I.errors(meas[k], I.analytic(sc, im), im)["restitution"]
        assert err > 10 * I.TOL["restitution"][0]


def test_clipped_dashpot_against_an_integration_of_the_clipped_equation():
    """An independent DOP853 integration of m_eff delta'' = -max(kn delta + m_eff gamma delta', 0),
    delta(0) = 0, delta'(0) = v_n, to delta = 0: restitution, contact time and release time."""
    meff, kn, vn = 0.15, 1.0e6, 1.0e-3
    for zeta in (0.0, 0.1, 0.35, 0.6):
        g = 2.0 * zeta * math.sqrt(kn / meff)
        c = clipped_dashpot(meff, kn, g, vn)

        def rhs(t, y, g=g):
            return [y[1], -max(kn * y[0] + meff * g * y[1], 0.0) / meff]

        def back(t, y):
            return y[0]

        def zero_force(t, y, g=g):
            return kn * y[0] + meff * g * y[1]

        back.terminal, back.direction = True, -1
        zero_force.direction = -1
        tc = math.pi * math.sqrt(meff / kn)
        sol = solve_ivp(
            rhs, (0, 3 * tc), [0, vn], method="DOP853", rtol=1e-12, atol=1e-18, events=(back, zero_force),
            first_step=tc * 1e-6, max_step=tc / 50,
        )  # fmt: skip
        assert -sol.y_events[0][0][1] / vn == pytest.approx(c["restitution"], rel=1e-9)
        assert sol.t_events[0][0] == pytest.approx(c["contact time"], rel=1e-9)
        t_zero = [t for t in sol.t_events[1] if t > 1e-3 * tc] or [sol.t_events[0][0]]  # zeta 0: at the end
        assert t_zero[0] == pytest.approx(c["release time"], rel=1e-8)
    und = clipped_dashpot(meff, kn, 0.0, vn)
    assert und["restitution"] == pytest.approx(1.0, abs=1e-15) and und["contact time"] == pytest.approx(tc, rel=1e-15)


def test_incremental_mindlin_equals_the_total_form_without_the_cap_and_slides_out_with_it():
    """Without the cap (mu 1e30) YADE's incremental form gives the exit slip of the case's total form
    H5 (an independent integration): s'' = -(3/m*) k_t(t) s with s(0) = s0, s'(0) = 0 against
    xi'' = -(3/m*) k_t(t) xi with xi(0) = 0, xi'(0) = 1, and for a k_t symmetric in time the two
    diagonal entries of the transfer matrix over the contact are equal. With mu 1e3 the force,
    which does not vanish with k_t, reaches mu F_n at the end and slides out: s'/s0 moves by
    1.4e-2 for s0 = 3 v_n (the spinning disk of the stick scene), beyond the tolerance 6e-3."""
    meff, reff = I._meff(I.R, I.R_WALL), I.R * I.R_WALL / (I.R + I.R_WALL)
    h = I.HertzLiggghtsLaw(I.E_H, I.NU_H, 1.0, I.MU_STICK).hertz()
    total = I.hertz_stick(meff, reff, h["y43"], h["kt0"], I.V_H)
    for s0 in (0.003, 0.03):
        assert mindlin_incremental_stick(meff, reff, h["y43"], h["kt0"], I.V_H, s0, 1e30) == pytest.approx(
            total, abs=1e-9
        )
    capped = mindlin_incremental_stick(meff, reff, h["y43"], h["kt0"], I.V_H, 0.03, I.MU_STICK)
    assert abs(capped - total) > I.TOL_HERTZ["exit slip (stick)"][0]


def test_laws_yade_cannot_run_are_refused_naming_them():
    damped = I.HertzLiggghtsLaw(I.E_H, I.NU_H, 0.5, 0.3)
    with pytest.raises(InputError, match=r"hertz-liggghts.*damped .*HertzMindlin.cpp:344-417"):
        yade_law(damped)
    tsuji = I.HertzGranularLammpsLaw(I.E_H, I.NU_H, 0.3, 0.3, 0.0, "tsuji")
    with pytest.raises(InputError, match="damped"):
        yade_law(tsuji)
    roll = next(s for s in I.rolling_scenes() if s.name == "roll-cdt").law
    with pytest.raises(InputError, match="Hooke and undamped Hertz laws only"):
        yade_law(roll)
    spec = yade_law(I.HertzHistoryLammpsLaw(I.E_H, I.NU_H, 0.3))
    assert spec == {"kind": "mindlin", "youngs_modulus": I.E_H, "poisson_ratio": I.NU_H, "mu": 0.3}
