"""Cases as declarations (validation.matrix) and the shared judges (validation.judges).

The columns follow from the code list; a comparison lands in the column of its runs' codes; a live
run of a code that is not installed leaves its comparisons out and marks a column without any
comparison not applicable; the one envelope criterion keeps both of its former forms (pointwise
for biaxial-full, windowed with floors for simple-shear) and fails on a NaN, on nothing, on a zero
envelope under a non-zero divergence and on a member cut short; the step-for-step judge fails on
a reference cut short and on a reference with a particle missing."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from validation import codes
from validation.core import CaseResult, Context
from validation.dem_compare import Trajectory
from validation.judges import (
    BITWISE_RULE,
    EnvelopeRule,
    StepBounds,
    band,
    envelope,
    envelope_ratio,
    step_for_step,
    windowed_max,
)
from validation.matrix import Comparison, Run, evaluate

BOUNDS = StepBounds(1e-10, 1e-8, "p", "v", "f", "s", "b")


def test_the_columns_follow_the_code_list(monkeypatch):
    monkeypatch.setattr(codes, "CODES", ("liggghts", "lammps"))
    assert codes.pairs() == {
        "native-liggghts": "native vs LIGGGHTS",
        "native-lammps": "native vs LAMMPS",
        "liggghts-lammps": "LIGGGHTS vs LAMMPS",
    }
    monkeypatch.setattr(codes, "CODES", ("liggghts", "lammps", "yade"))  # one more code: its columns
    p = codes.pairs()
    assert list(p) == [
        "native-liggghts",
        "native-lammps",
        "native-yade",
        "liggghts-lammps",
        "liggghts-yade",
        "lammps-yade",
    ]
    assert p["native-yade"] == "native vs YADE" and p["lammps-yade"] == "LAMMPS vs YADE"
    assert codes.pair_key("yade", "native") == "native-yade"
    with pytest.raises(ValueError, match="code"):
        codes.pair_key("native", "chute")
    with pytest.raises(ValueError, match="twice"):
        codes.pair_key("lammps", "lammps")


def _traj(n=6, steps=10, dump=5, seed=0, drop_steps=0, drop_particle=False):
    """A made-up run: stress and box every step, frames every ``dump`` steps, 2D disks."""
    rng = np.random.default_rng(seed)
    st = np.arange(steps + 1 - drop_steps)
    frames = {}
    for s in range(0, steps + 1 - drop_steps, dump):
        k = n - 1 if drop_particle else n
        frames[s] = {
            "x": rng.uniform(0, 1, (k, 2)),
            "v": rng.normal(size=(k, 2)),
            "w": rng.normal(size=k),
            "f": rng.normal(size=(k, 2)),
            "t": rng.normal(size=k),
        }
    return Trajectory(st, rng.normal(size=(len(st), 3)), np.ones((len(st), 2)), frames)


def _step(a, b):
    return step_for_step("c/x", a, b, d50=0.1, nsteps=10, dump_every=5, bounds=BOUNDS, sides=("native", "LAMMPS"))


def test_step_for_step_passes_equal_runs_and_fails_on_evidence_cut_short():
    a = _traj()
    recs, s = _step(a, _traj())
    assert all(r.passed for r in recs) and s["x"] == 0.0 and s["stress"] == 0.0
    cut = _traj(drop_steps=4)  # a log and a dump cut at step 6
    recs, _ = _step(a, cut)
    bad = [r.metric for r in recs if not r.passed]
    assert "incomplete: expected 11 LAMMPS series steps, got 7 (missing: 7, 8, 9, 10)" in bad
    assert any(m.startswith("incomplete: expected 3 LAMMPS frames, got 2") for m in bad)
    recs, _ = _step(a, _traj(drop_particle=True))  # a particle missing from every frame
    failed = {r.quantity for r in recs if not r.passed}
    assert {"position", "velocity", "spin", "particle_force", "particle_torque"} <= failed  # nothing to compare


def test_evaluate_files_each_comparison_in_its_runs_column():
    res = CaseResult("c", "t", "d")
    runs = [
        Run("native/x", "native", "lammps", "native", lambda: _traj()),
        Run("x/lammps", "lammps", "lammps", "stored", lambda: _traj(), verify=lambda label, tr: []),
        Run("live/lammps", "lammps", "lammps", "deck run now", lambda: _traj(), live=True),
        Run("live/liggghts", "liggghts", "liggghts", "deck run now", lambda: _traj(), live=True),
        Run("native/y", "native", "liggghts", "native", lambda: _traj()),
    ]
    params = {"d50": 0.1, "nsteps": 10, "dump_every": 5, "bounds": BOUNDS}
    comps = [
        Comparison("step", "c/stored", ("native/x", "x/lammps"), "why-lammps", params),
        Comparison("step", "c/live", ("native/x", "live/lammps"), "why-lammps", params),
        Comparison("step", "c/live-liggghts", ("native/y", "live/liggghts"), "why-liggghts", params),
    ]
    ctx = Context("quick", None, liggghts=False, lammps=True)
    out = evaluate(res, ctx, runs, comps)
    assert set(out.summaries) == {"c/stored", "c/live"}
    assert out.skipped == {"c/live-liggghts": "LIGGGHTS is not installed (live/liggghts not made)"}
    assert res.matrix == {"native-lammps": "why-lammps"}
    assert "LIGGGHTS is not installed" in res.not_applicable["native-liggghts"]
    assert all(r.pair == "native-lammps" for r in res.records) and res.passed
    assert any("LIGGGHTS is absent" in n for n in res.notes)
    # a live run with a stored stand-in: compared in its place when the code is absent
    runs.append(Run("stored/liggghts", "liggghts", "liggghts", "stored", lambda: _traj()))
    runs[3] = Run(
        "live/liggghts", "liggghts", "liggghts", "deck run now", lambda: 1 / 0, live=True, fallback="stored/liggghts"
    )
    res = CaseResult("c", "t", "d")
    out = evaluate(res, ctx, runs, comps)
    assert set(out.summaries) == {"c/stored", "c/live", "c/live-liggghts"} and "stored/liggghts" in out.runs
    assert res.cell("native-liggghts")["state"] == "pass"
    assert any("its stored output stored/liggghts is compared instead" in n for n in res.notes)
    with pytest.raises(ValueError, match="no run"):
        evaluate(CaseResult("c", "t", "d"), ctx, runs, [Comparison("step", "c/z", ("native/x", "nope"), "r", params)])


def test_the_envelope_ratio_of_both_rules():
    d = np.array([0.0, 1e-12, 4e-12, 0.0])
    env = np.array([0.0, 1e-12, 1e-12, 1e-12])
    assert envelope_ratio(d, env, 10.0) == 4.0  # d = 0 over a zero envelope counts 0
    assert envelope_ratio(d, np.array([0.0, 0.0, 1e-12, 1e-12]), 10.0) == math.inf  # d > 0, nothing to be within
    assert envelope_ratio(d, np.zeros(4), 10.0, floor=1e-10) == pytest.approx(0.4)  # below the floor
    for bad in (np.nan, np.inf):
        dd = d.copy()
        dd[2] = bad
        assert math.isnan(envelope_ratio(dd, env, 10.0))
    assert math.isnan(envelope_ratio([], [], 10.0))  # nothing compared: fails
    assert list(windowed_max([0, 10, 20, 30], [1.0, 5.0, 2.0, 3.0], 10)) == [5.0, 5.0, 5.0, 3.0]
    assert list(windowed_max([0, 10], [1.0, 5.0], 0)) == [1.0, 5.0]


def test_one_envelope_judge_with_the_metrics_of_both_cases():
    steps = np.arange(0, 101, 10)
    ref = Trajectory(steps, np.ones((11, 3)), np.ones((11, 2)), {})

    def member(eps):
        return Trajectory(steps, np.ones((11, 3)) + eps * np.exp(steps / 20.0)[:, None], np.ones((11, 2)), {})

    nat = member(2e-12)
    window = EnvelopeRule(10.0, 20, 1e-10, 1e-8, 2.0, "r CODE")
    for rule, metric, n_info in (
        (BITWISE_RULE, "max_t S_native(t)/E_S(t)", 0),
        (window, "max_t S_native(t)/max(E_S,w(t), 1e-8/10)", 2),
    ):
        recs, _, sdiv = envelope(
            "c", "LAMMPS", nat, ref, {"p": member(1e-12)}, frames=[], steps=steps, d50=1.0, rule=rule
        )
        (check,) = [r for r in recs if r.kind == "check"]
        assert check.metric == metric and check.passed
        # pointwise: twice the member everywhere; the window and the floor can only lower the ratio
        assert check.value == pytest.approx(2.0, rel=1e-4) if rule is BITWISE_RULE else 0 < check.value < 2.0
        assert len(recs) - 1 == n_info and "LAMMPS" in check.reason
    # 100 times the member's divergence: fails under both rules
    recs, _, _ = envelope(
        "c", "LAMMPS", member(1e-10), ref, {"p": member(1e-12)}, frames=[], steps=steps, d50=1.0, rule=BITWISE_RULE
    )
    assert not recs[0].passed and recs[0].value == pytest.approx(100.0, rel=1e-4)
    # a member cut short: its steps are missing, there is no verdict (the cases check evidence first)
    short = Trajectory(steps[:5], np.ones((5, 3)), np.ones((5, 2)), {})
    with pytest.raises(KeyError):
        envelope("c", "LAMMPS", nat, ref, {"p": short}, frames=[], steps=steps, d50=1.0, rule=BITWISE_RULE)


def test_band_is_the_largest_member_deviation_times_the_factor():
    ref = np.zeros(5)
    rec = band("c", "deviator", "m", np.full(5, 0.3), ref, [np.full(5, 0.2), np.full(5, -0.1)], factor=2.0, reason="r")
    assert rec.passed and rec.tolerance == pytest.approx(0.4) and rec.value == pytest.approx(0.3)
    rec = band("c", "deviator", "m", np.full(5, 0.3), ref, [np.full(5, 0.2)], factor=1.0, reason="r")
    assert not rec.passed
    rec = band("c", "deviator", "m", np.full(5, 0.1), ref, [], factor=1.0, reason="r")
    assert not rec.passed and "NaN" in rec.metric  # no member: no band, no pass


def test_a_cross_pair_states_why_the_codes_differ():
    why = codes.why_they_differ("liggghts-lammps")
    for words in ("lever arm", "Coulomb cap", "pair_gran_hooke_history.cpp:222-224", "surface_model_default.h:182"):
        assert words in why
    assert codes.why_they_differ("native-lammps") == ""


def test_the_third_code_has_its_columns_and_breaks_no_case(tmp_path):
    """YADE, the third code of the list (in a fresh interpreter, every code reported absent): the
    report has its three columns, the cases of the quick suite that declare runs per code still
    pass on the stored runs, native vs YADE is judged on YADE's stored output, and the two codes
    against YADE are not applicable with a reason (their undamped decks need the codes), never a
    failure and never an undeclared column."""
    import json
    import os
    import subprocess
    import sys

    script = f"""
