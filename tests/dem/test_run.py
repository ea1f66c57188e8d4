"""DEM run files: HDF5 layout, resume bit for bit, refusal of a foreign file, NaN handling,
biaxial protocol, CLI, VTK and plot."""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest

from gransim.cli import main
from gransim.dem import AxisControl, DEMEngine, DEMSettings, Loading
from gransim.dem.biaxial import (
    BiaxialSettings,
    biaxial_phases,
    default_settings,
    inertial_number,
    run_biaxial,
)
from gransim.dem.lattice import lattice_packing
from gransim.dem.output import OutputSettings, read_run, read_snapshot, snapshot_to_vtu
from gransim.dem.run import Phase, run_phases
from gransim.errors import InputError, ResultFileError, SimulationError
from gransim.io import save_packing

SETTINGS = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
LOADING = Loading(x=AxisControl("servo", target=100.0, gain=1e-2), y=AxisControl("rate", rate=-1.0))


@pytest.fixture(scope="module")
def packing():
    return lattice_packing(8, 8, seed=2, spread=0.1, compression=0.04)


def test_run_file_layout_and_stress_series(tmp_path, packing):
    out = tmp_path / "run.h5"
    run_phases(
        packing,
        SETTINGS,
        [Phase("load", LOADING, 600)],
        out,
        OutputSettings(series_every=2, snapshot_every=200, checkpoint_every=0),
        show_progress=False,
    )
    run = read_run(out)
    assert run.complete and run.stop_reason == ""
    np.testing.assert_array_equal(run.series["step"], np.arange(0, 601, 2))
    assert run.snapshot_steps == (0, 200, 400, 600)
    # the series equals an engine run without output (same trajectory)
    eng = DEMEngine(packing, SETTINGS)
    res = eng.advance(LOADING, 600)
    # files are tension positive; the engine's series is LIGGGHTS' compression-positive virial
    np.testing.assert_array_equal(run.series["stress"][1:], -res["stress"][1::2])
    np.testing.assert_array_equal(run.series["cell"][-1], eng.cell)
    snap = read_snapshot(out, 600)
    np.testing.assert_array_equal(snap.positions, eng.x)
    # contacts: l_ij = x_j + C n - x_i gives the stored overlaps
    c = snap.contacts
    lvec = snap.positions[c["j"]] + c["shift"] @ snap.cell.T - snap.positions[c["i"]]
    np.testing.assert_allclose(
        snap.radii[c["i"]] + snap.radii[c["j"]] - np.linalg.norm(lvec, axis=1), c["overlap"], atol=1e-15
    )
    with h5py.File(out) as f:
        assert f.attrs["kind"] == "dem-run"
        assert f["snapshots/s0000000600/contacts/force"].compression == "gzip"
    vtu = snapshot_to_vtu(out, None, tmp_path / "s.vtu")
    assert vtu.stat().st_size > 0
    with pytest.raises(ResultFileError, match="no snapshot at step 7"):
        read_snapshot(out, 7)


def test_resume_is_bit_for_bit_and_refuses_other_runs(tmp_path, packing):
    phases = [Phase("a", LOADING, 500), Phase("b", Loading(x=LOADING.x, y=AxisControl("rate", rate=0.5)), 300)]
    full = tmp_path / "full.h5"
    run_phases(
        packing, SETTINGS, phases, full, OutputSettings(snapshot_every=100, checkpoint_every=300), show_progress=False
    )
    part = tmp_path / "part.h5"
    # the same run interrupted at step 650 (second phase), its checkpoint at 650
    run_phases(
        packing,
        SETTINGS,
        phases,
        part,
        OutputSettings(snapshot_every=100, checkpoint_every=300),
        show_progress=False,
        stop_at_step=650,
    )
    assert not read_run(part).complete and read_run(part).series["step"][-1] == 650
    run_phases(
        packing,
        SETTINGS,
        phases,
        part,
        OutputSettings(snapshot_every=100, checkpoint_every=300),
        resume=True,
        show_progress=False,
    )
    a, b = read_run(full), read_run(part)
    for k in ("step", "stress", "cell", "n_contacts"):
        np.testing.assert_array_equal(a.series[k], b.series[k])
    np.testing.assert_array_equal(read_snapshot(full).positions, read_snapshot(part).positions)
    # another run's file is refused
    other = dataclasses.replace(SETTINGS, mu=0.4)
    with pytest.raises(ResultFileError, match="another run"):
        run_phases(packing, other, phases, part, resume=True, show_progress=False)


