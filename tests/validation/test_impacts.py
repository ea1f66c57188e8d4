"""The ``impacts`` validation case (validation/cases/impacts.py, docs/impacts.md).

Runs on the stored LIGGGHTS/LAMMPS outputs (reference_runs/stored/impacts-<code>/) so that it needs
neither code; the live comparison is the case itself under ``gransim validate``.
"""

from __future__ import annotations

import dataclasses
import math
import shutil

import pytest

from validation.cases import impacts as I
from validation.core import Context


def _ctx(tmp_path):
    return Context("quick", tmp_path / "results", liggghts=False, lammps=False)


def _only(monkeypatch, *names):
    orig = I.scenes
    monkeypatch.setattr(I, "scenes", lambda suite="default": [s for s in orig("full") if s.name in names])


def _failed(res, quantity=None):
    return [r for r in res.checks if not r.passed and (quantity is None or r.quantity == quantity)]


def test_closed_forms_against_numerical_integration():
    """Eqs (2)-(4), (7) against an independent fine RK4 integration of the damped oscillator."""
    meff, kn, vn = 0.15, 1e6, 1e-3
    for zeta in (0.0, 0.2, 0.5):
        w0 = math.sqrt(kn / meff)
        an = I.normal_linear(meff, kn, 2 * zeta * w0, vn)
        h = an["contact time"] / 200000
        x, v, t, peak, imp = 0.0, vn, 0.0, 0.0, 0.0

        def acc(x, v, w0=w0, zeta=zeta):
            return -w0 * w0 * x - 2 * zeta * w0 * v

        while True:
            k1 = (v, acc(x, v))
            k2 = (v + h / 2 * k1[1], acc(x + h / 2 * k1[0], v + h / 2 * k1[1]))
            k3 = (v + h / 2 * k2[1], acc(x + h / 2 * k2[0], v + h / 2 * k2[1]))
            k4 = (v + h * k3[1], acc(x + h * k3[0], v + h * k3[1]))
            xn = x + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
            vnew = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
            imp += abs(meff * (vnew - v))
            if xn <= 0 and t > 0:
                t += h * x / (x - xn)
                break
            x, v, t = xn, vnew, t + h
            peak = max(peak, x)
        assert t == pytest.approx(an["contact time"], rel=1e-6)
        assert -vnew / vn == pytest.approx(an["restitution"], rel=1e-4)
        assert peak == pytest.approx(an["peak overlap"], rel=1e-6)
        assert imp / (meff * vn) == pytest.approx(an["impulse factor"], rel=1e-4)


def test_rigid_body_threshold_is_psi1_6_for_disks():
    """Gross sliding exactly from Psi1 = 6 (disks: 1 + m r^2/I = 3), and Psi2 = Psi1 - 6 beyond."""
    m, r, mu, vn = 0.3, 0.01, 0.3, 1e-3
    P = 2 * (m / 2) * vn  # e = 1
    for psi, sliding in ((5.99, False), (6.01, True), (10.0, True)):
        s0 = psi * mu * 2 * vn / 2
        out = I.oblique_rigid(m, m, r, r, vn, s0, mu, P)
        assert out["sliding"] is sliding
        assert out["psi1"] == pytest.approx(psi)
        if sliding:
            assert 2 * out["exit slip"] / (mu * 2 * vn) == pytest.approx(psi - 6)


def test_case_passes_on_stored_outputs(tmp_path):
    res = I.impacts(_ctx(tmp_path))
    assert res.error is None
    assert res.passed, [(r.case, r.quantity, r.metric, r.value) for r in _failed(res)]
    assert not res.empty_cells
    for pair in ("native-liggghts", "native-lammps", "liggghts-lammps"):
        assert res.pair_checks(pair)
    assert any(r.pair == "" and r.quantity == "restitution" for r in res.checks)


