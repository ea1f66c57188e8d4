"""VTK polygons and wrapped plot polygons reproduce the faces (areas, periodic copies)."""

import meshio
import numpy as np
from voidcell_fixtures import contacts, lattice_packing

from gransim.voidcell import Snapshot, VoidCells
from gransim.voidcell.plots import wrapped_face_polygons
from gransim.voidcell.vtk import cells_to_vtu


def shoelace(p):
    q = np.roll(p, -1, axis=0)
    return 0.5 * np.sum(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0])


def computed():
    x, r, cell = lattice_packing(8, 10, seed=9, shear=0.2)
    i, j, s = contacts(x, r, cell)
    G = np.array([[0.1, 0.2], [0.0, -0.3]])
    return VoidCells().compute(Snapshot(x, cell, i, j, s, x @ G.T, cell_velocity=G @ cell, radii=r))


def test_vtu_polygons(tmp_path):
    vc = computed()
    cells_to_vtu(tmp_path / "c.vtu", vc)
    m = meshio.read(tmp_path / "c.vtu")
    areas, face_ids = [], []
    for block, fid in zip(m.cells, m.cell_data["face"]):
        for conn, f in zip(block.data, fid):
            areas.append(shoelace(m.points[conn, :2]))
            face_ids.append(int(f))
    face_ids = np.array(face_ids)
    assert sorted(face_ids) == list(range(vc.n_faces))
    np.testing.assert_allclose(np.array(areas), vc.face_area[face_ids], rtol=1e-12)
    # centroids wrapped into the primary cell
    C = vc.snapshot.cell
    cen = np.array([m.points[c, :2].mean(axis=0) for b in m.cells for c in b.data])
    s = np.linalg.solve(C, cen.T).T
    assert np.all((s > -0.5) & (s < 1.5))


def test_wrapped_plot_polygons_cover_the_cell():
    vc = computed()
    polys, owner = wrapped_face_polygons(vc)
    assert set(owner.tolist()) == set(range(vc.n_faces))
    np.testing.assert_allclose([shoelace(p) for p in polys], vc.face_area[owner], rtol=1e-12)
    # periodic copies exist for cells across the boundary: more polygons than faces
    assert len(polys) > vc.n_faces
