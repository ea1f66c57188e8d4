"""Taylor states run through LIGGGHTS now (needs the binary) against the numpy Taylor stress."""

import numpy as np
import pytest

from gransim.geometry import Packing
from reference_runs.runner import is_complete
from reference_runs.taylor import run_taylor
from reference_runs.taylor_numpy import candidate_pairs, taylor_stress_numpy

pytestmark = pytest.mark.liggghts
KN = 2.8e7
RTOL = 1e-10  # same float64 forces summed in different orders; measured ~1e-15


def test_taylor_paths_both_routes(lattice_packing, tmp_path):
    p = lattice_packing
    run = run_taylor(p, KN, tmp_path / "job", name="lattice", stride=10, progress=False)
    cand = candidate_pairs(p, 0.85)
    for (path, route), s in run.series.items():
        for F, sig in zip(s.F, s.cauchy):
            ref = taylor_stress_numpy(p, F, KN, cand).cauchy
            assert np.abs(sig - ref).max() < RTOL * np.abs(ref).max(), (path, route, F.tolist())
    for path in ("compression-11", "compression-22"):
        a, b = run.get(path, "periodic"), run.get(path, "images")
        assert np.abs(a.cauchy - b.cauchy).max() < RTOL * np.abs(a.cauchy).max()
    assert {k[0] for k in run.series} == {"compression-11", "compression-22", "shear-12", "shear-21"}
    # a complete job is not run again
    assert is_complete(tmp_path / "job")
    again = run_taylor(p, KN, tmp_path / "job", name="lattice", stride=10, progress=False)
    assert again.manifest["end"] == run.manifest["end"]


@pytest.mark.parametrize("route", ["periodic", "images"])
def test_two_disks_analytic_sign(tmp_path, route):
    # one contact of overlap delta along x in a 4 mm periodic box: sigma_xx = -kn delta d / A
    L, r, d = 4e-3, 0.55e-3, 1.0e-3
    p = Packing(np.array([[0.3e-3, 2e-3], [0.3e-3 + d, 2e-3]]), np.array([r, r]), np.diag([L, L]))
    run = run_taylor(
        p, KN, tmp_path / route, paths=("compression-11",), routes=(route,), n_steps=1, max_strain=0.0, progress=False
    )
    sig = run.get("compression-11", route).cauchy[0]
    expect = -KN * (2 * r - d) * d / L**2
    assert np.isclose(sig[0, 0], expect, rtol=1e-12) and sig[1, 1] == 0 and sig[0, 1] == 0


def test_contacts_dumped(lattice_packing, tmp_path):
    run = run_taylor(
        lattice_packing,
        KN,
        tmp_path / "c",
        paths=("shear-12",),
        routes=("images",),
        n_steps=2,
        stride=2,
        contacts=True,
        progress=False,
    )
    fr = run.contacts("shear-12", "images", 2)
    assert len(fr) > lattice_packing.n and np.all(fr["delta"] > 0)


def test_images_route_with_tilted_reference_cell(lattice_packing, tmp_path):
    # the image construction does not need an orthogonal cell: shear the reference packing first
    S = np.array([[1.0, 0.25], [0.0, 1.0]])
    p = lattice_packing.deformed(S)
    run = run_taylor(
        p, KN, tmp_path / "tilt", paths=("shear-21", "compression-22"), routes=("images",), stride=25, progress=False
    )
    cand = candidate_pairs(p, 0.85)
    for s in run.series.values():
        for F, sig in zip(s.F, s.cauchy):
            ref = taylor_stress_numpy(p, F, KN, cand).cauchy
            assert np.abs(sig - ref).max() < RTOL * np.abs(ref).max()
