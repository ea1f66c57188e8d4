"""Faces of the particle graph: DCEL invariants, Euler's formula (eq 16), areas, periodic images."""

import numpy as np
import pytest
from voidcell_fixtures import contacts, lattice_packing, square_lattice

from gransim.voidcell import Snapshot, VoidCells
from gransim.voidcell.dcel import find_crossing


def analyse(x, r, cell, **kw):
    i, j, s = contacts(x, r, cell)
    return VoidCells(**kw).compute(Snapshot(x, cell, i, j, s, np.zeros_like(x), radii=r))


@pytest.fixture(scope="module", params=["lattice", "relaxed", "sheared"])
def computed(request, lattice, relaxed):
    if request.param == "lattice":
        return analyse(*lattice)
    if request.param == "relaxed":
        return analyse(*relaxed)
    return analyse(*lattice_packing(10, 12, seed=5, shear=0.35))


def test_dcel_invariants(computed):
    d = computed.dcel
    H = d.n_halfedges
    h = np.arange(H)
    np.testing.assert_array_equal(d.twin[d.twin], h)
    np.testing.assert_array_equal(d.origin[d.twin], d.dest)
    np.testing.assert_allclose(d.vec[d.twin], -d.vec, atol=0)
    np.testing.assert_array_equal(d.shift[d.twin], -d.shift)
    np.testing.assert_array_equal(d.origin[d.next], d.dest)  # next leaves where h arrives
    np.testing.assert_array_equal(d.face[d.next], d.face)  # next cycles stay in their face
    np.testing.assert_array_equal(np.sort(d.face_halfedges), h)  # each half-edge in one face
    for f in range(d.n_faces):  # cycles close in walk order
        hs = d.face_halfedges[d.face_ptr[f] : d.face_ptr[f + 1]]
        np.testing.assert_array_equal(d.next[hs], np.roll(hs, -1))
        assert np.all(d.face[hs] == f)


def test_euler_and_areas(computed):
    d = computed.dcel
    assert d.n_faces - d.n_edges + d.n_vertices == 0  # eq (16)
    C = computed.snapshot.cell
    np.testing.assert_allclose(d.face_area.sum(), np.linalg.det(C), rtol=1e-12)
    assert np.all(d.face_area > 0)
    assert d.valence.min() >= 3 or d.n_faces < 3


def test_face_polygons_are_counter_clockwise_and_close(computed):
    d = computed.dcel
    for f in range(0, d.n_faces, 7):
        p = d.face_polygon(f)
        q = np.roll(p, -1, axis=0)
        area = 0.5 * np.sum(p[:, 0] * q[:, 1] - p[:, 1] * q[:, 0])
        assert area == pytest.approx(d.face_area[f], rel=1e-12)
        hs = d.face_halfedges[d.face_ptr[f] : d.face_ptr[f + 1]]
        np.testing.assert_allclose(d.vec[hs].sum(axis=0), 0, atol=1e-12)


def test_square_lattice_counts_and_boundary_faces():
    for n in (1, 2, 5):
        pos, edges = square_lattice(n)
        i, j, s = (np.array([e[k] for e in edges]) for k in range(3))
        vc = VoidCells().compute(Snapshot(pos, np.diag([n, n]) * 1.0, i, j, s.reshape(-1, 2), np.zeros_like(pos)))
        assert (vc.n_faces, vc.n_edges, vc.n_vertices) == (n * n, 2 * n * n, n * n)
        np.testing.assert_allclose(vc.face_area, 1.0, rtol=1e-13)
        assert np.all(vc.valence == 4)


def test_results_do_not_depend_on_which_image_is_stored(relaxed):
    x, r, cell = relaxed
    i, j, s = contacts(x, r, cell)
    rng = np.random.default_rng(7)
    m = rng.integers(-3, 4, size=(len(x), 2))  # move particle k to x_k + C m_k
    x2 = x + m @ cell.T
    s2 = s + m[i] - m[j]  # l = x_j + C n - x_i unchanged
    G = np.array([[0.1, 0.4], [-0.3, -0.2]])
    v = rng.normal(size=x.shape)
    a = VoidCells().compute(Snapshot(x, cell, i, j, s, v, cell_velocity=G @ cell))
    v2 = v + m @ (G @ cell).T  # the image x + C m moves with v + (dC/dt) m
    b = VoidCells().compute(Snapshot(x2, cell, i, j, s2, v2, cell_velocity=G @ cell))
    assert (a.n_faces, a.n_edges) == (b.n_faces, b.n_edges)
    ka = np.argsort(a.face_area + 1e-6 * a.L[:, 0, 0])  # match faces by area (distinct here)
    kb = np.argsort(b.face_area + 1e-6 * b.L[:, 0, 0])
    np.testing.assert_allclose(a.face_area[ka], b.face_area[kb], rtol=1e-10)
    np.testing.assert_allclose(a.L[ka], b.L[kb], rtol=1e-8, atol=1e-10)


def test_crossing_detected_across_the_boundary():
    cell = np.diag([10.0, 10.0])
    pos = np.array([[9.5, 5.0], [0.5, 5.0], [0.0, 4.5], [0.0, 5.5], [5.0, 5.0]])
    # 0 -> image of 1 (shift +x) crosses 2 -> 3 at x = 0 (10 in the image)
    ei, ej = np.array([0, 2, 4]), np.array([1, 3, 0])
    vec = np.array([[1.0, 0.0], [0.0, 1.0], [4.5, 0.0]])
    assert find_crossing(pos, cell, ei, ej, vec) == (0, 1)
    vec[1] = [0.0, 0.4]  # shortened: 2 -> (0, 4.9) no longer reaches the line y = 5
    assert find_crossing(pos, cell, ei, ej, vec) is None


def brute_force_crossings(pos, cell, ei, ej, vec):
    """O(E^2 K^2) count of properly crossing segment pairs over image shifts -2..2 (numpy)."""
    a0 = pos[ei]
    a1 = a0 + vec
    count = 0
    for s1 in range(-2, 3):
        for s2 in range(-2, 3):
            off = cell @ np.array([s1, s2], float)
            b0 = a0 + off
            b1 = a1 + off

            def orient(p, q, r):
                return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (
                    r[..., 0] - p[..., 0]
                )

            P, Q = a0[:, None], a1[:, None]
            R, S = b0[None, :], b1[None, :]
            hit = (orient(P, Q, R) * orient(P, Q, S) < 0) & (orient(R, S, P) * orient(R, S, Q) < 0)
            share = (
                (ei[:, None] == ei[None, :])
                | (ei[:, None] == ej[None, :])
                | (ej[:, None] == ei[None, :])
                | (ej[:, None] == ej[None, :])
            )
            hit &= ~share
            count += int(np.triu(hit, 1).sum() + np.tril(hit, -1).sum())
    return count // 2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_crossing_count_matches_brute_force(seed):
    rng = np.random.default_rng(seed)
    cell = np.array([[6.0, 1.5], [0.0, 5.0]])  # sheared
    n = 60
    pos = rng.random((n, 2)) @ cell.T
    ei = rng.integers(0, n, 80)
    ej = (ei + 1 + rng.integers(0, n - 1, 80)) % n
    vec = rng.normal(scale=0.6, size=(80, 2))  # segments need not end at pos[ej]: geometry only
    first, count = find_crossing(pos, cell, ei, ej, vec, count_all=True)
    expect = brute_force_crossings(pos, cell, ei, ej, vec)
    assert expect > 0 and count == expect
    assert (first is None) == (count == 0)