def test_nan_keeps_last_good_snapshot(tmp_path, packing):
    v = np.zeros((packing.n, 2))
    eng_v = v.copy()
    eng_v[5] = [1e150, 0.0]  # finite (inputs are checked), so far in one step that the particle is lost
    out = tmp_path / "bad.h5"
    with pytest.raises(SimulationError, match="particle 5"):
        run_phases(
            packing,
            SETTINGS,
            [Phase("load", LOADING, 100)],
            out,
            OutputSettings(snapshot_every=50),
            velocities=eng_v,
            show_progress=False,
        )
    run = read_run(out)
    assert not run.complete and "particle 5" in run.stop_reason
    assert run.snapshot_steps == (0,)


def test_biaxial_protocol_holds_sigma11_and_compresses(tmp_path, packing):
    dem, bi = default_settings(packing, kn=1e5)
    bi = dataclasses.replace(bi, strain=0.002, strain_rate=0.004, consolidation_steps=20000, check_every=500)
    assert inertial_number(packing, bi.strain_rate, bi.confining) < 1e-4  # quasi-static
    out = tmp_path / "bi.h5"
    summary = run_biaxial(
        packing, dem, bi, out, OutputSettings(series_every=5, snapshot_every=0, checkpoint_every=0), show_progress=False
    )
    assert summary["complete"]
    assert summary["axial_strain"] == pytest.approx(0.002, rel=0.02)
    assert summary["sigma11_mean_rel_error"] < 0.05
    assert summary["stress_ratio_peak"] > 1.05  # deviatoric stress builds up
    run = read_run(out)
    comp = run.series["phase"] == 1
    L = run.series["cell"][comp]
    assert L[-1, 1, 1] < L[0, 1, 1]


def test_biaxial_bad_inputs(packing):
    with pytest.raises(InputError, match="strain"):
        BiaxialSettings(confining=10.0, strain=0.9)
    with pytest.raises(InputError, match="confining"):
        BiaxialSettings(confining=-1.0)
    with pytest.raises(InputError, match="series_every"):
        OutputSettings(series_every=0)
    dem, bi = default_settings(packing)
    assert [p.name for p in biaxial_phases(dem, bi)] == ["consolidation", "compression"]


def test_cli_biaxial_and_export(tmp_path, packing, capsys):
    pk = tmp_path / "p.h5"
    save_packing(pk, packing)
    out = tmp_path / "b.h5"
    # 2000 steps do not settle this packing: the run goes on only with --allow-unsettled, and says so
    rc = main(
        [
            "biaxial",
            "--packing",
            str(pk),
            "--strain",
            "0.001",
            "--strain-rate",
            "0.1",
            "-o",
            str(out),
            "--consolidation-steps",
            "2000",
            "--snapshot-every",
            "1000",
            "--plot",
            str(tmp_path / "f.png"),
            "--allow-unsettled",
        ]
    )
    assert rc == 0
    text = capsys.readouterr().out
    assert "inertial_number" in text and (tmp_path / "f.png").exists()
    assert "WARNING: consolidation did not settle" in text
    run = read_run(out)
    assert run.complete and [u["name"] for u in run.unsettled_phases] == ["consolidation"]
    assert main(["dem-export", str(out), "--vtu", str(tmp_path / "x.vtu")]) == 0
    assert main(["biaxial", "--packing", str(tmp_path / "missing.h5"), "-o", str(out)]) == 2
