"""Kuhn's void cells in a sheared (triclinic) periodic cell, from ``gransim shear`` run files.

The faces are checked against two constructions that share nothing with the DCEL's periodic
bookkeeping: the unsheared image of the affine-mapped packing (a linear map with det > 0 keeps
the angular order of the edges at every particle, so the faces are the same half-edge cycles, the
areas scale by det M and each cell's gradient is M L M^-1), and a brute-force walk of the faces of
the plane graph of explicit periodic copies. Invariants: areas summing to the cell area, Euler's
formula on the torus, twin(twin(h)) == h, and the area-weighted mean gradient equal to the
sheared cell's own (dC/dt) C^-1 (eq 3 on a tessellation of the torus), which fails if the cell,
its rate or the motion of the images x_j + C n are wrong.
"""

import csv
import math

import h5py
import numpy as np
import pytest
from voidcell_fixtures import contacts, lattice_packing

from gransim.cli import main
from gransim.contacts import find_neighbours_bruteforce
from gransim.errors import InputError
from gransim.io import save_packing
from gransim.voidcell import Snapshot, VoidCells
from gransim.voidcell.io import describe_run, load_run_snapshots
from gransim.voidcell.measures import RELATIVE_MOTION_RTOL, relative_motion_undefined
from reference_runs.decks.shear import short_case

STRAIN, RATE = 0.004, 5.0  # 67 steps of the 120-disk short case: a tilt of 0.4% of Ly


