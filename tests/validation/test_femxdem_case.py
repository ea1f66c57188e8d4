"""femxdem-short: a Gauss point of the FEM x DEM run replayed in YADE, judged bit for bit.

The native 2 x 4 run is made once (module fixture); YADE's side is the real replay (YADE installed)
or a stand-in that shows how the case treats incomplete or different evidence: an output cut short
(the reader refuses it: incomplete), an output missing its last call, a state 1 ulp off, YADE absent.
"""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np
import pytest

from reference_runs.yade.rve import OUTPUT_MAGIC, read_rve_out
from validation.cases import femxdem as fx
from validation.core import Context

HAVE_YADE = shutil.which("yade") is not None


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    out = tmp_path_factory.mktemp("fxcase") / "native"
    return fx.native_history(out)


@pytest.fixture
def case(native, tmp_path, monkeypatch):
    monkeypatch.setattr(fx, "native_history", lambda out, spec=fx.SPEC: native)
    ctx = Context(suite="default", results=tmp_path / "results")

    def run(replay, available=True):
        monkeypatch.setattr(fx, "yade_available", lambda: available)
        return fx.femxdem_short(ctx, replay=replay)

    return run


def _native_replay(job_dir, increments, timeout):
    return fx.native_calls(increments), {"engine_version": "stand-in"}


def test_the_native_gauss_point_is_a_single_rve_driven_by_its_history(native):
    summary, g, committed = native
    assert g == int(np.argmax(summary["fields"][2]["deviatoric_strain"])) and committed.updates == 2
    assert fx.differing_fields(fx.native_calls(committed.increments)[-1], committed.rve) == []


@pytest.mark.skipif(not HAVE_YADE, reason="yade binary not installed (apt-get install yade)")
def test_yade_replay_equals_the_native_rve_bit_for_bit(case):
    res = case(fx.yade_replay)
    assert res.passed, [(r.quantity, r.metric, r.value) for r in res.checks if not r.passed]
    names = {r.quantity for r in res.checks}
    assert {"position", "velocity", "spin", "stress", "saved_scene", "prepared_rve"} <= names
    yade = [r for r in res.checks if r.pair != "native-lammps"]  # (LAMMPS' side is round-off)
    assert all(r.value == 0.0 for r in yade if r.quantity != "evidence")


def test_an_output_cut_short_is_incomplete(case):
    def cut(job_dir, increments, timeout):
        p = job_dir / "rve.out"
        p.write_text(OUTPUT_MAGIC + "\n" + '{"call": 0}\n')  # killed before its calls and END
        return read_rve_out(p), {}

    res = case(cut)
    assert not res.passed
    bad = [r for r in res.checks if not r.passed]
    assert bad and "incomplete" in bad[0].metric and "no header or no END" in bad[0].metric


def test_a_missing_call_fails_as_evidence(case):
    res = case(lambda j, inc, t: (fx.native_calls(inc)[:-1], {}))
    assert not res.passed
    ev = [r for r in res.checks if r.quantity == "evidence" and not r.passed]
    assert any("YADE" in r.metric for r in ev)


def test_one_ulp_in_one_spin_fails(case):
    def off(job_dir, increments, timeout):
        states = fx.native_calls(increments)
        w = np.array(states[-1].spins)
        w[7] = np.nextafter(w[7], np.inf)
        states[-1] = dataclasses.replace(states[-1], spins=w)
        return states, {}

    res = case(off)
    failed = {r.quantity for r in res.checks if not r.passed}
    assert failed == {"spin", "saved_scene"}
    assert case(_native_replay).passed  # the same run with the native states as YADE's: passes


def test_yade_absent_is_said(case):
    res = case(_native_replay, available=False)
    assert not res.passed and "YADE is not installed" in res.error


HAVE_LMP = shutil.which("lmp") is not None


def _lammps_cells(res):
    return [r for r in res.records if r.pair == "native-lammps"]


@pytest.mark.skipif(not HAVE_LMP, reason="lmp (LAMMPS) not installed")
def test_lammps_replay_agrees_to_round_off(case):
    res = case(_native_replay)
    recs = _lammps_cells(res)
    assert recs and all(r.passed for r in recs), [r for r in recs if not r.passed]
    assert {r.quantity for r in recs} >= {"evidence", "position", "stress"}
    assert any("LAMMPS" in t[0] for t in res.tables)


def test_lammps_replay_missing_a_call_fails(case, monkeypatch):
    # LAMMPS' states with the last call cut off: incomplete evidence, the case fails
    def short(job_dir, rve, inc, timeout):
        return rve.replay(inc)[:-1]

    monkeypatch.setattr(fx, "replay_in_lammps", short)
    monkeypatch.setattr(fx, "lammps_available", lambda: True)
    res = case(_native_replay)
    bad = [r for r in _lammps_cells(res) if not r.passed]
    assert bad and any(r.quantity == "evidence" for r in bad) and not res.passed


def test_lammps_replay_off_by_more_than_round_off_fails(case, monkeypatch):
    # one disk moved by 1e-9 D50 on LAMMPS' side after the last call: beyond the round-off bound
    def moved(job_dir, rve, inc, timeout):
        states = rve.replay(inc)
        states[-1]["positions"] = states[-1]["positions"].copy()
        states[-1]["positions"][7, 0] += 1e-9 * 2 * float(np.median(rve.packing.radii))
        return states

    monkeypatch.setattr(fx, "replay_in_lammps", moved)
    monkeypatch.setattr(fx, "lammps_available", lambda: True)
    res = case(_native_replay)
    bad = [r for r in _lammps_cells(res) if not r.passed]
    assert [r.quantity for r in bad] == ["position"] and not res.passed


def test_lammps_absent_is_missing_evidence(case, monkeypatch):
    monkeypatch.setattr(fx, "lammps_available", lambda: False)
    res = case(_native_replay)
    assert not res.passed and any("LAMMPS is not installed" in n for n in res.notes)