import json
import validation.runner as r
r.liggghts_available = lambda: False
r.lammps_available = lambda: False
r._available = lambda code: False
from validation.report import matrix_html
pairs = ("native-yade", "liggghts-yade", "lammps-yade")
ok, res = r.run_validation(
    "quick", {str(tmp_path / "results")!r}, only=["biaxial-short", "simple-shear"], log=lambda *a: None
)
cells = {{x.case: {{p: x.cell(p)["state"] for p in pairs}} for x in res}}
header = "".join(matrix_html(res)).split("</tr>")[0]
print(json.dumps({{"ok": ok, "cells": cells, "header": header}}))
"""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    doc = json.loads(out.stdout.strip().splitlines()[-1])
    assert doc["ok"], doc
    assert doc["cells"]["biaxial-short"] == {
        "native-yade": "pass",
        "liggghts-yade": "n/a",
        "lammps-yade": "n/a",
    }
    assert doc["cells"]["simple-shear"] == {
        "native-yade": "pass",
        "liggghts-yade": "n/a",
        "lammps-yade": "n/a",
    }
    for label in ("native vs YADE", "LIGGGHTS vs YADE", "LAMMPS vs YADE"):
        assert label in doc["header"]


def test_the_analytic_judge_takes_the_worst_run_and_fails_a_missing_answer():
    from validation.judges import Bound, analytic

    expected = [("a", "error"), ("a", "order"), ("", "norm")]
    bound = {
        "error": Bound(1e-3, "why e"),
        "order": Bound(1.5, "why o", "at_least"),
        "norm": Bound(math.nan, "i", "info"),
    }

    def values(run):
        return run

    good = {("a", "error"): 1e-4, ("a", "order"): 1.9, ("", "norm"): 1e-20}
    other = {("a", "error"): 5e-4, ("a", "order"): 1.7, ("", "norm"): 1e-19}
    recs, summary = analytic("c", good, other, expected=expected, values=values, bound=bound, sides=("n", "m"))
    by_q = {r.quantity: r for r in recs}
    assert by_q["error"].value == 5e-4 and by_q["error"].passed and by_q["error"].case == "c/a"
    assert by_q["order"].value == 1.7 and by_q["order"].passed
    assert by_q["norm"].kind == "info" and by_q["norm"].case == "c"
    assert summary[("a", "error")] == {"n": 1e-4, "m": 5e-4}
    # a run beyond the tolerance or below the rate fails
    slow = {**other, ("a", "order"): 1.0}
    recs, _ = analytic("c", good, slow, expected=expected, values=values, bound=bound, sides=("n", "m"))
    assert [r.passed for r in recs if r.kind == "check"] == [True, False]
    # a run that does not answer a pair: NaN, failing, named
    cut = {("a", "order"): 1.9}
    recs, _ = analytic("c", good, cut, expected=expected, values=values, bound=bound, sides=("n", "m"))
    err = next(r for r in recs if r.quantity == "error")
    assert not err.passed and "no answer from m" in err.metric
    # an inf order is no pass either
    recs, _ = analytic(
        "c", {**good, ("a", "order"): math.inf}, expected=expected, values=values, bound=bound, sides=("n",)
    )
    assert not next(r for r in recs if r.quantity == "order").passed


def test_a_one_run_comparison_files_outside_the_matrix_unless_it_names_a_column():
    from validation.judges import Bound

    res = CaseResult("c", "t", "d")
    runs = [
        Run("native", "native", "lammps", "native", lambda: {("", "e"): 0.0}),
        Run("yade", "yade", "yade", "YADE now", lambda: {("", "e"): 2.0}),
    ]
    params = {"expected": [("", "e")], "values": lambda r: r, "bound": {"e": Bound(1.0, "r")}}
    comps = [
        Comparison("analytic", "c/native", ("native",), "closed form", params),
        Comparison("analytic", "c/yade", ("yade",), "closed form, YADE", params, pair="native-yade"),
    ]
    evaluate(res, Context("quick", None, available=frozenset({"yade"})), runs, comps)
    native, yade = res.records
    assert native.pair == "" and native.passed
    assert yade.pair == "native-yade" and not yade.passed and res.cell("native-yade")["state"] == "FAIL"
    assert list(res.matrix) == ["native-yade"]
    # YADE absent and no stored stand-in: its comparison is left out, its column not applicable
    res = CaseResult("c", "t", "d")
    runs[1] = dataclasses.replace(runs[1], live=True)
    out = evaluate(res, Context("quick", None), runs, comps)
    assert list(out.summaries) == ["c/native"] and "c/yade" in out.skipped
    assert res.cell("native-yade")["state"] == "n/a"
    with pytest.raises(ValueError, match="pair"):
        Comparison("analytic", "c/x", ("native",), "r", params, pair="native-chute")


def test_a_failed_run_gives_failing_evidence_and_a_view_is_what_the_judge_sees():
    from validation.judges import Bound
    from validation.matrix import Failed

    params = {"expected": [("", "e")], "values": lambda r: r, "bound": {"e": Bound(1.0, "r")}}
    runs = [
        Run("native", "native", "lammps", "native", lambda: {("", "e"): 0.5}),
        Run("lammps", "lammps", "lammps", "deck now", lambda: Failed("job killed at step 7"), live=True),
        Run("wrapped", "native", "lammps", "native", lambda: [{("", "e"): 0.25}]),
    ]
    comps = [
        Comparison("analytic", "c/lammps", ("lammps",), "closed form", params, pair="native-lammps"),
        Comparison("analytic", "c/native", ("native",), "closed form", params),
        Comparison("analytic", "c/wrapped", ("wrapped",), "closed form", params, view=lambda r: r[0]),
    ]
    res = CaseResult("c", "t", "d")
    out = evaluate(res, Context("quick", None, lammps=True), runs, comps)
    bad = [r for r in res.records if not r.passed]
    assert len(bad) == 1 and bad[0].pair == "native-lammps" and bad[0].quantity == "evidence"
    assert "incomplete: LAMMPS (lammps): job killed at step 7" == bad[0].metric
    assert res.cell("native-lammps")["state"] == "FAIL" and not res.passed
    assert "c/lammps" not in out.summaries and out.summaries["c/wrapped"][("", "e")] == {"native": 0.25}
    assert ("lammps", "LAMMPS", "LAMMPS", "deck now", "failed: job killed at step 7") in res.runs


def test_same_states_counts_differing_fields_and_fails_a_run_cut_short():
    from types import SimpleNamespace as S

    from validation.judges import same_states

    def st(k):
        return S(x=np.arange(3.0) + k, f=np.array([np.nan, 1.0]))

    a = [st(0), st(1), st(2)]
    kw = {"fields": ("x", "f"), "quantity": "scene", "metric": "m", "reason": "r", "sides": ("native", "YADE")}
    recs, _ = same_states("c", a, [st(0), st(1), st(2)], what="calls", **kw)
    assert all(r.passed for r in recs) and recs[-1].value == 0.0  # NaN equal to NaN
    b = [st(0), st(1), S(x=np.nextafter(a[2].x, 9.0), f=a[2].f)]
    recs, summary = same_states("c", a, b, what="calls", **kw)
    assert not recs[-1].passed and recs[-1].value == 1.0 and "first: calls 2: x" in recs[-1].metric
    assert summary["differing"] == [(2, ["x"])]
    recs, _ = same_states("c", a, a[:2], what="calls", **kw)  # YADE's last call missing
    assert [r.passed for r in recs] == [True, False, True] and "YADE calls" in recs[1].metric
    recs, _ = same_states("c", a, [], what="calls", **kw)  # nothing in common: NaN, fails
    assert not recs[-1].passed
    recs, _ = same_states("c", st(0), S(x=np.arange(2.0), f=st(0).f), **kw)  # one state each: a shape differs
    assert len(recs) == 1 and not recs[0].passed and recs[0].metric.endswith(": x")


def test_the_equilibria_judge_holds_two_stresses_at_rest_to_their_residuals_and_fails_a_missing_side():
    from types import SimpleNamespace

    from validation.judges import equilibria

    ref = np.array([[-2.0, 0.25], [0.25, -3.0]])  # max |sigma| = 3: the scale
    bump = np.array([[0.0, 0.0], [0.0, 1.0]])

    def side(d, rho=1e-6):
        return SimpleNamespace(sigma=ref + d * bump, rho=rho)

    kw = {"sides": ("native", "LAMMPS"), "metric": "m", "reason": "r", "amplification": 10.0, "roundoff": 1e-12}
    # tolerance 10 (1e-6 + 2e-6) + 1e-12 = 3.0000001e-5 of max |sigma_b|
    recs, s = equilibria("c", side(3 * 2.9e-5), side(0.0, 2e-6), **kw)
    (rec,) = recs
    assert rec.quantity == "stress" and rec.passed
    assert rec.value == pytest.approx(2.9e-5, rel=1e-9) and rec.tolerance == pytest.approx(3.0000001e-5, rel=1e-12)
    assert s["missing"] == [] and s["rho"] == (1e-6, 2e-6)
    recs, _ = equilibria("c", side(3 * 3.1e-5), side(0.0, 2e-6), **kw)
    assert not recs[0].passed and recs[0].value == pytest.approx(3.1e-5, rel=1e-9)
    # the residuals set the tolerance: the same difference passes between two less balanced states
    recs, _ = equilibria("c", side(3 * 3.1e-5, 2e-6), side(0.0, 2e-6), **kw)
    assert recs[0].passed
    # a missing side (None, or no stress): failing evidence naming it, and no stress judged
    for gone in (None, SimpleNamespace(sigma=None, rho=1e-6)):
        recs, s = equilibria("c", side(0.0), gone, **kw)
        (ev,) = recs
        assert ev.quantity == "evidence" and not ev.passed and "(missing: LAMMPS)" in ev.metric
        assert s["missing"] == ["LAMMPS"] and math.isnan(s["value"])
    # a NaN in a stress or a residual fails the stress record
    nan = side(0.0)
    nan.sigma[0, 1] = np.nan
    assert not equilibria("c", side(0.0), nan, **kw)[0][0].passed
    assert not equilibria("c", side(0.0, np.nan), side(0.0), **kw)[0][0].passed
    # complete evidence recorded on request (a column without its runs' own evidence)
    recs, _ = equilibria("c", side(0.0), side(0.0), record_evidence=True, **kw)
    assert [r.quantity for r in recs] == ["evidence", "stress"] and all(r.passed for r in recs)
    assert recs[0].metric == "complete: 2 of 2 equilibria at rest"
    with pytest.raises(ValueError, match="distinct"):
        equilibria("c", side(0.0), side(0.0), **{**kw, "sides": ("native", "native")})
    # a declared comparison of a native run and a code's run lands in their column
    res = CaseResult("c", "t", "d")
    runs = [
        Run("n", "native", "lammps", "native", lambda: side(0.0)),
        Run("l", "lammps", "lammps", "s", lambda: side(1.0)),
    ]
    params = {k: kw[k] for k in ("metric", "amplification", "roundoff")}
    evaluate(res, Context("quick", None), runs, [Comparison("equilibria", "c/x", ("n", "l"), "why", params)])
    (rec,) = res.records
    assert (
        rec.pair == "native-lammps"
        and not rec.passed
        and rec.reason == "why"
        and res.matrix == {"native-lammps": "why"}
    )


def test_final_state_judges_the_ends_and_takes_no_verdict_on_a_run_cut_short():
    from validation.judges import final_state

    rng = np.random.default_rng(3)
    x = rng.uniform(0, 1, (5, 2))
    L = np.ones((1, 2))
    saved = Trajectory(np.array([10]), np.zeros((1, 3)), L, {10: {"x": x}})
    full = _traj(n=5, steps=10, dump=10)
    fr = dict(full.frames)
    fr[10] = {**fr[10], "x": x + np.array([1.0, 0.0])}  # the same positions one box further
    run = dataclasses.replace(full, frames=fr)
    kw = {"step": 10, "d50": 0.1, "position_tol": 1e-12, "box_tol": 0.0, "reason": "r", "sides": ("file", "LIGGGHTS")}
    ev = (None, (np.arange(11), [0, 10]))
    recs, s = final_state("c", saved, run, evidence_of=ev, **kw)
    assert all(r.passed for r in recs) and s["x"] < 1e-14 and s["box"] == 0.0  # the wrap's rounding only
    fr[10] = {**fr[10], "x": fr[10]["x"] + 1e-9}
    recs, _ = final_state("c", saved, dataclasses.replace(full, frames=fr), evidence_of=ev, **kw)
    assert [r.quantity for r in recs if not r.passed] == ["position"]
    cut = _traj(n=5, steps=10, dump=10, drop_steps=3)  # the log and the last dump cut short
    recs, s = final_state("c", saved, cut, evidence_of=ev, **kw)
    assert {r.quantity for r in recs} == {"evidence"} and not all(r.passed for r in recs) and math.isnan(s["x"])


def test_frame_for_frame_judges_every_frame_and_fails_a_missing_one():
    """Runs seen at their frames only (the impacts): equal runs pass with 0; a velocity 1e-6 off fails
    its relative bound with that value; a frame missing on one side is failing evidence naming the
    step; no frame in common is NaN (fails); one run alone records its evidence only."""
    from validation.judges import FrameBound, frame_for_frame

    bounds = (
        FrameBound("x", "positions", "max |dx|/D over {n} frames ({a} vs {b})", 1e-10, "p", 0.1),
        FrameBound("v", "velocities", "max |dv|/max|v| ({a} vs {b})", 1e-8, "v"),
    )
    frames, sides = [0, 5, 10], ("native", "LAMMPS")
    a = _traj()
    recs, s = frame_for_frame("c/x", a, _traj(), frames=frames, bounds=bounds, sides=sides)
    assert all(r.passed for r in recs) and s == {"frames": 3, "positions": 0.0, "velocities": 0.0}
    assert [r.metric for r in recs if r.quantity == "positions"] == ["max |dx|/D over 3 frames (native vs LAMMPS)"]
    off = _traj()
    off.frames[5]["v"] = off.frames[5]["v"] * (1 + 1e-6)
    recs, s = frame_for_frame("c/x", a, off, frames=frames, bounds=bounds, sides=sides)
    (bad,) = [r for r in recs if not r.passed]
    top = max(float(np.abs(off.frames[k]["v"]).max()) for k in frames)  # relative to the largest |v| of b
    assert bad.quantity == "velocities"
    assert s["velocities"] == pytest.approx(1e-6 * float(np.abs(a.frames[5]["v"]).max()) / top, rel=1e-6)
    cut = _traj()
    del cut.frames[5]
    recs, s = frame_for_frame("c/x", a, cut, frames=frames, bounds=bounds, sides=sides)
    assert [r.metric for r in recs if not r.passed] == ["incomplete: expected 3 LAMMPS frames, got 2 (missing: 5)"]
    assert s["frames"] == 2
    empty = Trajectory(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 2)), {})
    recs, s = frame_for_frame("c/x", a, empty, frames=frames, bounds=bounds, sides=sides)
    assert {r.quantity for r in recs if not r.passed} == {"evidence", "positions", "velocities"}
    assert math.isnan(s["positions"])
    recs, _ = frame_for_frame("c/x", cut, frames=frames, bounds=bounds, sides=("LIGGGHTS",))
    assert [(r.quantity, r.passed) for r in recs] == [("evidence", False)]


def test_explained_measures_passes_a_law_difference_and_fails_any_other():
    """Two codes' answers per (impact, quantity): a difference that equals the native flavours' is
    explained (0) and within twice the analytic bound; the same difference with equal native runs is
    not (1e-4 > 1e-9); a missing answer is NaN (fails); slips are compared absolutely."""
    from validation.judges import Bound, explained_measures

    a = {("i1", "t"): 1.0, ("i2", "t"): 2.0, ("i1", "slip"): 0.0, ("i2", "slip"): 1e-6}
    b = {k: v * (1 + 1e-4) + (3e-9 if k[1] == "slip" else 0.0) for k, v in a.items()}
    kw = {
        "expected": list(a),
        "values": lambda r: r,
        "tolerance": 1e-9,
        "reason": "r",
        "sides": ("LIGGGHTS", "LAMMPS"),
        "absolute": ("slip",),
        "agree": {"t": Bound(2e-3, "twice")},
        "why": "w",
    }
    recs, s = explained_measures("c/cross", a, b, a, b, **kw)
    assert all(r.passed for r in recs) and s["t"] == {"raw": pytest.approx(1e-4), "unexplained": 0.0}
    assert [r.quantity for r in recs] == [
        "t: LIGGGHTS - LAMMPS",
        "t: difference explained by the native flavours",
        "t: LIGGGHTS vs LAMMPS",
        "slip: LIGGGHTS - LAMMPS",
        "slip: difference explained by the native flavours",
    ]
    assert s["slip"]["raw"] == pytest.approx(3e-9 + 1e-10, rel=1e-6)  # absolute, not relative to 0
    recs, s = explained_measures("c/cross", a, b, a, a, **kw)
    bad = {r.quantity for r in recs if not r.passed}
    assert bad == {
        "t: difference explained by the native flavours",
        "slip: difference explained by the native flavours",
    }
    assert s["t"]["unexplained"] == pytest.approx(1e-4)
    cut = {k: v for k, v in b.items() if k != ("i2", "t")}
    recs, s = explained_measures("c/cross", a, cut, a, b, **kw)
    assert math.isnan(s["t"]["unexplained"]) and not all(r.passed for r in recs if r.quantity.startswith("t:"))


def test_the_analytic_judge_makes_one_figure_of_several_runs():
    """An observed time-step order: the errors of a run at dt and at dt/2 give log2 of their ratio
    (the record's value; the summary keeps both errors); a run without an answer makes it NaN."""
    from validation.judges import Bound, analytic

    def order(item, q, vals):
        e1, e2 = vals.values()
        return math.log2(e1 / e2)

    kw = {
        "expected": [("", "t: order")],
        "values": lambda r: r,
        "bound": {"t: order": Bound(math.nan, "figure", "info")},
        "sides": ("dt", "dt/2"),
        "figure": order,
    }
    recs, s = analytic("c", {("", "t: order"): 4e-3}, {("", "t: order"): 1e-3}, **kw)
    assert recs[0].kind == "info" and recs[0].value == pytest.approx(2.0)
    assert s[("", "t: order")] == {"dt": 4e-3, "dt/2": 1e-3}
    recs, _ = analytic("c", {("", "t: order"): 4e-3}, {}, **kw)
    assert math.isnan(recs[0].value) and "no answer from dt/2" in recs[0].metric


def test_statistics_band_and_cross_judge_within_the_bands_and_need_every_run():
    from validation.judges import statistics_band, statistics_cross

    frames = [0, 5, 10]
    runs = {k: _traj(n=4, steps=10, dump=5, seed=k) for k in range(6)}
    level = {
        0: 0.0,
        1: 0.0,
        2: 0.1,
        3: -0.2,
        4: 0.05,
        5: 0.3,
    }  # native, ref a, members a, ref b, ... statistics offsets

    def stats(tr):
        k = next(i for i, t in runs.items() if t is tr)
        return np.full((len(frames), 2), level[k])

    kw = {"frames": frames, "statistics": stats, "checks": ((0, "mean_alpha"),), "reason": "r"}
    recs, s = statistics_band("c", runs[0], runs[1], runs[2], runs[3], factor=1.0, sides=("native", "L"), **kw)
    band = [r for r in recs if r.quantity == "mean_alpha"]
    assert s["complete"] and band[0].value == 0.0 and band[0].tolerance == pytest.approx(0.2) and band[0].passed
    level[0] = 0.25  # the native statistic beyond the band
    recs, _ = statistics_band("c", runs[0], runs[1], runs[2], runs[3], factor=1.0, sides=("native", "L"), **kw)
    assert [r.quantity for r in recs if not r.passed] == ["mean_alpha"]
    cut = _traj(n=4, steps=10, dump=5, seed=2, drop_steps=1)  # a member without its last frame
    runs[2] = cut
    recs, s = statistics_band("c", runs[0], runs[1], cut, runs[3], factor=1.0, sides=("native", "L"), **kw)
    assert not s["complete"] and {r.quantity for r in recs if not r.passed} == {"evidence"}
    runs[2] = _traj(n=4, steps=10, dump=5, seed=2)
    # two codes: |0.0 - 0.05| within the sum of their bands (0.2 + 0.25), not without a member of b
    recs, _ = statistics_cross("x", runs[1], runs[4], runs[2], runs[3], runs[5], n_a=2, sides=("L", "M"), **kw)
    q = [r for r in recs if r.quantity == "mean_alpha"][0]
    assert q.passed and q.value == pytest.approx(0.05) and q.tolerance == pytest.approx(0.2 + 0.25)
    recs, s = statistics_cross("x", runs[1], runs[4], runs[2], runs[3], n_a=2, sides=("L", "M"), **kw)
    assert not s["complete"] and not all(r.passed for r in recs)
