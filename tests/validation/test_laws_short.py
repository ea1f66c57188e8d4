"""The laws-short case (every contact law, native vs its code's stored run, step for step) passes on
the stored runs and fails when the native law is off by 1% (a stiffness) or the stored run is cut."""

from __future__ import annotations

import shutil

import pytest

import validation.cases.laws_short as L
from validation.core import Context


def _ctx(tmp_path):
    return Context("default", tmp_path / "results", liggghts=False, lammps=False)


def _only(monkeypatch, name, law=None):
    monkeypatch.setattr(L, "SHORT_CASE_LAWS", (name,))
    if law is not None:
        monkeypatch.setattr(L, "short_case_law", lambda n: law)


def test_hertz_stored_run_passes_bit_for_bit(tmp_path, monkeypatch):
    _only(monkeypatch, "hertz-liggghts")
    res = L.laws_short(_ctx(tmp_path))
    assert res.passed, [r for r in res.records if not r.passed]
    (row,) = res.tables[0][2]
    assert row[5:] == [0.0, 0.0, 0.0, 0.0]  # positions, velocities, forces, stress: the doubles are equal


@pytest.mark.parametrize("name, field", [("hertz-liggghts", "yeff"), ("hooke-epsd2-liggghts", "mu_r")])
def test_one_percent_off_fails(tmp_path, monkeypatch, name, field):
    law = L.short_case_law(name)  # a namedtuple of the law's parameters (yeff: Y*, mu_r: rolling friction)
    _only(monkeypatch, name, law._replace(**{field: getattr(law, field) * 1.01}))
    res = L.laws_short(_ctx(tmp_path))
    assert not res.passed
    assert any(r.quantity == "position" and not r.passed for r in res.records)


def test_cut_stored_run_is_incomplete(tmp_path, monkeypatch):
    src = L.stored_dir("biaxial-short-hertz-lammps")
    cut = tmp_path / "stored" / "biaxial-short-hertz-lammps"
    shutil.copytree(src, cut)
    dump = cut / "dump.atoms"
    text = dump.read_text()
    dump.write_text(text[: len(text) // 2])  # half the frames
    _only(monkeypatch, "hertz-lammps")
    monkeypatch.setattr(L, "stored_dir", lambda name: cut)
    res = L.laws_short(_ctx(tmp_path))
    assert not res.passed
    assert any(r.quantity == "evidence" and not r.passed for r in res.records)
