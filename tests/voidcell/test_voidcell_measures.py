"""Per-cell gradients (eq 7), the assembly average (eq 3) and eqs 18-21 on periodic snapshots."""

import numpy as np
import pytest
from voidcell_fixtures import contacts, lattice_packing

from gransim.voidcell import Snapshot, VoidCells, alignment, normalised_vorticity
from gransim.voidcell.measures import d50_area_weighted

G = np.array([[0.3, 0.12], [-0.25, -0.5]])


def snapshot(x, r, cell, v, Cdot, **kw):
    i, j, s = contacts(x, r, cell)
    return Snapshot(x, cell, i, j, s, v, cell_velocity=Cdot, radii=r, **kw)


@pytest.mark.parametrize("case", ["lattice", "relaxed", "sheared"])
def test_affine_periodic_field_every_cell_exact(case, lattice, relaxed):
    x, r, cell = {"lattice": lattice, "relaxed": relaxed, "sheared": lattice_packing(10, 12, seed=5, shear=0.35)}[case]
    v = x @ G.T + np.array([0.7, -0.2])  # affine field, images move with G C n
    vc = VoidCells().compute(snapshot(x, r, cell, v, G @ cell))
    scale = np.abs(G).max()
    np.testing.assert_allclose(vc.L, np.broadcast_to(G, vc.L.shape), rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(vc.L_cells, G, rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(vc.alpha, 1.0, atol=1e-12)
    np.testing.assert_allclose(vc.v_rel, 0.0, atol=1e-10)
    assert vc.mean_alpha == pytest.approx(1.0) and vc.fraction_nonpositive_alpha == 0.0


def test_assembly_average_equals_imposed_gradient_for_any_particle_motion(relaxed):
    # eq (3): sum_i A^i L^i / A is a boundary term; fluctuations of periodic particles cancel,
    # so it equals (dC/dt) C^{-1} even for random velocities
    x, r, cell = relaxed
    rng = np.random.default_rng(11)
    v = x @ G.T + rng.normal(scale=0.3, size=x.shape)
    vc = VoidCells().compute(snapshot(x, r, cell, v, G @ cell))
    np.testing.assert_allclose(vc.L_cells, G, rtol=0, atol=1e-12)
    assert np.std(vc.alpha) > 0.1  # the cells do differ
    vc2 = VoidCells(reference="cell").compute(vc.snapshot)
    np.testing.assert_allclose(vc2.L_mean, G, atol=1e-14)
    np.testing.assert_allclose(vc2.alpha, vc.alpha, atol=1e-9)


def test_displacements_between_two_affine_states(relaxed):
    x, r, cell = relaxed
    F = np.array([[1.002, 0.001], [0.0005, 0.997]])
    snap0 = snapshot(x, r, cell, np.zeros_like(x), None)
    x1 = x @ F.T
    C1 = F @ cell
    s = np.linalg.solve(C1, x1.T).T
    x1w = (s - np.floor(s)) @ C1.T  # the later state wrapped into its cell
    vc = VoidCells().compute(snap0.with_displacements_to(x1w, C1))
    assert vc.snapshot.motion == "displacement"
    np.testing.assert_allclose(vc.L, np.broadcast_to(F - np.eye(2), vc.L.shape), atol=1e-12)


def test_rigid_rotation_vorticity_sign(lattice):
    x, r, cell = lattice
    om = 0.2
    W = np.array([[0.0, -om], [om, 0.0]])  # counter-clockwise spin
    Lbar = 0.5 * (G + G.T) + W  # symmetric stretching plus the spin
    vc = VoidCells().compute(snapshot(x, r, cell, x @ Lbar.T, Lbar @ cell))
    assert np.all(vc.w > 0)
    np.testing.assert_allclose(vc.w, 2 * om / np.linalg.norm(Lbar), rtol=1e-10)


def test_alignment_and_vorticity_formulas():
    L0 = np.array([[1.0, 2.0], [0.5, -1.0]])
    Ls = np.stack([L0, -L0, 3 * L0, np.array([[0.0, 0.5], [-2.0, 0.0]]), np.zeros((2, 2))])
    a = alignment(Ls, L0)
    np.testing.assert_allclose(a[:3], [1, -1, 1])
    assert a[3] == pytest.approx(np.sum(Ls[3] * L0) / np.linalg.norm(Ls[3]) / np.linalg.norm(L0))
    assert np.isnan(a[4])
    w = normalised_vorticity(Ls, L0)
    assert w[3] == pytest.approx(-(0.5 + 2.0) / np.linalg.norm(L0))


def test_relative_motion_scaling(lattice):
    x, r, cell = lattice
    rng = np.random.default_rng(2)
    dv = rng.normal(size=x.shape)
    dv -= dv.mean(axis=0)
    vc = VoidCells().compute(snapshot(x, r, cell, x @ G.T + dv, G @ cell))
    d50 = d50_area_weighted(r)
    # eq (21) with the exact Lbar (= G here): the fluctuation over D50 |L22|
    np.testing.assert_allclose(vc.v_rel, dv / (d50 * abs(G[1, 1])), atol=1e-10)


def test_cell_gradients_equal_boundary_integral_on_a_packing(relaxed):
    # compiled eq (7) per face against (1/A) sum_edges mean edge velocity (x) outward normal,
    # with the lifted image velocities, for random particle velocities
    x, r, cell = relaxed
    rng = np.random.default_rng(5)
    v = rng.normal(size=x.shape)
    Cdot = rng.normal(size=(2, 2)) * 0.1
    vc = VoidCells().compute(snapshot(x, r, cell, v, Cdot))
    d = vc.dcel
    assert d.valence.max() >= 9  # large valences are exercised too
    for f in range(d.n_faces):
        hs = d.face_halfedges[d.face_ptr[f] : d.face_ptr[f + 1]]
        # velocity of each lifted vertex: the first vertex's, plus the relative velocities so far
        vh = v[d.dest[hs]] + d.shift[hs] @ Cdot.T - v[d.origin[hs]]
        vert_v = v[d.origin[hs[0]]] + np.cumsum(np.vstack([np.zeros(2), vh[:-1]]), axis=0)
        e = d.vec[hs]
        b = np.column_stack([e[:, 1], -e[:, 0]])
        Lb = (0.5 * (vert_v + np.roll(vert_v, -1, axis=0))).T @ b / d.face_area[f]
        np.testing.assert_allclose(vc.L[f], Lb, rtol=0, atol=1e-11 * np.abs(Lb).max())