def test_fails_when_damping_is_off_by_one_percent(tmp_path, monkeypatch):
    _only(monkeypatch, "normal-z0.35")
    orig = I.native_settings
    monkeypatch.setattr(
        I, "native_settings", lambda law, dt, fl: dataclasses.replace(orig(law, dt, fl), gamma_n=1.01 * law.gamma_n)
    )
    res = I.impacts(_ctx(tmp_path))
    assert not res.passed
    assert _failed(res, "restitution")


def test_fails_when_stiffness_is_off_by_one_percent(tmp_path, monkeypatch):
    _only(monkeypatch, "normal-z0")
    orig = I.native_settings
    monkeypatch.setattr(
        I, "native_settings", lambda law, dt, fl: dataclasses.replace(orig(law, dt, fl), kn=1.01 * law.kn)
    )
    res = I.impacts(_ctx(tmp_path))
    assert _failed(res, "contact time")


def test_truncated_stored_log_fails_as_incomplete(tmp_path, monkeypatch):
    from reference_runs import store

    _only(monkeypatch, "normal-z0")
    dest = tmp_path / "stored"
    for code in I.CODES:
        shutil.copytree(store.STORED / f"impacts-{code}", dest / f"impacts-{code}")
    log = dest / "impacts-liggghts" / "normal-z0" / "log.lammps"
    lines = log.read_text().splitlines()
    log.write_text("\n".join(lines[: len(lines) // 2]) + "\n")
    dump = dest / "impacts-liggghts" / "normal-z0" / "dump.atoms"
    dl = dump.read_text().splitlines()
    dump.write_text("\n".join(dl[: len(dl) // 2]) + "\n")
    monkeypatch.setattr(store, "STORED", dest)
    res = I.impacts(_ctx(tmp_path))
    bad = _failed(res, "evidence")
    assert bad and any("incomplete" in r.metric for r in bad)
    assert not res.passed


# ---------------------------------------------------------------------- Hertz-Mindlin scenes
def _rk4_hertz(meff, K, c, vn, h):
    """Independent dimensional integration (classical RK4, step h) of m* delta'' = -K delta^(3/2)
    - c delta^(1/4) delta' to the return to delta = 0: (contact time, peak overlap, restitution)."""

    def acc(x, v):
        x = max(x, 0.0)
        return -(K * x**1.5 + c * x**0.25 * v) / meff

    x, v, t, peak = 0.0, vn, 0.0, 0.0
    while True:
        k1 = (v, acc(x, v))
        k2 = (v + h / 2 * k1[1], acc(x + h / 2 * k1[0], v + h / 2 * k1[1]))
        k3 = (v + h / 2 * k2[1], acc(x + h / 2 * k2[0], v + h / 2 * k2[1]))
        k4 = (v + h * k3[1], acc(x + h * k3[0], v + h * k3[1]))
        xn = x + h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        vnew = v + h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        if xn <= 0 and t > 0:
            return t + h * x / (x - xn), peak, -vnew / vn
        x, v, t = xn, vnew, t + h
        peak = max(peak, x)


def test_hertz_closed_forms_against_integration():
    """H1-H3 (closed forms, Beta function) against the scaled ODE (DOP853) at alpha = 0, and the
    scaled damped solution (H4) against an independent dimensional RK4 integration."""
    o = I.hertz_scaled_ode(0.0)
    assert o["x_max"] == pytest.approx(1.25**0.4, rel=1e-9)
    assert o["f_max"] == pytest.approx(1.25**0.6, rel=1e-9)
    assert o["tau_c"] == pytest.approx(2 * 1.25**0.4 * 1.4716, rel=1e-4)  # int_0^1 dx/sqrt(1 - x^2.5)
    assert o["restitution"] == pytest.approx(1.0, abs=1e-9)
    meff, reff, y43, vn = 0.157, 0.005, 3.663e8, 0.01
    und = I.hertz_undamped(meff, reff, y43, vn)
    assert und["contact time"] == pytest.approx(2.9432 * und["peak overlap"] / vn, rel=1e-4)
    K = y43 * math.sqrt(reff)
    for alpha in (0.0, 0.9):
        an = I.normal_hertz(meff, reff, y43, vn, alpha)
        tc, peak, e = _rk4_hertz(meff, K, alpha * math.sqrt(meff * K), vn, an["contact time"] / 20000)
        assert tc == pytest.approx(an["contact time"], rel=1e-5)
        assert peak == pytest.approx(an["peak overlap"], rel=1e-5)  # RK4 order drops at delta^(1/4)
        assert e == pytest.approx(an["restitution"], rel=1e-4)


def test_liggghts_hertz_damping_gives_the_requested_restitution():
    """LIGGGHTS' 2 sqrt(5/6) beta(e) damping is alpha = -sqrt(5) beta(e) in H4; integrated
    independently it returns e (speed-free); LAMMPS' tsuji polynomial gives 0.4396 for DAMP 0.3."""
    from gransim.contacts.material import beta_liggghts, tsuji_alpha_lammps

    for e in (0.3, 0.5, 0.8, 0.95):
        alpha = -math.sqrt(5) * beta_liggghts(e)
        assert I.hertz_scaled_ode(alpha)["restitution"] == pytest.approx(e, rel=1e-8)
    e_tsuji = I.hertz_scaled_ode(tsuji_alpha_lammps(0.3))["restitution"]
    assert e_tsuji == pytest.approx(0.4396, abs=1e-4)
    meff, K, vn = 0.157, 2.59e7, 0.01
    _, _, e = _rk4_hertz(meff, K, tsuji_alpha_lammps(0.3) * math.sqrt(meff * K), vn, 1e-7)
    assert e == pytest.approx(e_tsuji, rel=1e-4)


def test_hertz_stick_reference_limits():
    """H5: for kt0 -> 0 the slip is unchanged (s'/s0 -> 1); the ratio does not depend on s0
    (linear) and equals an RK4 integration of the same pair of equations."""
    meff, reff, y43, vn = 0.3137, 0.0096, 3.663e8, 0.01
    assert I.hertz_stick(meff, reff, y43, 1e-6, vn) == pytest.approx(1.0, abs=1e-9)
    ratio = I.hertz_stick(meff, reff, y43, 4.52e8, vn)
    K = y43 * math.sqrt(reff)

    def f(y):
        d = max(y[0], 0.0)
        return [y[1], -K * d**1.5 / meff, y[3], -3 * 4.52e8 * math.sqrt(reff * d) * y[2] / meff]

    y, h = [0.0, vn, 0.0, 1.0], 1e-7
    while True:
        k1 = f(y)
        k2 = f([a + h / 2 * b for a, b in zip(y, k1)])
        k3 = f([a + h / 2 * b for a, b in zip(y, k2)])
        k4 = f([a + h * b for a, b in zip(y, k3)])
        yn = [a + h / 6 * (b1 + 2 * b2 + 2 * b3 + b4) for a, b1, b2, b3, b4 in zip(y, k1, k2, k3, k4)]
        if yn[0] <= 0 and y[0] > 0 and y[1] < 0:
            break
        y = yn
    assert yn[3] == pytest.approx(ratio, abs=1e-5)


def _perturbed(monkeypatch, fn):
    orig = I.native_law
    monkeypatch.setattr(I, "native_law", lambda law, fl: fn(orig(law, fl)))


def test_hertz_scenes_pass_bit_for_bit_on_stored_outputs(tmp_path, monkeypatch):
    names = [s.name for s in I.hertz_scenes()]
    _only(monkeypatch, *names)
    res = I.impacts(_ctx(tmp_path))
    assert res.passed, [(r.case, r.quantity, r.metric, r.value) for r in _failed(res)]
    for n in names:
        pos = [r for r in res.checks if r.case.startswith(f"impacts/{n}/") and r.quantity == "positions"]
        assert pos and all(r.value == 0.0 for r in pos), n
    assert {r.pair for r in res.checks} >= {"native-liggghts", "native-lammps"}


def test_fails_when_hertz_restitution_formula_off_by_one_percent(tmp_path, monkeypatch):
    """LIGGGHTS: beta computed from 0.99 e (the law's restitution off by 1%) -> the restitution
    record fails; LAMMPS tsuji: the polynomial evaluated at 1.01 DAMP -> the same."""
    from gransim.contacts.material import beta_liggghts, tsuji_alpha_lammps

    _only(monkeypatch, "hertz-liggghts-e0.5", "hertz-granular-tsuji0.3")

    def off(law):
        if type(law).__name__ == "HertzHistoryLiggghts":
            return law._replace(betaeff=beta_liggghts(0.99 * 0.5))
        return law._replace(damp=tsuji_alpha_lammps(1.01 * 0.3))

    _perturbed(monkeypatch, off)
    res = I.impacts(_ctx(tmp_path))
    bad = [r for r in _failed(res, "restitution") if r.pair == ""]
    assert {r.case.split("/")[1] for r in bad} == {"hertz-liggghts-e0.5", "hertz-granular-tsuji0.3"}


@pytest.mark.parametrize(
    "scene, field", [("hertz-liggghts-stick", "geff"), ("hertz-lammps-stick", "kt"), ("hertz-granular-stick", "kt0")]
)
def test_fails_when_mindlin_stiffness_off_by_one_percent(tmp_path, monkeypatch, scene, field):
    _only(monkeypatch, scene)
    _perturbed(monkeypatch, lambda law: law._replace(**{field: 1.01 * getattr(law, field)}))
    res = I.impacts(_ctx(tmp_path))
    bad = [r for r in _failed(res, "exit slip (stick)") if r.pair == ""]
    assert len(bad) == 3


def test_fails_when_hertz_modulus_off_by_one_percent(tmp_path, monkeypatch):
    _only(monkeypatch, "hertz-liggghts")
    _perturbed(monkeypatch, lambda law: law._replace(yeff=1.01 * law.yeff))
    res = I.impacts(_ctx(tmp_path))
    assert [r for r in _failed(res, "contact time") if r.pair == "" and r.case.endswith(("/disks", "/wall"))]


def test_hertz_laws_refuse_the_other_code(tmp_path):
    from gransim.errors import InputError
    from reference_runs.decks.impact import HertzHistoryLammpsLaw, HertzLiggghtsLaw

    with pytest.raises(InputError, match="only liggghts"):
        HertzLiggghtsLaw(5e8, 0.3).deck_lines("lammps")
    with pytest.raises(InputError, match="only lammps"):
        HertzHistoryLammpsLaw(5e8, 0.3).deck_lines("liggghts")
    with pytest.raises(InputError, match="youngs_modulus"):
        HertzLiggghtsLaw(5e10, 0.3)


def test_coulomb_excess_of_frames_without_normal_force():
    """A frame with no force at all is within the Coulomb bound; a tangential force without a
    normal one is an infinite excess, and its record fails."""
    import numpy as np

    from validation.cases.impacts import _coulomb_excess
    from validation.core import compare

    assert _coulomb_excess(np.array([0.0, 0.5]), np.array([0.0, 1.0])) == -0.5
    bad = _coulomb_excess(np.array([0.1, 0.5]), np.array([0.0, 1.0]))
    assert bad == np.inf
    assert not compare("scene", "coulomb bound", "bound", bad, 1e-9, "exact cap").passed


def test_a_code_output_missing_one_frame_fails_its_evidence(tmp_path, monkeypatch):
    """LIGGGHTS' stored dump of normal-z0 with the frame of one step cut out of its middle: the frame
    evidence of native vs LIGGGHTS fails naming that step (besides the stored job's own check), the
    column and the case fail; the frames that remain are still compared (0: bit for bit)."""
    from reference_runs import store

    _only(monkeypatch, "normal-z0")
    dest = tmp_path / "stored"
    for code in I.CODES:
        shutil.copytree(store.STORED / f"impacts-{code}" / "normal-z0", dest / f"impacts-{code}" / "normal-z0")
    dump = dest / "impacts-liggghts" / "normal-z0" / "dump.atoms"
    blocks = dump.read_text().split("ITEM: TIMESTEP\n")[1:]
    gone = int(blocks[40].split("\n", 1)[0])
    dump.write_text("".join("ITEM: TIMESTEP\n" + b for k, b in enumerate(blocks) if k != 40))
    monkeypatch.setattr(store, "STORED", dest)
    res = I.impacts(_ctx(tmp_path))
    n = len(blocks)
    bad = [r for r in _failed(res, "evidence") if r.pair == "native-liggghts"]
    assert f"incomplete: expected {n} LIGGGHTS frames, got {n - 1} (missing: {gone})" in [r.metric for r in bad]
    assert res.cell("native-liggghts")["state"] == "FAIL" and not res.passed
    pos = [r for r in res.checks if r.case == "impacts/normal-z0/liggghts" and r.quantity == "positions"]
    assert pos[0].value == 0.0 and f"over {n - 1} frames" in pos[0].metric
    assert res.cell("native-lammps")["state"] == "pass"


def test_absent_codes_are_stood_in_for_by_their_stored_runs(tmp_path, monkeypatch):
    """Without LIGGGHTS, LAMMPS and YADE every live run of a scene is replaced by its stored output
    (the run table says so), and every column of the three codes is still judged."""
    _only(monkeypatch, "normal-z0")
    res = I.impacts(_ctx(tmp_path))
    status = {key: st for key, _, _, _, st in res.runs}
    for code in ("liggghts", "lammps", "yade"):
        assert status[f"normal-z0/{code}"].endswith(f"normal-z0/{code}/stored compared instead")
        assert status[f"normal-z0/{code}/stored"] == "made"
    assert status["native/normal-z0/liggghts/dt2"] == "made"  # the time-step order: the first code's arithmetic
    for pair in ("native-liggghts", "native-lammps", "native-yade", "liggghts-lammps"):
        assert res.cell(pair)["state"] == "pass", pair
    assert res.not_applicable.keys() == {"liggghts-yade", "lammps-yade"}


def test_a_failed_yade_job_fails_its_evidence_and_gets_no_verdict(tmp_path, monkeypatch):
    """YADE installed but its job fails: the native vs YADE column holds the failure (named) and the
    missing frames, and YADE's run is not judged against the closed forms (no answers to judge); the
    other columns are unaffected."""
    from reference_runs.errors import ReferenceRunError
    from validation import yade_runs

    _only(monkeypatch, "normal-z0.35")

    def boom(*a, **k):
        raise ReferenceRunError("yade exited with status 1\nsecond line")

    monkeypatch.setattr(yade_runs, "impact_live", boom)
    ctx = Context("quick", tmp_path / "results", available=frozenset({"yade"}))
    res = I.impacts(ctx)
    bad = [r for r in res.checks if not r.passed]
    assert {(r.case, r.pair) for r in bad} == {("impacts/normal-z0.35/yade", "native-yade")}
    assert "incomplete: YADE job failed: yade exited with status 1" in [r.metric for r in bad]
    assert any(r.metric.startswith("incomplete: expected 82 YADE frames, got 0") for r in bad)
    assert not [r for r in res.records if r.case.endswith("/yade") and r.case.count("/") == 3]
    assert res.cell("native-yade")["state"] == "FAIL" and res.cell("native-liggghts")["state"] == "pass"


def test_the_columns_follow_the_laws_engines(tmp_path, monkeypatch):
    """A scene whose law only LAMMPS has (gran/hertz/history) makes the native vs LAMMPS column (and
    YADE's, which has an undamped Hertz law) and nothing of LIGGGHTS: its columns are not applicable,
    saying so, and no column is left undeclared."""
    from validation.core import PAIRS

    _only(monkeypatch, "hertz-lammps")
    res = I.impacts(_ctx(tmp_path))
    assert res.passed and set(res.matrix) == {"native-lammps", "native-yade"}
    assert "no scene of the quick suite has a law of LIGGGHTS" in res.not_applicable["native-liggghts"]
    assert set(res.matrix) | set(res.not_applicable) == set(PAIRS)
    assert not [r for r in res.checks if "liggghts" in r.pair]
