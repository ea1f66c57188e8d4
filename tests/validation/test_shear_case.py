"""Validation case ``simple-shear`` (quick suite, stored LAMMPS and YADE runs only): it passes on the
stored data, and it fails on damaged evidence (a cut log, a cut dump, a cut YADE output) and on a
perturbed native side."""

from __future__ import annotations

import dataclasses
import shutil
from pathlib import Path

import numpy as np
import pytest

import validation.runner as vrunner
from reference_runs import store
from validation import dem_compare
from validation.runner import run_validation

CASE = "simple-shear"


def _quiet(*_a, **_k):
    pass


@pytest.fixture
def stored_copy(tmp_path, monkeypatch):
    """A copy of the stored shear runs that the case reads instead; LAMMPS and LIGGGHTS reported
    absent (only the stored evidence is compared)."""
    dest = tmp_path / "stored"
    dest.mkdir()
    for name in ("shear-short-lammps", "shear-full-lammps", "simple-shear-yade"):
        if (Path(store.STORED) / name).exists():
            shutil.copytree(Path(store.STORED) / name, dest / name)
    monkeypatch.setattr(store, "STORED", dest)
    monkeypatch.setattr(vrunner, "liggghts_available", lambda: False)
    monkeypatch.setattr(vrunner, "lammps_available", lambda: False)
    monkeypatch.setattr(vrunner, "_available", lambda code: False)
    return dest


def _run(tmp_path):
    ok, results = run_validation("quick", tmp_path / "results", only=[CASE], log=_quiet)
    (res,) = results
    return ok, res


def _failed(res) -> set:
    return {(r.case, r.quantity) for r in res.checks if not r.passed}


def test_case_passes_on_stored_runs_with_the_matrix_cells(stored_copy, tmp_path):
    ok, res = _run(tmp_path)
    assert ok and res.passed, [r for r in res.records if not r.passed]
    assert res.matrix.keys() == {"native-lammps", "native-yade"}
    assert set(res.not_applicable) == {"native-liggghts", "liggghts-lammps", "liggghts-yade", "lammps-yade"}
    assert "ghost" in res.not_applicable["native-liggghts"] and "ghost" in res.not_applicable["liggghts-yade"]
    assert "LAMMPS is not installed" in res.not_applicable["lammps-yade"]
    for name in ("constant-volume", "servo"):  # YADE's stored sheared cells, bit for bit
        yade = [r for r in res.checks if r.case == f"{CASE}/yade-120/{name}"]
        assert {r.quantity for r in yade} >= {"evidence", "position", "velocity", "stress", "box"}
        assert all(r.pair == "native-yade" and r.tolerance == 0.0 and r.value == 0.0 for r in yade)
    qty = {(r.case, r.quantity) for r in res.checks}
    for name in ("constant-volume", "servo"):
        for q in ("position", "velocity", "spin", "particle_force", "particle_torque", "stress", "box"):
            assert (f"{CASE}/stored-120/{name}", q) in qty
        for q in ("cell_list", "alpha", "w"):
            assert (f"{CASE}/voidcells-120/{name}", q) in qty
    assert all(r.pair in ("native-lammps", "native-yade") and r.reason for r in res.records)
    # the evidence covers every thermo step (3001; YADE's every 10th: 301) and every dump frame (7) on both sides
    ev = [r.metric for r in res.records if r.quantity == "evidence"]
    assert sum("3001 of 3001" in m for m in ev) == 4 and sum("7 of 7" in m for m in ev) == 12
    assert sum("301 of 301" in m for m in ev) == 4
    assert any("LAMMPS is absent" in n for n in res.notes)
    figs = {p.name for p, _ in res.figures}
    assert {"simple_shear_voidcells.png", "simple_shear_short.png"} <= figs


def _cut_log(path: Path, last_step: int) -> None:
    out = []
    for line in path.read_text().splitlines():
        out.append(line)
        f = line.split()
        if f and f[0].isdigit() and int(f[0]) == last_step:
            break
    path.write_text("\n".join(out) + "\n")


def test_truncated_stored_log_fails_as_incomplete(stored_copy, tmp_path):
    _cut_log(stored_copy / "shear-short-lammps" / "servo" / "log.lammps", 1200)
    ok, res = _run(tmp_path)
    assert not ok and not res.passed and res.error is None
    bad = [r.metric for r in res.records if r.quantity == "evidence" and not r.passed]
    assert any(m.startswith("incomplete: expected 3001 LAMMPS series steps, got 1201") for m in bad), bad
    assert any(m.startswith("incomplete stored job") for m in bad), bad
    # the undamaged constant-volume run still passes on its own
    assert not any("constant-volume" in c for c, _ in _failed(res))


