"""``gransim info`` and ``gransim dem-export`` read a simple-shear run (kind "shear-run",
docs/shear.md) as they read a biaxial run: its sheared cell, series, snapshots and contacts."""

from __future__ import annotations

import h5py
import meshio
import numpy as np
import pytest

from gransim.cli import main
from gransim.contacts import find_neighbours_bruteforce
from gransim.dem.output import read_run, read_snapshot
from gransim.io import save_packing
from reference_runs.decks.shear import short_case


@pytest.fixture(scope="module")
def shear_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("shear")
    p, _, _, _ = short_case("constant-volume")  # 120 dense disks
    save_packing(tmp / "p.h5", p)
    out = tmp / "run.h5"
    argv = ["shear", "--packing", str(tmp / "p.h5"), "--strain", "0.004", "--rate", "5", "--snapshot-every", "20"]
    assert main([*argv, "-o", str(out)]) == 0
    with h5py.File(out, "r") as f:
        raw = {k: f["series"][k][()] for k in f["series"]}
        snaps = {int(g.attrs["step"]): {k: g[k][()] for k in g} for g in f["snapshots"].values()}
        attrs = dict(f.attrs)
        radii = f["packing/radii"][()]
    return out, raw, snaps, attrs, radii


def test_read_run_of_a_shear_run(shear_run):
    path, raw, snaps, attrs, _ = shear_run
    run = read_run(path)
    assert run.kind == "shear-run" and run.complete and run.snapshot_steps == (0, 20, 40, 60, 67)
    box = raw["box"]
    np.testing.assert_array_equal(run.series["cell"][:, 0, 0], box[:, 0])
    np.testing.assert_array_equal(run.series["cell"][:, 0, 1], box[:, 2])  # the tilt xy
    np.testing.assert_array_equal(run.series["cell"][:, 1, 1], box[:, 1])
    assert np.all(run.series["cell"][:, 1, 0] == 0) and run.series["cell"][-1, 0, 1] > 0
    np.testing.assert_array_equal(run.series["stress"], raw["stress"])  # tension positive, as stored
    assert run.series["shear_strain"][-1] == attrs["shear_strain_reached"]


def test_read_snapshot_of_a_shear_run(shear_run):
    path, _, snaps, attrs, radii = shear_run
    dt = read_run(path).settings["dem"]["dt"]
    for step in (None, 40):
        s = read_snapshot(path, step)
        want = 67 if step is None else step
        assert s.step == want and s.time == pytest.approx(want * dt, rel=1e-15)
        np.testing.assert_array_equal(s.cell, snaps[want]["cell"])
        np.testing.assert_array_equal(s.positions, snaps[want]["positions"])
        # the contacts of a snapshot without a list: the overlapping pairs, O(N^2) over all images
        nl = find_neighbours_bruteforce(s.positions, radii, s.cell)
        assert np.array_equal(np.sort(s.contacts["i"] * 1000 + s.contacts["j"]), np.sort(nl.i * 1000 + nl.j))


def test_info_and_dem_export_on_a_shear_run(shear_run, tmp_path, capsys):
    path, raw, snaps, attrs, radii = shear_run
    assert main(["info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "kind                   shear-run" in out and "complete               True" in out
    assert f"series                 {len(raw['step'])} rows, steps 0..67; 5 snapshots" in out
    assert f"shear strain reached   {attrs['shear_strain_reached']:.6g}" in out
    assert f"a2 = ({raw['box'][-1, 2]:.6g}, {raw['box'][-1, 1]:.6g})" in out  # the sheared last cell
    vtu, png = tmp_path / "s.vtu", tmp_path / "s.png"
    assert main(["dem-export", str(path), "--vtu", str(vtu), "--step", "60", "--plot", str(png)]) == 0
    assert png.stat().st_size > 1000
    m = meshio.read(vtu)
    s = snaps[60]
    assert m.points.shape == (len(radii), 3)
    # wrapped into the sheared cell: fractional coordinates in [0, 1)
    frac = np.linalg.solve(s["cell"], m.points[:, :2].T).T
    assert np.all((frac >= -1e-12) & (frac < 1 + 1e-12))
    nl = find_neighbours_bruteforce(s["positions"], radii, s["cell"])
    z = np.bincount(nl.i, minlength=len(radii)) + np.bincount(nl.j, minlength=len(radii))
    np.testing.assert_array_equal(m.point_data["contacts"], z)
    np.testing.assert_allclose(m.point_data["velocity"][:, :2], s["velocities"], rtol=0, atol=0)
    assert main(["dem-export", str(path), "--vtu", str(tmp_path / "x.vtu"), "--step", "61"]) == 2
    assert "no snapshot at that step" in capsys.readouterr().err
