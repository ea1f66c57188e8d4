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
    monkeypatch.setattr(I, "native_settings", lambda law, dt, fl: dataclasses.replace(
        orig(law, dt, fl), gamma_n=1.01 * law.gamma_n))
    res = I.impacts(_ctx(tmp_path))
    assert not res.passed
    assert _failed(res, "restitution")


def test_fails_when_stiffness_is_off_by_one_percent(tmp_path, monkeypatch):
    _only(monkeypatch, "normal-z0")
    orig = I.native_settings
    monkeypatch.setattr(I, "native_settings", lambda law, dt, fl: dataclasses.replace(
        orig(law, dt, fl), kn=1.01 * law.kn))
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
