"""Reading DEM run files (docs/schema_dem.md layout) and the ``gransim voidcells`` command."""

import csv

import numpy as np
import pytest
from voidcell_fixtures import relaxed_packing

from gransim.cli import main
from gransim.contacts import find_neighbours
from gransim.errors import InputError, ResultFileError
from gransim.io import atomic_h5
from gransim.voidcell import VoidCells
from gransim.voidcell.io import load_run_snapshots

DT = 1e-3
RATE = 1e-4  # axial strain per step


def eps_of(step):
    return RATE * max(step - 5, 0)


def write_affine_run(path, snapshot_steps=(2, 5, 6, 7, 21, 22), complete=True, stop_reason=""):
    """A fake biaxial run in the DEM schema: the packing compressed affinely, Ly = Ly0 exp(-eps)."""
    x0, r, C0 = relaxed_packing()
    steps = np.arange(0, 25)
    F = lambda s: np.diag([1.0, np.exp(-eps_of(s))])  # noqa: E731
    with atomic_h5(path, kind="dem-run", parameters={"test": True}, seed=0) as f:
        f.attrs["complete"] = complete
        f.attrs["stop_reason"] = stop_reason
        g = f.create_group("packing")
        g["positions"], g["radii"], g["cell"] = x0, r, C0
        se = f.create_group("series")
        se["step"] = steps
        se["time"] = steps * DT
        se["cell"] = np.array([F(s) @ C0 for s in steps])
        se["phase"] = (steps >= 5).astype(np.int8)
        sn = f.create_group("snapshots")
        for s in snapshot_steps:
            C = F(s) @ C0
            x = x0 @ F(s).T
            frac = np.linalg.solve(C, x.T).T
            xw = (frac - np.floor(frac)) @ C.T  # the engine keeps particles in the cell
            rate = np.diag([0.0, -RATE / DT]) if s >= 5 else np.zeros((2, 2))
            nl = find_neighbours(xw, r, C, skin=0.0)
            h = sn.create_group(f"s{s:010d}")
            h.attrs["step"] = s
            # velocities as the engine stores them: relative to the affine remap (here zero)
            h["cell"], h["positions"], h["velocities"] = C, xw, np.zeros_like(xw)
            h.attrs["absolute_velocities"] = xw @ rate.T
            h["contacts/i"], h["contacts/j"], h["contacts/shift"] = nl.i, nl.j, nl.shift
    return path


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    return write_affine_run(tmp_path_factory.mktemp("run") / "run.h5")


def test_load_run_snapshots_picks_strains(run_file):
    got = load_run_snapshots(run_file, [1e-4, 1.6e-3])
    assert [g.step for g in got] == [6, 21]
    np.testing.assert_allclose([g.strain for g in got], [1e-4, 1.6e-3], rtol=1e-9)
    for g in got:
        vc = VoidCells().compute(g.snapshot)
        # central difference of exp(-eps): O(RATE^2) relative error on the cell rate
        np.testing.assert_allclose(vc.L_cells, np.diag([0, -RATE / DT]), atol=1e-6 * RATE / DT)
        assert vc.mean_alpha == pytest.approx(1.0, abs=1e-6)


def test_absolute_velocity_convention(run_file, tmp_path):
    # the same motion stored as absolute velocities reads the same
    import shutil

    import h5py

    p = tmp_path / "abs.h5"
    shutil.copy(run_file, p)
    with h5py.File(p, "r+") as f:
        for g in f["snapshots"].values():
            g["velocities"][...] = g.attrs["absolute_velocities"]
    a = load_run_snapshots(run_file, [1.6e-3])[0].snapshot
    b = load_run_snapshots(p, [1.6e-3], velocities="absolute")[0].snapshot
    np.testing.assert_allclose(a.velocities, b.velocities, rtol=1e-6, atol=1e-12)


def test_displacement_mode(run_file):
    (g,) = load_run_snapshots(run_file, [1e-4], motion="displacement")
    vc = VoidCells().compute(g.snapshot)
    expect = np.diag([0.0, np.exp(-RATE) - 1.0])  # F(7) F(6)^-1 - I
    np.testing.assert_allclose(vc.L, np.broadcast_to(expect, vc.L.shape), atol=1e-13)


def test_bad_run_files(run_file, tmp_path):
    with pytest.raises(InputError, match="nearest snapshot"):
        load_run_snapshots(run_file, [0.05])
    with pytest.raises(ResultFileError, match="no such file"):
        load_run_snapshots(tmp_path / "missing.h5", [1e-4])
    with atomic_h5(tmp_path / "pack.h5", kind="packing") as f:
        f["x"] = 1
    with pytest.raises(ResultFileError, match="expected 'dem-run'"):
        load_run_snapshots(tmp_path / "pack.h5", [1e-4])


def test_cli_writes_figures_and_table(run_file, tmp_path, capsys):
    out = tmp_path / "vc"
    rc = main(["voidcells", str(run_file), "--strain", "0.0001", "0.0016", "--out", str(out), "--all-frames"])
    assert rc == 0
    for tag in ("strain_0.0001", "strain_0.0016"):
        for kind in ("graph", "alpha", "w", "hist", "vrel"):
            assert (out / f"{tag}_{kind}.png").stat().st_size > 1000
        assert (out / f"{tag}.vtu").exists()
    rows = list(csv.DictReader(open(out / "voidcells.csv")))
    assert [int(r["step"]) for r in rows] == [5, 6, 21]  # initial graph, then the strains
    for row in rows[1:]:
        assert int(row["euler"]) == 0
        assert float(row["mean_alpha"]) == pytest.approx(1.0, abs=1e-6)
        assert float(row["fraction_alpha_le_0"]) == 0.0
        assert float(row["coordination_2M_over_N"]) == pytest.approx(2 * int(row["edges"]) / int(row["vertices"]))
    assert "Kuhn (1997)" in capsys.readouterr().out
    frames = list(csv.DictReader(open(out / "frames.csv")))
    assert [int(f["step"]) for f in frames] == [2, 5, 6, 7, 21, 22]
    assert all(int(f["euler"]) == 0 for f in frames)


def test_cli_error_is_one_line(tmp_path, capsys):
    rc = main(["voidcells", str(tmp_path / "nope.h5")])
    assert rc == 2
    assert "no such file" in capsys.readouterr().err
