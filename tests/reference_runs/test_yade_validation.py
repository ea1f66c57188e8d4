"""The validation case taylor-rve-yade: gransim's Taylor stress and the material part of its tangent
against YADE's getStressAndTangent on standard RVEs, and its verdict on incomplete evidence (an
output cut short, a state missing, YADE absent).

The case runs all 15 RVEs at every state in the full suite (about 2 minutes of YADE); here it runs
one RVE of each size (70, 350, 700 disks) at every 10th state (24 states each): the tolerances are
the case's (reference_runs.yade.compare: STRESS_RTOL 1e-10, TANGENT_RTOL 1e-12, with their reasons).
"""

import dataclasses
import shutil

import pytest

import reference_runs.yade.taylor as yade_taylor
import validation.cases.taylor_yade as case_mod
from reference_runs.yade.compare import STRESS_RTOL, TANGENT_RTOL
from validation.core import Context

needs_yade = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)
SUBSET = {"names": ["rve-70-1", "rve-350-1", "rve-700-1"], "stride": 10}


@pytest.fixture
def subset(monkeypatch, tmp_path):
    monkeypatch.setitem(case_mod.SUITE_SETTINGS, "quick", SUBSET)
    return Context(suite="quick", results=tmp_path)


def test_case_is_in_the_full_suite_only():
    """All 15 RVEs at every state cost about 95 s of YADE: the full suite only."""
    from validation.core import registered_cases

    assert "taylor-rve-yade" in [c.id for c in registered_cases("full")]
    assert "taylor-rve-yade" not in [c.id for c in registered_cases("default")]
    assert "taylor-rve-yade" not in [c.id for c in registered_cases("quick")]


def _failing(res):
    return [r for r in res.checks if not r.passed]


@needs_yade
def test_yade_matches_gransims_taylor_stress_and_tangent_on_rves_at_round_off(subset):
    res = case_mod.taylor_rve_yade(subset)
    assert res.error is None and not _failing(res), [r.metric for r in _failing(res)]
    assert res.passed
    assert res.records[0].metric == "complete: 3 of 3 RVEs run by YADE"
    by = {q: [r for r in res.checks if r.quantity == q] for q in ("stress", "tangent", "contacts", "evidence")}
    assert len(by["stress"]) == 3 * 4 * 2 and len(by["tangent"]) == 12 and len(by["contacts"]) == 12
    assert all(r.metric == "complete: 6 of 6 YADE states" for r in by["evidence"][1:])
    # round-off, well inside the stated tolerances (measured: 1.4e-13 and 4.8e-15 on the 15 RVEs)
    assert max(r.value for r in by["stress"]) < STRESS_RTOL / 100
    assert max(r.value for r in by["tangent"]) < TANGENT_RTOL / 10
    assert [row[0] for row in res.tables[0][2]] == SUBSET["names"]


@needs_yade
def test_a_yade_output_cut_short_fails_the_case_as_incomplete(subset, monkeypatch):
    cut = "\ntext = open('taylor.out').read()\nopen('taylor.out', 'w').write(text[: len(text) // 2])\n"
    monkeypatch.setitem(case_mod.SUITE_SETTINGS, "quick", {"names": ["rve-70-2"], "stride": 25})
    monkeypatch.setattr(yade_taylor, "TAYLOR_SCRIPT", yade_taylor.TAYLOR_SCRIPT + cut)
    res = case_mod.taylor_rve_yade(subset)
    assert not res.passed
    bad = _failing(res)
    assert bad[0].metric == "incomplete: expected 1 RVEs run by YADE, got 0 (missing: rve-70-2)"
    assert any("incomplete: YADE job failed" in r.metric and "cut short" in r.metric for r in bad)
    assert not [r for r in res.checks if r.quantity in ("stress", "tangent")]  # nothing judged on what remains


@needs_yade
def test_a_state_missing_from_a_complete_job_fails_the_case(subset, monkeypatch):
    """A run that lacks one state of one path (here dropped after reading) is incomplete evidence."""
    real = case_mod.run_yade_taylor

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

    monkeypatch.setitem(case_mod.SUITE_SETTINGS, "quick", {"names": ["rve-70-3"], "stride": 25})
    monkeypatch.setattr(case_mod, "run_yade_taylor", drop_last)
    res = case_mod.taylor_rve_yade(subset)
    bad = _failing(res)
    assert not res.passed and len(bad) == 1
    assert bad[0].case == "taylor-rve-yade/70-3/shear21"
    assert bad[0].metric == "incomplete: expected 3 YADE states, got 2 (missing: 50)"


def test_without_yade_the_case_fails_saying_so(subset, monkeypatch, tmp_path):
    monkeypatch.setitem(case_mod.SUITE_SETTINGS, "quick", {"names": ["rve-70-1"], "stride": 25})
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    res = case_mod.taylor_rve_yade(subset)
    assert not res.passed and "YADE is not installed" in res.error and "apt-get install yade" in res.error
    assert res.records[0].metric.startswith("incomplete: expected 1 RVEs run by YADE, got 0")
