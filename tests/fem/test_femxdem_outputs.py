"""Outputs of gransim femxdem at chosen steps: maps, RVE pictures, VTU, HDF5 fields, report order.

* the deviatoric strain of exact strain states (biaxialSmooth.py:102-104: sqrt(2 e:e));
* the Gauss-point sub-cells of the maps tile each element, each around its own Gauss point;
* a J2 stand-in run: every file at every field step, the VTU's quad8 mesh and fields read back by
  meshio, femxdem.h5's fields, void ratio and rotation n/a, the report leading with the curves;
* a DEM run: the void ratio from the committed RVE's cell and disks, the rotation the step sums of
  the point's strain path give (tests/fem/test_dem_rve.py checks the sums against YADE), both
  surviving a checkpoint and --resume to the same bits; a checkpoint holding the former estimate
  is refused;
* the options --field-steps and --rve-pictures checked at the boundary.
"""

from __future__ import annotations

import argparse

import h5py
import meshio
import numpy as np
import pytest

from gransim.dem.yade_arithmetic import rve_run_rotation
from gransim.errors import InputError
from gransim.fem.biaxial import BiaxialSpec, biaxial_setup
from gransim.fem.dem_rve import ROTATION_KEY, DemRVE, load_rve_state
from gransim.fem.femxdem import FemxdemInterrupted, run_femxdem
from gransim.fem.output_femxdem import deviatoric_strain, gauss_cells, gauss_positions


def test_deviatoric_strain_of_exact_states():
    a, g = 1e-3, 4e-3
    eps = np.array([[[a, 0], [0, -a]], [[a, 0], [0, a]], [[0, g / 2], [g / 2, 0]], [[0, g], [0, 0]]])
    # pure shear: e = eps, sqrt(2 (a^2 + a^2)) = 2a; isotropic: 0; simple shear (sym part): g
    assert np.allclose(deviatoric_strain(eps), [2 * a, 0.0, g, g], rtol=1e-14, atol=1e-18)


def _area(p):
    x, y = p[:, 0], p[:, 1]
    return 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)


@pytest.mark.parametrize("element,gauss", [("Q8", 2), ("Q9", 3)])
def test_gauss_cells_tile_the_elements_around_their_points(element, gauss):
    setup = biaxial_setup(BiaxialSpec(nx=2, ny=3, element=element, gauss=gauss, steps=1))
    mesh = setup.problem.mesh
    rng = np.random.default_rng(0)
    x = mesh.nodes + 1e-4 * rng.standard_normal(mesh.nodes.shape)  # a distorted configuration
    cells = gauss_cells(mesh, x, gauss)
    gp = gauss_positions(mesh, x, gauss)
    assert cells.shape[0] == gp.shape[0] == mesh.n_elements * gauss**2
    areas = np.array([_area(c) for c in cells])
    assert np.all(areas > 0)  # counter-clockwise
    # the undeformed sub-cells are the element split in equal parts, summing to the specimen
    c0 = gauss_cells(mesh, mesh.nodes, gauss)
    a0 = np.array([_area(c) for c in c0])
    assert np.allclose(a0, 0.05 * 0.1 / len(a0), rtol=1e-12)
    from matplotlib.path import Path as MPath

    assert all(MPath(c).contains_point(p) for c, p in zip(cells, gp))  # each point in its own cell
    # the points are the problem's Gauss points (same order) on the reference mesh
    assert np.allclose(
        gauss_positions(mesh, mesh.nodes, gauss), setup.problem.geometry(mesh.nodes).points.reshape(-1, 2)
    )


def test_j2_run_writes_every_output_and_says_na(tmp_path):
    spec = BiaxialSpec(nx=2, ny=4, steps=3)
    out = tmp_path / "j2"
    s = run_femxdem(spec, rve="j2", out=out, field_steps=(1, 3))
    for k in (1, 3):
        assert (out / f"maps_{k:03d}.png").stat().st_size > 0
        m = meshio.read(out / f"mesh_{k:03d}.vtu")
        assert [c.type for c in m.cells] == ["quad8", "vertex"]
        rec = s["steps"][k - 1]
        nn = len(rec.x)
        assert np.array_equal(m.cells[0].data, biaxial_setup(spec).problem.mesh.elements)
        X = biaxial_setup(spec).problem.mesh.nodes
        assert np.allclose(m.points[:nn, :2], rec.x) and np.allclose(m.point_data["displacement"][:nn, :2], rec.x - X)
        dev = deviatoric_strain(rec.strain)
        assert np.allclose(m.cell_data["deviatoric_strain"][1], dev)
        assert "void_ratio" not in m.point_data and "rotation" not in m.point_data
    assert not (out / "maps_002.png").exists() and not list(out.glob("rve_*.png"))  # j2: no grains
    with h5py.File(out / "femxdem.h5", "r") as f:
        assert sorted(f["fields"]) == ["X", "elements", "step_001", "step_003"]
        assert f["fields"].attrs["not_available"] == "void_ratio, rotation"
        assert np.array_equal(f["fields/step_003/deviatoric_strain"][()], deviatoric_strain(s["steps"][2].strain))
        assert "provenance" in f.attrs or "parameters" in f.attrs
    md = (out / "report.md").read_text()
    assert md.index("curves.png") < md.index("maps_001.png") < md.index("maps_003.png")
    assert "void ratio n/a" in md


