"""fast-order: the fast ordering passes within the code order's own envelope, and the case fails on
a fast run off by more than the envelope allows or on missing evidence (shorter runs here)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from validation.cases import fast_order as fo
from validation.core import Context


@pytest.fixture
def short(monkeypatch):
    monkeypatch.setattr(fo, "NSTEPS", 3000)
    monkeypatch.setattr(fo, "DUMP_EVERY", 1000)
    monkeypatch.setattr(fo, "RULE", dataclasses.replace(fo.RULE, window=1000))


def _run_case(tmp_path):
    return fo.fast_order(Context(suite="default", results=tmp_path / "results"))


def test_fast_order_is_within_the_envelope(short, tmp_path):
    res = _run_case(tmp_path)
    assert res.passed, [(r.case, r.quantity, r.metric, r.value) for r in res.records if not r.passed]
    judged = {(r.case, r.quantity) for r in res.records if r.tolerance == fo.RULE.factor}
    assert judged == {(f"fast-order/{c}", q) for c in ("orthogonal", "sheared") for q in ("position", "stress")}
    assert all(not r.pair for r in res.records)  # no code: outside the matrix


def _patched(monkeypatch, change):
    real = fo.run

    def run(packing, settings, loading, cell, order, threads=None):
        tr = real(packing, settings, loading, cell, order, threads)
        return change(tr) if order == "fast" else tr

    monkeypatch.setattr(fo, "run", run)


def test_a_fast_run_off_by_1e_6_d50_fails(short, tmp_path, monkeypatch):
    def moved(tr):
        frames = {k: dict(f) for k, f in tr.frames.items()}
        last = max(frames)
        frames[last]["x"] = frames[last]["x"].copy()
        frames[last]["x"][3, 0] += 1e-6 * 0.002  # D50 ~ 2 mm
        return dataclasses.replace(tr, frames=frames)

    _patched(monkeypatch, moved)
    res = _run_case(tmp_path)
    bad = {r.quantity for r in res.records if not r.passed}
    assert not res.passed and bad == {"position"}


def test_a_fast_run_missing_a_frame_fails(short, tmp_path, monkeypatch):
    def cut(tr):
        frames = {k: f for k, f in tr.frames.items() if k != max(tr.frames)}
        return dataclasses.replace(
            tr, frames=frames, steps=tr.steps[:-5], stress=tr.stress[:-5], lengths=tr.lengths[:-5]
        )

    _patched(monkeypatch, cut)
    res = _run_case(tmp_path)
    bad = [r for r in res.records if not r.passed]
    assert not res.passed and any(r.quantity == "evidence" for r in bad)
    assert np.isfinite([r.value for r in bad if r.quantity == "evidence"]).all()