def _shear(tmp, name, *extra):
    p, _, _, _ = short_case("constant-volume")  # 120 dense disks, Lx = 0.02 m, Ly = 0.0208 m
    pk = tmp / "p.h5"
    if not pk.exists():
        save_packing(pk, p)
    out = tmp / name
    args = ["shear", "--packing", str(pk), "--strain", str(STRAIN), "--rate", str(RATE), "--snapshot-every", "20"]
    assert main([*args, *extra, "-o", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("shear")
    return {"cv": _shear(tmp, "cv.h5"), "servo": _shear(tmp, "servo.h5", "--servo", "1000")}


def _analysable(path):
    """The snapshots of a run whose contact graph spans the cell (the packing's own does not)."""
    out = []
    for rs in load_run_snapshots(path, None):
        try:
            out.append((rs, VoidCells().compute(rs.snapshot)))
        except InputError:
            pass
    assert len(out) >= 3
    return out


def test_shear_run_is_read_in_its_sheared_cell(runs):
    info = describe_run(runs["cv"])
    assert info.kind == "shear-run" and info.measure == "shear" and info.velocities == "absolute"
    with h5py.File(runs["cv"], "r") as f:
        series = {k: f["series"][k][()] for k in ("step", "box", "shear_strain")}
        r = f["packing/radii"][()]
        stored = {int(g.attrs["step"]): g["velocities"][()] for g in f["snapshots"].values()}
    picked = load_run_snapshots(runs["cv"], None)
    assert [rs.step for rs in picked] == sorted(stored) == [0, 20, 40, 60, 67]
    for rs in picked:
        k = int(np.searchsorted(series["step"], rs.step))
        lx, ly, xy = series["box"][k, :3]
        s = rs.snapshot
        np.testing.assert_array_equal(s.cell, [[lx, xy], [0.0, ly]])
        assert rs.measure == "shear" and rs.strain == pytest.approx(series["shear_strain"][k], rel=1e-12, abs=1e-15)
        # lab-frame velocities (remap v): read as stored, nothing added
        np.testing.assert_array_equal(s.velocities, stored[rs.step])
        # contacts: the overlapping pairs, against the O(N^2) search over all images
        nl = find_neighbours_bruteforce(s.positions, r, s.cell)
        got = {_key(a, b, t) for a, b, t in zip(s.contacts_i, s.contacts_j, s.contacts_shift)}
        assert got == {_key(a, b, t) for a, b, t in zip(nl.i, nl.j, nl.shift)} and len(got) == s.n_contacts
    assert picked[-1].snapshot.cell[0, 1] > 0  # the last frame is sheared


def _key(a, b, t):
    a, b, t0, t1 = int(a), int(b), int(t[0]), int(t[1])
    return (a, b, t0, t1) if (a, t0, t1) <= (b, -t0, -t1) else (b, a, -t0, -t1)


def test_mean_gradient_is_the_sheared_cells(runs):
    # eq (3) on a tessellation of the torus: sum_i A^i L^i = the boundary integral over the cell =
    # A (dC/dt) C^-1, whatever the particles do (0.5% of the snapshots' steps)
    for _, vc in _analysable(runs["cv"]):
        G = vc.snapshot.imposed_gradient
        assert G[0, 1] == pytest.approx(RATE, rel=1e-6)  # xy erate R: d(xy)/dt = R Ly, L_12 = R
        np.testing.assert_allclose(vc.L_cells, G, rtol=0, atol=1e-12 * RATE)


def _check_invariants(vc):
    d = vc.dcel
    h = np.arange(d.n_halfedges)
    np.testing.assert_array_equal(d.twin[d.twin], h)
    np.testing.assert_array_equal(d.origin[d.next], d.dest)
    assert d.n_faces - d.n_edges + d.n_vertices == 0  # Euler on the torus, eq (16)
    assert d.face_area.sum() == pytest.approx(np.linalg.det(vc.snapshot.cell), rel=1e-12)
    assert np.all(d.face_area > 0)


def _cases(runs):
    x, r, cell = lattice_packing(10, 12, seed=5, shear=0.35)  # a strongly sheared cell
    rng = np.random.default_rng(3)
    i, j, s = contacts(x, r, cell)
    lat = Snapshot(x, cell, i, j, s, rng.normal(size=x.shape), cell_velocity=rng.normal(size=(2, 2)), radii=r)
    return [("lattice", lat)] + [(f"run-{rs.step}", rs.snapshot) for rs, _ in _analysable(runs["cv"])[-2:]]


def test_faces_against_the_unsheared_affine_image(runs):
    for name, s in _cases(runs):
        vc = VoidCells().compute(s)
        _check_invariants(vc)
        C = s.cell
        C0 = np.diag([np.linalg.norm(C[:, 0]), np.linalg.det(C) / np.linalg.norm(C[:, 0]) * 1.3])
        M = C0 @ np.linalg.inv(C)  # maps the sheared cell onto an orthogonal one (and stretches y)
        img = Snapshot(
            s.positions @ M.T,
            M @ C,
            s.contacts_i,
            s.contacts_j,
            s.contacts_shift,
            s.velocities @ M.T,
            cell_velocity=M @ s.cell_velocity,
            radii=s.radii,
        )
        assert abs(img.cell[0, 1]) < 1e-12 * img.cell[0, 0]
        vo = VoidCells().compute(img)
        # the same graph, the same half-edges: the same faces, walked the same way
        np.testing.assert_array_equal(vo.graph.edge_contact, vc.graph.edge_contact, err_msg=name)
        np.testing.assert_array_equal(vo.dcel.next, vc.dcel.next, err_msg=name)
        np.testing.assert_array_equal(vo.dcel.face, vc.dcel.face, err_msg=name)
        detM = np.linalg.det(M)
        np.testing.assert_allclose(vo.dcel.face_area, detM * vc.dcel.face_area, rtol=1e-10, err_msg=name)
        # each cell's velocity gradient (eq 7) transforms as M L M^-1
        want = np.einsum("pq,fqr,rs->fps", M, vc.L, np.linalg.inv(M))
        scale = np.abs(want).max()
        np.testing.assert_allclose(vo.L, want, rtol=0, atol=1e-9 * scale, err_msg=name)


def _plane_faces(x, C, ei, ej, es):
    """Faces of the plane graph of the periodic copies x_k + C a (a in -2..2), walked in plain
    Python: at each copy the neighbours sorted by angle, the next edge of a face the one clockwise
    from the edge it arrived by. Returns, for each bounded face whose vertices are all copies with
    a in -1..1 and whose centroid lies in the primary cell: (sorted particle ids, area, centroid)."""
    adj = {}
    for i, j, n in zip(ei, ej, es):
        for a0 in range(-2, 3):
            for a1 in range(-2, 3):
                u, w = (int(i), a0, a1), (int(j), a0 + int(n[0]), a1 + int(n[1]))
                adj.setdefault(u, []).append(w)
                adj.setdefault(w, []).append(u)

    def pos(v):
        return x[v[0]] + C @ np.array(v[1:], float)

    order = {}
    for v, ws in adj.items():
        p = pos(v)
        ang = [math.atan2(*(pos(w) - p)[::-1]) for w in ws]
        order[v] = [w for _, w in sorted(zip(ang, ws))]
    seen, faces = set(), []
    Ci = np.linalg.inv(C)
    for u in order:
        for w in order[u]:
            if (u, w) in seen:
                continue
            cyc = []
            a, b = u, w
            while (a, b) not in seen:
                seen.add((a, b))
                cyc.append(a)
                ring = order[b]
                k = ring.index(a)
                a, b = b, ring[k - 1]  # clockwise of the twin
            if not all(max(abs(v[1]), abs(v[2])) <= 1 for v in cyc):
                continue
            P = np.array([pos(v) for v in cyc])
            Q = np.roll(P, -1, axis=0)
            cr = P[:, 0] * Q[:, 1] - P[:, 1] * Q[:, 0]
            area = 0.5 * cr.sum()
            if area <= 0:
                continue
            cen = ((P + Q) * cr[:, None]).sum(axis=0) / (6 * area)
            if np.all((Ci @ cen >= 0) & (Ci @ cen < 1)):
                faces.append((tuple(sorted(v[0] for v in cyc)), area, cen))
    return faces


def test_faces_against_a_brute_force_plane_walk(runs):
    for name, s in _cases(runs):
        vc = VoidCells().compute(s)
        g, d, C = vc.graph, vc.dcel, s.cell
        brute = _plane_faces(s.positions, C, g.edge_i, g.edge_j, g.edge_shift)
        assert len(brute) == d.n_faces, name
        # DCEL faces keyed by their centroid moved into the primary cell
        k = np.floor(np.linalg.solve(C, d.face_centroid.T).T)
        cen = d.face_centroid - k @ C.T
        scale = np.sqrt(np.linalg.det(C))
        for parts, area, c in brute:
            f = int(np.argmin(np.linalg.norm(cen - c, axis=1)))
            assert np.linalg.norm(cen[f] - c) < 1e-9 * scale, name
            hs = d.face_halfedges[d.face_ptr[f] : d.face_ptr[f + 1]]
            assert tuple(sorted(int(p) for p in d.origin[hs])) == parts, name
            assert d.face_area[f] == pytest.approx(area, rel=1e-10), name


def test_relative_motion_criterion():
    L = np.array([[0.0, 5.0], [0.0, 0.0]])
    assert relative_motion_undefined(L) == "undefined (mean L_22 = 0 against |L| = 5)"
    for rel, defined in ((0.5, True), (1.01 * RELATIVE_MOTION_RTOL, True), (0.99 * RELATIVE_MOTION_RTOL, False)):
        Lx = L.copy()
        Lx[1, 1] = -rel * 5.0 / math.sqrt(1 - rel**2)  # |Lx_22| = rel |Lx|
        assert (relative_motion_undefined(Lx) is None) == defined, rel
    assert relative_motion_undefined(np.zeros((2, 2))) == "undefined (mean L_22 = 0 against |L| = 0)"


def test_constant_volume_relative_motion_is_undefined(runs, tmp_path):
    # simple shear at constant volume: L_22 is round-off, eq (21) would divide by it
    rs, vc = _analysable(runs["cv"])[-1]
    l22, norm = vc.L_mean[1, 1], np.linalg.norm(vc.L_mean)
    assert abs(l22) < 1e-12 * norm  # round-off, not a rate
    assert vc.v_rel_undefined == f"undefined (mean L_22 = {l22:.3g} against |L| = {norm:.3g})"
    with pytest.raises(InputError, match="undefined"):
        _ = vc.v_rel
    out = tmp_path / "vc"
    assert main(["voidcells", str(runs["cv"]), "--out", str(out), "--no-vtk"]) == 0
    rows = list(csv.DictReader(open(out / "voidcells.csv")))
    last = rows[-1]
    assert int(last["step"]) == 67 and float(last["strain"]) == pytest.approx(STRAIN, rel=0.01)
    assert last["rms_v_rel"].startswith("undefined (mean L_22 = ") and last["rms_v_rel"].endswith(
        f"against |L| = {RATE:.3g})"
    )
    assert 0 < float(last["mean_alpha"]) < 1 and int(last["euler"]) == 0
    assert "\\|L\\|" in (out / "voidcells.md").read_text()  # a table cell, not a column break
    with h5py.File(out / "voidcells.h5", "r") as f:
        assert f.attrs["kind"] == "voidcells"
        g = f["snapshots"][sorted(f["snapshots"])[-1]]
        assert g.attrs["step"] == 67 and g.attrs["measure"] == "shear"
        assert np.all(np.isnan(g["v_rel"][()])) and g["v_rel"].attrs["undefined"] == last["rms_v_rel"]
        assert np.isnan(g.attrs["rms_v_rel"]) and g.attrs["rms_v_rel_undefined"] == last["rms_v_rel"]
        np.testing.assert_allclose(g["L_mean"][()][0, 1], RATE, rtol=1e-6)
        assert g["face_area"][()].sum() == pytest.approx(np.linalg.det(g["cell"][()]), rel=1e-12)


def test_servo_relative_motion_is_defined(runs, tmp_path):
    # under the normal-stress servo the cell height moves: L_22 is a rate and eq (21) a number
    rs, vc = _analysable(runs["servo"])[-1]
    assert abs(vc.L_mean[1, 1]) > 1e-6 * np.linalg.norm(vc.L_mean)
    assert vc.v_rel_undefined is None and np.all(np.isfinite(vc.v_rel))
    out = tmp_path / "vc"
    assert main(["voidcells", str(runs["servo"]), "--out", str(out), "--no-vtk"]) == 0
    last = list(csv.DictReader(open(out / "voidcells.csv")))[-1]
    assert float(last["rms_v_rel"]) == pytest.approx(vc.v_rel_rms, rel=1e-12)
    with h5py.File(out / "voidcells.h5", "r") as f:
        g = f["snapshots"][sorted(f["snapshots"])[-1]]
        assert "undefined" not in g["v_rel"].attrs and np.all(np.isfinite(g["v_rel"][()]))
