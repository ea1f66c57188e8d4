"""Pruning of the particle graph (Fig. 4) on hand-made graphs on the torus."""

import numpy as np
import pytest
from voidcell_fixtures import square_lattice

from gransim.errors import InputError
from gransim.voidcell import Snapshot, VoidCells, build_graph, find_bridges
from gransim.voidcell.graph import ISLAND, ISOLATED, KEPT, PENDANT, PENINSULAR, components


def add(pos, edges, new_pos, new_edges):
    """Append particles (positions) and edges given with indices relative to len(pos) as 'n+k'."""
    base = len(pos)
    pos = np.vstack([pos, np.atleast_2d(new_pos)])
    out = list(edges)
    for a, b in new_edges:
        a = base + int(a[1:]) if isinstance(a, str) else a
        b = base + int(b[1:]) if isinstance(b, str) else b
        out.append((a, b, (0, 0)))
    return pos, out


def graph_of(pos, edges):
    i = np.array([e[0] for e in edges])
    j = np.array([e[1] for e in edges])
    s = np.array([e[2] for e in edges]).reshape(-1, 2)
    return build_graph(len(pos), i, j, s), (i, j, s)


def test_lattice_keeps_everything_and_counts():
    pos, edges = square_lattice(4)
    g, _ = graph_of(pos, edges)
    assert g.n_vertices == 16 and g.n_edges == 32
    assert not g.bridge.any()
    assert np.all(g.removed == KEPT)


def test_bridges_on_path_cycle_and_parallel_edges():
    # path 0-1-2-3: every edge a bridge; a 3-cycle: none; two parallel edges: none
    assert find_bridges(4, [0, 1, 2], [1, 2, 3]).all()
    assert not find_bridges(3, [0, 1, 2], [1, 2, 0]).any()
    assert not find_bridges(2, [0, 0], [1, 1]).any()
    # two triangles joined by one edge: only that edge is a bridge
    b = find_bridges(6, [0, 1, 2, 3, 4, 5, 2], [1, 2, 0, 4, 5, 3, 3])
    np.testing.assert_array_equal(b, [False] * 6 + [True])


def test_wrapping_rank():
    pos, edges = square_lattice(3)
    _, (i, j, s) = graph_of(pos, edges)
    _, _, rank = components(len(pos), i, j, s)
    assert rank.tolist() == [2]
    # keep only the horizontal rings: three components that wrap once (rank 1)
    horiz = s[:, 1] == 0
    horiz &= np.array([e[1] == (e[0] + 3) % 9 for e in edges])
    _, _, rank = components(len(pos), i[horiz], j[horiz], s[horiz])
    assert sorted(rank.tolist()) == [1, 1, 1]


def test_pendant_chain_isolated_and_island():
    pos, edges = square_lattice(4)
    # pendant chain of two particles hanging on particle 0; an isolated particle;
    # an island triangle inside the face between particles 5, 6, 9, 10
    pos, edges = add(pos, edges, [[0.5, 0.9], [0.5, 1.2]], [(0, "n0"), ("n0", "n1")])
    pos, edges = add(pos, edges, [[2.9, 2.9]], [])
    pos, edges = add(pos, edges, [[1.8, 1.8], [2.2, 1.8], [2.0, 2.2]], [("n0", "n1"), ("n1", "n2"), ("n2", "n0")])
    g, _ = graph_of(pos, edges)
    assert g.removed[16] == PENDANT and g.removed[17] == PENDANT
    assert g.removed[18] == ISOLATED
    assert np.all(g.removed[19:22] == ISLAND)
    assert np.all(g.removed[:16] == KEPT) and g.n_edges == 32
    assert g.removal_counts() == {"kept": 16, "isolated": 1, "pendant": 2, "island": 3, "peninsular": 0}


def test_peninsula_on_a_bridge():
    pos, edges = square_lattice(4)
    # a triangle hanging on particle 5 through one contact (and a chain particle in between)
    pos, edges = add(
        pos,
        edges,
        [[1.7, 1.6], [1.85, 1.55], [2.0, 1.6], [1.9, 1.8]],
        [(5, "n0"), ("n0", "n1"), ("n1", "n2"), ("n2", "n3"), ("n3", "n1")],
    )
    g, _ = graph_of(pos, edges)
    assert np.all(g.removed[16:20] == PENINSULAR)
    assert g.n_vertices == 16 and g.n_edges == 32
    assert g.bridge.sum() == 2


def test_group_on_a_cut_vertex_is_kept():
    # a triangle sharing particle 5: no bridge, kept; faces stay closed and Euler holds
    pos, edges = square_lattice(4)
    pos, edges = add(pos, edges, [[1.8, 1.6], [1.6, 1.8]], [(5, "n0"), ("n0", "n1"), ("n1", 5)])
    g, (i, j, s) = graph_of(pos, edges)
    assert g.n_vertices == 18 and g.n_edges == 35
    vc = VoidCells().compute(Snapshot(pos, np.diag([4.0, 4.0]), i, j, s, np.zeros_like(pos)))
    assert vc.n_faces == 17 and vc.dcel.euler_characteristic == 0
    np.testing.assert_allclose(vc.face_area.sum(), 16.0, rtol=1e-13)


def test_no_wrapping_component_is_an_error():
    pos, edges = square_lattice(3)
    i = np.array([0, 1, 2])
    j = np.array([1, 2, 0])
    with pytest.raises(InputError, match="spans the periodic cell|spans"):
        build_graph(9, i, j, np.zeros((3, 2), int))


def test_empty_and_duplicate_contacts():
    with pytest.raises(InputError, match="empty"):
        build_graph(5, np.zeros(0, int), np.zeros(0, int), np.zeros((0, 2), int))
    pos, edges = square_lattice(3)
    edges.append((edges[0][1], edges[0][0], tuple(-np.array(edges[0][2]))))  # same edge reversed
    with pytest.raises(InputError, match="more than once"):
        graph_of(pos, edges)
