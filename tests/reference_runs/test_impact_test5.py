"""Chung & Ooi's test 5 (constant normal, swept tangential speed on a wall) for the Hertz laws: native
(in each law's code's arithmetic), LIGGGHTS, LAMMPS and YADE against the closed forms of the impacts
case (validation.cases.impacts: H1-H3 and the rigid-body limit of gross sliding, eq (6) with
P = 2 m* v_n), at the tolerances of reference_runs.decks.impact.TEST5_TOL (each with its reason).

What can fail: every error against the closed form (a 1% stiffness moves the contact time by 4e-3,
over its 2e-3); the tangential force of gross sliding equal to mu |F_n| in every contact frame; the
codes equal to the native engine in every frame; the normal answers the same for every tangential
speed. Each code's part is skipped without its binary."""

import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from reference_runs.decks.impact import TEST5_PSI1, TEST5_TOL, chung_ooi_test5_impacts, sliding_force_deviation
from validation.cases import impacts as I
from validation.core import Context

LAWS = {
    "liggghts": I.HertzLiggghtsLaw(I.E_H, I.NU_H, 1.0, I.MU_OBLIQUE),
    "lammps": I.HertzHistoryLammpsLaw(I.E_H, I.NU_H, I.MU_OBLIQUE),
    "granular": I.HertzGranularLammpsLaw(I.E_H, I.NU_H, 0.0, I.MU_OBLIQUE),
}


def scene(name: str) -> I.Scene:
    imps = tuple(
        I.Impact(d["label"], d["kind"], d["r1"], d["r2"], d["v1"], d["v2"], d["w1"], d["w2"], d["note"])
        for d in chung_ooi_test5_impacts(I.V_H, I.MU_OBLIQUE, I.R, I.R_WALL)
    )
    return I.Scene(f"test5-{name}", LAWS[name], imps, meta={"energy": True})


def judge(frames: dict, sc: I.Scene) -> dict:
    """{quantity: largest error over the sweep}; every error must be finite."""
    p, _, _, _, pairs = I.layout(sc)
    meas = I.measure(frames, sc, pairs, I.DT)
    dev = sliding_force_deviation(frames, pairs, p.radii, sc.law.mu)
    worst = {}
    for k, im in enumerate(sc.impacts):
        e = I.errors(meas[k], I.analytic(sc, im), im)
        if im.kind == "sliding":
            e["sliding force"] = dev[k]
        for q, x in e.items():
            assert math.isfinite(x), (sc.name, im.label, q)
            worst[q] = max(worst.get(q, 0.0), x)
    return worst


def check(worst: dict, who: str) -> None:
    assert {"contact time", "restitution", "peak force", "friction impulse", "exit slip", "sliding force"} <= set(worst)
    for q, x in worst.items():
        tol, _why = TEST5_TOL[q]
        assert x <= tol, (who, q, x, tol)


def test_the_sweep_is_test_5():
    imps = chung_ooi_test5_impacts(I.V_H, I.MU_OBLIQUE, I.R, I.R_WALL)
    assert [d["v1"][0] for d in imps] == [I.V_H] * len(TEST5_PSI1)  # constant normal speed
    vt = [d["v1"][1] for d in imps]
    assert vt == sorted(vt) and [d["kind"] for d in imps].count("sliding") == 4  # Psi1 6.5, 8, 12, 20
    for d in imps:  # Psi1 = 2 v_t/(mu (1 + e) v_n), e = 1
        assert 2 * d["v1"][1] / (I.MU_OBLIQUE * 2 * I.V_H) == pytest.approx(d["psi1"], rel=1e-15)


@pytest.mark.parametrize("name", list(LAWS))
def test_native_meets_the_closed_forms(name):
    sc = scene(name)
    frames = I.run_native(sc, sc.law.engines[0])
    check(judge(frames, sc), f"native {name}")
    # the normal answers do not depend on the tangential speed (the test's point): the contact times
    # of the sweep within the tolerance of each other
    p, _, _, _, pairs = I.layout(sc)
    tc = [m["contact time"] for m in I.measure(frames, sc, pairs, I.DT)]
    assert max(tc) / min(tc) - 1 < TEST5_TOL["contact time"][0]


@pytest.mark.parametrize("name", list(LAWS))
def test_each_code_equals_native_and_meets_the_closed_forms(name, tmp_path):
    sc = scene(name)
    code = sc.law.engines[0]
    binary = {"liggghts": "liggghts", "lammps": "lmp"}[code]
    if shutil.which(binary) is None:
        pytest.skip(f"{binary} not installed")
    ctx = Context(suite="full", results=Path(tmp_path), liggghts=code == "liggghts", lammps=code == "lammps")
    frames, _, live = I.run_code(ctx, sc, code)
    assert live
    _, _, _, n, _ = I.layout(sc)
    assert sorted(frames) == list(range(0, n + 1, I.EVERY))  # every frame (evidence)
    nat = I.run_native(sc, code)
    for k in nat:
        for key in ("x", "v", "w", "f", "t"):
            assert np.array_equal(nat[k][key], frames[k][key]), (name, k, key)
    check(judge(frames, sc), f"{code} {name}")


def test_yade_meets_the_closed_forms(tmp_path):
    """YADE's Law2_ScGeom_MindlinPhys_Mindlin: gross sliding and the normal impact are the same closed
    forms (reference_runs.yade.impacts); the microslip impacts are judged by the bounds only."""
    if shutil.which("yade") is None:
        pytest.skip("yade not installed")
    from reference_runs.yade.impacts import yade_impacts

    sc = scene("liggghts")
    p, v, w, n, _ = I.layout(sc)
    frames, m = yade_impacts(tmp_path / "job", p, v, w, sc.law, I.DT, n, I.EVERY)
    assert m["status"] == "ok" and sorted(frames) == list(range(0, n + 1, I.EVERY))
    check(judge(frames, sc), "yade")