@pytest.fixture(scope="module")
def dem_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("fxo") / "dem"
    s = run_femxdem(BiaxialSpec(nx=1, ny=1, steps=2), rve="dem", out=out, field_steps=(1, 2), rve_pictures=(3,))
    with h5py.File(out / "checkpoint" / "states_002.h5", "r") as f:
        states = DemRVE.unpack_states({k: np.array(v) for k, v in f["states"].items()})
    return out, s, states


def test_dem_void_ratio_and_rotation_of_the_committed_rves(dem_run):
    out, s, states = dem_run
    fl = s["fields"][2]
    first, _ = load_rve_state()
    for g, st in enumerate(states):
        H = st.rve.hsize
        vs = np.pi * np.sum(st.rve.radii**2)
        assert fl["void_ratio"][g] == pytest.approx((abs(np.linalg.det(H)) - vs) / vs, rel=1e-13)
        # the rotation: spin dt summed over the steps of the point's calls
        rve, rot = first, np.zeros(st.rve.n)
        for D in st.increments:
            rve, rot = rve_run_rotation(rve, D, rot)
        assert np.array_equal(rot, st.rotation), g
        assert fl["rotation"][g] == np.mean(st.rotation)
    assert np.any(fl["rotation"] != 0)
    snap = fl["pictures"][3]
    assert np.array_equal(snap["rotation"], states[3].rotation) and len(snap["ids"]) == len(states[3].rve.kn)
    assert (out / "rve_002_g00003.png").stat().st_size > 0 and (out / "maps_002.png").exists()
    with h5py.File(out / "femxdem.h5", "r") as f:
        assert np.array_equal(f["fields/step_001/void_ratio"][()], s["fields"][1]["void_ratio"])
        assert np.array_equal(f["fields/step_002/pictures/gp_00003/positions"][()], states[3].rve.positions)


def test_dem_fields_survive_the_checkpoint(dem_run, tmp_path):
    out, s, _ = dem_run
    cut = tmp_path / "cut"
    spec = BiaxialSpec(nx=1, ny=1, steps=2)
    with pytest.raises(FemxdemInterrupted):
        run_femxdem(spec, rve="dem", out=cut, field_steps=(1, 2), rve_pictures=(3,), stop_after=1)
    r = run_femxdem(spec, rve="dem", out=cut, field_steps=(1, 2), rve_pictures=(3,), resume=True)
    for k in (1, 2):
        for n in ("deviatoric_strain", "void_ratio", "rotation"):
            assert np.array_equal(r["fields"][k][n], s["fields"][k][n]), (k, n)
        assert np.array_equal(r["fields"][k]["pictures"][3]["rotation"], s["fields"][k]["pictures"][3]["rotation"])
    with h5py.File(cut / "femxdem.h5", "r") as f, h5py.File(out / "femxdem.h5", "r") as g:
        assert np.array_equal(f["fields/step_001/rotation"][()], g["fields/step_001/rotation"][()])


def test_a_checkpoint_with_the_former_rotation_estimate_is_refused(dem_run):
    out, _, states = dem_run
    with h5py.File(out / "checkpoint" / "states_002.h5", "r") as f:
        arrays = {k: np.array(v) for k, v in f["states"].items()}
    assert np.array_equal(DemRVE.unpack_states(arrays)[1].rotation, states[1].rotation)
    arrays["rotation"] = arrays.pop(ROTATION_KEY)  # as gransim wrote it while the rotation was an estimate
    with pytest.raises(InputError, match="estimate"):
        DemRVE.unpack_states(arrays)


def _args(**kw):
    base = dict(rve="dem", full=False, mesh=None, steps=None, element="Q8", gauss=None, pressure=1e5,
                top_step=1e-4, tol=1e-2, max_iter=25, packing=None, packing_dir=None, out=None, resume=False,
                stop_after=None, workers=None, scheduler=None, field_steps=None, rve_pictures=None, tangent=None,
                tangent_step=None)  # fmt: skip
    base.update(kw)
    return argparse.Namespace(**base)


def test_options_are_checked_at_the_boundary(tmp_path):
    from gransim.cli.cmd_femxdem import check_options

    o = check_options(_args(out=str(tmp_path / "a"), field_steps="10,1,5", rve_pictures="31,0"))
    assert o["field_steps"] == (1, 5, 10) and o["rve_pictures"] == (0, 31)
    assert check_options(_args(out=str(tmp_path / "b")))["field_steps"] == (10,)  # default: the last
    # the Newton limit: 25 a step by default, Guo & Zhao's 100 with --full (msFEM2D.py:204), as given
    assert check_options(_args(out=str(tmp_path / "d"), max_iter=None))["spec"]["max_iter"] == 25
    assert check_options(_args(out=str(tmp_path / "e"), max_iter=None, full=True))["spec"]["max_iter"] == 100
    assert check_options(_args(out=str(tmp_path / "f"), max_iter=7, full=True))["spec"]["max_iter"] == 7
    for kw, opt in [
        ({"field_steps": "0"}, "--field-steps"),
        ({"field_steps": "11"}, "--field-steps"),
        ({"field_steps": "2,2"}, "--field-steps"),
        ({"rve_pictures": "32"}, "--rve-pictures"),  # 2 x 4 Q8: Gauss points 0..31
        ({"rve_pictures": "a"}, "--rve-pictures"),
        ({"rve": "j2", "pressure": 1e5, "rve_pictures": "0"}, "--rve-pictures"),
    ]:
        with pytest.raises(InputError, match=opt):
            check_options(_args(out=str(tmp_path / "c"), **kw))
