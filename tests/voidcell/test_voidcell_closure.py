"""The DCEL face-closure check: a face whose half-edge vectors do not add up to zero
winds around the torus; ``faces_from_next`` and ``build_dcel`` must refuse it, naming the face and
its particles. The rotation systems are built here independently of gransim (sort by angle)."""

import numpy as np
import pytest
from voidcell_fixtures import contacts, lattice_packing

from gransim.errors import InputError
from gransim.voidcell import Snapshot, VoidCells
from gransim.voidcell.dcel import build_dcel, faces_from_next


def rotation_next(origin, vec, n, swap_at=None):
    """next[h] = the half-edge leaving dest(h) next clockwise from twin(h) (Kuhn's sharpest
    clockwise corner), from a plain sort by angle; ``swap_at`` = a vertex whose two first
    half-edges exchange places in the cyclic order (a rotation system that is not the drawing's)."""
    H = origin.shape[0]
    angle = np.arctan2(vec[:, 1], vec[:, 0])
    order = np.lexsort((angle, origin))  # by vertex, then counter-clockwise
    ptr = np.searchsorted(origin[order], np.arange(n + 1))
    if swap_at is not None:
        a = ptr[swap_at]
        order[a], order[a + 1] = order[a + 1], order[a]
    pos = np.empty(H, np.int64)
    pos[order] = np.arange(H)
    nxt = np.empty(H, np.int64)
    for h in range(H):
        t = h ^ 1
        v = origin[t]
        r = pos[t]
        nxt[h] = order[r - 1] if r > ptr[v] else order[ptr[v + 1] - 1]
    return nxt


def test_independent_rotation_system_equals_the_dcel_and_closes():
    x, r, cell = lattice_packing(8, 8, seed=3)
    i, j, s = contacts(x, r, cell)
    d = VoidCells().compute(Snapshot(x, cell, i, j, s, np.zeros_like(x), radii=r)).dcel
    nxt = rotation_next(d.origin, d.vec, len(x))
    np.testing.assert_array_equal(nxt, d.next)
    for f in range(d.n_faces):  # every face closes to round-off (|x| ~ 10 m, eps 2e-16)
        hs = d.face_halfedges[d.face_ptr[f] : d.face_ptr[f + 1]]
        assert np.abs(d.vec[hs].sum(axis=0)).max() < 1e-12


def test_one_particle_torus_with_a_wrong_rotation_does_not_close():
    # one disk touching its own images along a1 and a2 (a square torus of side 1): half-edges
    # h0 +x, h1 -x, h2 +y, h3 -y. The drawing's rotation (+x, +y, -x, -y) gives one face of area 1;
    # the rotation (+x, -x, +y, -y) gives next[h0] = h0: a "face" that is one edge around the torus.
    origin = np.zeros(4, np.int64)
    vec = np.array([[1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]])
    cell = np.eye(2)
    _, _, ptr, area, _ = faces_from_next(np.array([2, 3, 1, 0]), origin, vec, cell, 1)
    assert ptr.shape[0] - 1 == 1 and area[0] == pytest.approx(1.0, rel=1e-15)
    with pytest.raises(InputError, match=r"do not close: face 0 \(particles 0\) .* \(1, 0\) m"):
        faces_from_next(np.array([0, 3, 2, 1]), origin, vec, cell, 1)


@pytest.mark.parametrize("vertex", [0, 17, 40])
def test_transposed_rotation_at_one_particle_changes_the_genus(vertex):
    # exchanging two neighbouring half-edges in the cyclic order at one particle keeps a
    # consistent half-edge map whose faces still close, but it lives on a surface of genus 2:
    # two faces fewer, F - E + V = -2 (eq 16 says 0 on the torus)
    x, r, cell = lattice_packing(8, 8, seed=3)
    i, j, s = contacts(x, r, cell)
    d = VoidCells().compute(Snapshot(x, cell, i, j, s, np.zeros_like(x), radii=r)).dcel
    nxt = rotation_next(d.origin, d.vec, len(x), swap_at=vertex)
    np.testing.assert_array_equal(d.origin[nxt], d.dest)  # still a consistent half-edge map
    with pytest.raises(
        InputError,
        match=rf"F - E \+ V = {d.n_faces - 2} - {d.n_edges} \+ "
        rf"{d.n_vertices} = -2 != 0",
    ):
        faces_from_next(nxt, d.origin, d.vec, cell, d.n_vertices)


def test_next_leaving_the_wrong_particle_is_named():
    x, r, cell = lattice_packing(6, 6, seed=1)
    i, j, s = contacts(x, r, cell)
    d = VoidCells().compute(Snapshot(x, cell, i, j, s, np.zeros_like(x), radii=r)).dcel
    nxt = d.next.copy()
    h = 0
    nxt[h], nxt[nxt[h] ^ 1] = nxt[nxt[h] ^ 1], nxt[h]  # exchange with a half-edge of elsewhere
    with pytest.raises(InputError, match="inconsistent rotation system"):
        faces_from_next(nxt, d.origin, d.vec, cell, d.n_vertices)


@pytest.mark.parametrize("which", range(4))
def test_image_shift_off_by_one_period_is_refused_by_closure(which):
    # a contact across the periodic boundary stored with its image shift doubled (one period too
    # far, in the direction the edge already points): the rotation at both ends stays the
    # drawing's, so Euler's formula still holds, but the two faces beside that contact line no
    # longer close: their vectors add up to -/+ C n. Only the closure check sees it (the crossing
    # test is off, it would see the long edge).
    x, r, cell = lattice_packing(8, 8, seed=3)
    i, j, s = contacts(x, r, cell)
    k = int(np.flatnonzero(np.abs(s).sum(axis=1) > 0)[which])
    s = s.copy()
    s[k] *= 2
    with pytest.raises(InputError, match="2 face\\(s\\) do not close") as err:
        build_dcel(x, cell, i, j, s, len(x), check_crossings=False)
    msg = str(err.value)
    parts = [int(p) for p in msg.split("(particles ")[1].split(")")[0].split(", ")]
    assert int(i[k]) in parts and int(j[k]) in parts, msg  # the face beside contact k is named
    gap = np.array([float(g) for g in msg.split("adding up to (")[1].split(")")[0].split(", ")])
    n = s[k] // 2  # the extra image shift of that contact: the gap is +/- C n
    assert min(np.abs(gap - cell @ n).max(), np.abs(gap + cell @ n).max()) < 1e-6 * np.abs(cell).max()