def test_truncated_stored_dump_fails_as_incomplete(stored_copy, tmp_path):
    dump = stored_copy / "shear-short-lammps" / "constant-volume" / "dump.atoms"
    lines = dump.read_text().splitlines()
    starts = [k for k, line in enumerate(lines) if line.startswith("ITEM: TIMESTEP")]
    dump.write_text("\n".join(lines[: starts[3] + 40]) + "\n")  # 3 frames and a cut 4th one
    ok, res = _run(tmp_path)
    assert not ok and not res.passed
    bad = [r.metric for r in res.records if r.quantity == "evidence" and not r.passed]
    # the parser refuses the cut dump as a whole: no LAMMPS frame counts
    assert any(m.startswith("incomplete: expected 7 LAMMPS frames, got 0") for m in bad), bad
    assert any(m.startswith("incomplete stored job") for m in bad), bad


def test_one_percent_stiffer_native_contacts_fail_step_for_step(stored_copy, tmp_path, monkeypatch):
    def stiffer(settings, loading):
        return dataclasses.replace(settings, kn=1.01 * settings.kn, kt=1.01 * settings.kt), loading

    monkeypatch.setattr(dem_compare, "native_setup", stiffer)
    ok, res = _run(tmp_path)
    assert not ok and not res.passed and res.error is None
    bad = _failed(res)
    for name in ("constant-volume", "servo"):
        for q in ("position", "velocity", "particle_force", "stress"):
            assert (f"{CASE}/stored-120/{name}", q) in bad, (name, q)
    assert (f"{CASE}/stored-120/servo", "box") in bad  # the servo follows the stiffer stress
    # the evidence itself is complete: the failure is the physics, not missing data
    assert all(r.passed for r in res.records if r.quantity == "evidence")


def test_dropped_servo_fails_the_box(stored_copy, tmp_path, monkeypatch):
    def no_servo(settings, loading):
        return settings, dataclasses.replace(loading, y="fixed", gain=0.0) if loading.y == "servo" else loading

    monkeypatch.setattr(dem_compare, "native_setup", no_servo)
    ok, res = _run(tmp_path)
    assert not ok
    bad = _failed(res)
    assert (f"{CASE}/stored-120/servo", "box") in bad
    assert not any("constant-volume" in c for c, _ in bad)


def test_sheared_snapshot_uses_the_tilted_cell_and_the_box_rate():
    from validation.cases.shear import box_rate, reduce_sheared, sheared_snapshot
    from validation.dem_compare import Trajectory

    # a hand-made series: box (lx, ly, xy) with xy growing by 0.1 m per step of 1e-3 s
    steps = np.array([0, 1, 2])
    box = np.array([[1.0, 1.0, 0.0], [1.0, 1.0, 0.1], [1.0, 1.0, 0.2]])
    # disk 0's image above, x0 + a2 = (0.3, 1.05), touches disk 1 (gap 0.08 - 0.11 < 0) only through
    # the tilt: without it the image is at (0.2, 1.05), 0.128 away
    x = np.array([[0.2, 0.05], [0.3, 0.97]])
    v = np.array([[0.1, 0.0], [0.0, 0.0]])
    fr = {"x": x, "v": v, "w": np.zeros(2), "f": np.zeros((2, 2)), "t": np.zeros(2)}
    tr = Trajectory(steps, np.zeros((3, 3)), box, {1: fr})
    np.testing.assert_allclose(box_rate(tr, 1, 1e-3), [[0.0, 100.0], [0.0, 0.0]], rtol=1e-12, atol=0)
    snap = sheared_snapshot(tr, 1, np.array([0.05, 0.06]), 1e-3)
    np.testing.assert_array_equal(snap.cell, [[1.0, 0.1], [0.0, 1.0]])
    np.testing.assert_array_equal(snap.velocities, v)  # remap v: lab velocities, nothing added
    assert len(snap.contacts_i) == 1
    assert tuple(np.abs(snap.contacts_shift[0])) == (0, 1)
    # reduction modulo the sheared cell: a2 = (xy, ly) is removed, not (0, ly)
    d = np.array([[0.1 + 1e-12, 1.0]])
    np.testing.assert_allclose(reduce_sheared(d, snap.cell), [[1e-12, 0.0]], atol=1e-16)


def test_truncated_stored_yade_output_fails_as_incomplete(stored_copy, tmp_path):
    import gzip

    gz = stored_copy / "simple-shear-yade" / "servo" / "dem.out.gz"
    text = gzip.decompress(gz.read_bytes())
    gz.write_bytes(gzip.compress(text[: 2 * len(text) // 3]))
    ok, res = _run(tmp_path)
    assert not ok and not res.passed and res.error is None
    assert res.cell("native-yade")["state"] == "FAIL" and res.cell("native-lammps")["state"] == "pass"
    bad = [r.metric for r in res.records if r.case == f"{CASE}/yade-120/servo" and not r.passed]
    assert any(m.startswith("incomplete: stored YADE output: incomplete:") for m in bad), bad
    assert not any("constant-volume" in c for c, _ in _failed(res))
