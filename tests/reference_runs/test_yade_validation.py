"""taylor-rve's YADE column: gransim's Taylor stress and the material part of its tangent against
YADE's getStress and getStressAndTangent on standard RVEs, and its verdict on incomplete evidence (an
output cut short, a state missing, YADE absent).

The full suite runs the column on all 15 RVEs at every state (about 95 s of YADE); here it runs one RVE
of each size (70, 350, 700 disks) at every 10th state (24 states each): the tolerances are the column's
(reference_runs.yade.compare: STRESS_RTOL 1e-10, TANGENT_RTOL 1e-12, with their reasons). The column is
made as the case makes it (validation.cases.taylor.yade_plan, judged by validation.matrix.evaluate).
"""

import dataclasses
import shutil

import pytest

import reference_runs.yade.taylor as yade_taylor
import validation.yade_runs as yade_runs
from gransim import generation
from gransim.io import load_packing
from reference_runs.yade.compare import STRESS_RTOL, TANGENT_RTOL
from validation.cases import taylor
from validation.codes import NATIVE
from validation.core import CaseResult, Context
from validation.matrix import Run, evaluate

needs_yade = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)
SUBSET = {"names": ["rve-70-1", "rve-350-1", "rve-700-1"], "stride": 10}


def _column(tmp_path, monkeypatch, settings, have_yade=True) -> CaseResult:
    """taylor-rve's YADE column alone (its runs, its comparison, gransim's Taylor material) on the RVEs
    and stride of ``settings``, in the full suite."""
    monkeypatch.setitem(taylor.YADE_SETTINGS, "full", settings)
    ctx = Context(suite="full", results=tmp_path, available=frozenset({"yade"} if have_yade else ()))
    paths = generation.standard_packings(tmp_path / "packings", names=settings["names"])
    packings = {n: load_packing(p) for n, p in paths.items()}
    runs, comps = taylor.yade_plan(ctx, packings, "full")
    native = Run("native", NATIVE, "", "gransim's Taylor material", lambda: taylor._material)
    res = CaseResult(taylor.CASE, "YADE column", "")
    out = evaluate(res, ctx, [native, *runs], comps)
    res.tables.append(("", [], out.summaries[comps[0].label]["rows"]))
    return res


def _failing(res):
    return [r for r in res.checks if not r.passed]


def test_taylor_rve_carries_yades_column_and_the_full_suite_asks_for_every_state_of_the_15_rves():
    """One judge per criterion: YADE's Taylor states are a column of taylor-rve (no case of their own),
    and the full suite gives it the whole study."""
    from validation.core import registered_cases

    for suite in ("quick", "default", "full"):
        assert "taylor-rve-yade" not in [c.id for c in registered_cases(suite)]
    assert taylor.YADE_SETTINGS["full"] == {"names": None, "stride": 1}


@needs_yade
def test_yade_matches_gransims_taylor_stress_and_tangent_on_rves_at_round_off(tmp_path, monkeypatch):
    res = _column(tmp_path, monkeypatch, SUBSET)
    assert res.error is None and not _failing(res), [r.metric for r in _failing(res)]
    assert res.passed and res.cell("native-yade")["state"] == "pass"
    assert res.records[0].metric == "complete: 3 of 3 RVEs run by YADE"
    by = {q: [r for r in res.checks if r.quantity == q] for q in ("stress", "tangent", "contacts", "evidence")}
    assert len(by["stress"]) == 3 * 4 * 2 and len(by["tangent"]) == 12 and len(by["contacts"]) == 12
    assert all(r.metric == "complete: 6 of 6 YADE states" for r in by["evidence"][1:])
    # round-off, well inside the stated tolerances (measured: 1.4e-13 and 4.8e-15 on the 15 RVEs)
    assert max(r.value for r in by["stress"]) < STRESS_RTOL / 100
    assert max(r.value for r in by["tangent"]) < TANGENT_RTOL / 10
    assert [row[0] for row in res.tables[0][2]] == sorted(SUBSET["names"])
    assert all(float(row[-1]) > 0 for row in res.tables[0][2])  # YADE's own seconds, from its manifest


@needs_yade
def test_a_yade_output_cut_short_fails_the_column_as_incomplete(tmp_path, monkeypatch):
    cut = "\ntext = open('taylor.out').read()\nopen('taylor.out', 'w').write(text[: len(text) // 2])\n"
    monkeypatch.setattr(yade_taylor, "TAYLOR_SCRIPT", yade_taylor.TAYLOR_SCRIPT + cut)
    res = _column(tmp_path, monkeypatch, {"names": ["rve-70-2"], "stride": 25})
    assert not res.passed and res.cell("native-yade")["state"] == "FAIL"
    bad = _failing(res)
    assert bad[0].metric == "incomplete: expected 1 RVEs run by YADE, got 0 (missing: rve-70-2)"
    assert any("incomplete: YADE job failed" in r.metric and "cut short" in r.metric for r in bad)
    assert not [r for r in res.checks if r.quantity in ("stress", "tangent")]  # nothing judged on what remains


@needs_yade
def test_a_state_missing_from_a_complete_job_fails_the_column(tmp_path, monkeypatch):
    """A run that lacks one state of one path (here dropped after reading) is incomplete evidence."""
    real = yade_runs.run_yade_taylor

    def drop_last(*a, **k):
        run = real(*a, **k)
        keep = slice(0, len(run.states) - 1)
        return dataclasses.replace(
            run,
            states=run.states[keep],
            F=run.F[keep],
            cauchy=run.cauchy[keep],
            tangent=run.tangent[keep],
            n_contacts=run.n_contacts[keep],
            raw=run.raw[keep],
        )

    monkeypatch.setattr(yade_runs, "run_yade_taylor", drop_last)
    res = _column(tmp_path, monkeypatch, {"names": ["rve-70-3"], "stride": 25})
    bad = _failing(res)
    assert not res.passed and len(bad) == 1
    assert bad[0].case == "taylor-rve/yade/70-3/shear21"
    assert bad[0].metric == "incomplete: expected 3 YADE states, got 2 (missing: 50)"


def test_without_yade_a_suite_asking_for_more_than_the_stored_states_fails_as_incomplete(tmp_path, monkeypatch):
    """YADE absent, the stored outputs (rve-70-1..3, every 5th state) stand in: the full suite's RVEs
    beyond them are missing evidence, named, never a pass on the RVEs that remain."""
    res = _column(tmp_path, monkeypatch, {"names": ["rve-70-1", "rve-350-1"], "stride": 5}, have_yade=False)
    assert not res.passed and res.cell("native-yade")["state"] == "FAIL"
    assert any("YADE is absent" in n and "stored/yade is compared instead" in n for n in res.notes)
    bad = _failing(res)
    assert bad[0].metric == "incomplete: expected 2 RVEs run by YADE, got 1 (missing: rve-350-1)"
    assert any(r.case == "taylor-rve/yade/350-1" and r.metric.startswith("incomplete: YADE job failed") for r in bad)
    assert not [r for r in bad if "70-1" in r.case]  # the stored RVE itself is judged, and passes
