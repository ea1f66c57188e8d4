"""Segments on the torus: the proper-crossing test of straight segments (contact lines) in a
periodic cell, O(E), with the shared bin-stencil walk of :mod:`gransim.geometry.bins`.

Used by the void-cell graph (:mod:`gransim.voidcell.dcel`) to prove the particle graph planar. The
visitor class lives here, in the geometry layer, because numba's disk cache of
:func:`~gransim.geometry.bins.walk_pairs` lists the classes of all its compiled visitors and every
process that loads the walk imports their modules: they must stay at the bottom of the imports.
"""

from __future__ import annotations

from collections import namedtuple

import numpy as np

from .._numba import njit, pjit, prange
from .bins import bin_layout, bin_points, register_pair_visitor, walk_pairs, wrap_fractional

#: visitor of :func:`gransim.geometry.bins.walk_pairs` over edge midpoints (bin order): half
#: vectors ``sh`` (E, 2), end particles ``se`` (E, 2) and, per edge, the bin-order position of its
#: first crossing partner (written at slot 0)
_CrossingVisitor = namedtuple("_CrossingVisitor", ["sh", "se", "partner"])


@njit(inline="always")
def _crossing_pair(v, pa, pc, a, c, t1, t2, d0, d1, slot):
    """True when segments a (-ha .. +ha about its midpoint) and c (d - hc .. d + hc) cross
    properly; edges sharing a particle never count (they meet at that particle)."""
    # most candidates are edges of a common particle (they meet there): rejected first
    se = v.se
    if se[pc, 0] == se[pa, 0] or se[pc, 0] == se[pa, 1] or se[pc, 1] == se[pa, 0] or se[pc, 1] == se[pa, 1]:
        return False
    ha0 = v.sh[pa, 0]
    ha1 = v.sh[pa, 1]
    hc0 = v.sh[pc, 0]
    hc1 = v.sh[pc, 1]
    # bounding boxes (about the midpoints, half widths |h|) must overlap: a cheap, tighter filter
    if abs(d0) > abs(ha0) + abs(hc0) or abs(d1) > abs(ha1) + abs(hc1):
        return False
    o_c0 = ha0 * (d1 - hc1 + ha1) - ha1 * (d0 - hc0 + ha0)
    o_c1 = ha0 * (d1 + hc1 + ha1) - ha1 * (d0 + hc0 + ha0)
    o_a0 = hc0 * (-ha1 - d1 + hc1) - hc1 * (-ha0 - d0 + hc0)
    o_a1 = hc0 * (ha1 - d1 + hc1) - hc1 * (ha0 - d0 + hc0)
    if o_c0 * o_c1 < 0.0 and o_a0 * o_a1 < 0.0:
        if slot == 0:
            v.partner[pa] = pc
        return True
    return False


register_pair_visitor(_CrossingVisitor, _crossing_pair)


@pjit
def _midpoints(x, ei, vec):
    """Midpoints x_i + l / 2 (E, 2) and half lengths |l| / 2 (E,) of the edges."""
    ne = ei.shape[0]
    mid = np.empty((ne, 2))
    half = np.empty(ne)
    for e in prange(ne):
        mid[e, 0] = x[ei[e], 0] + 0.5 * vec[e, 0]
        mid[e, 1] = x[ei[e], 1] + 0.5 * vec[e, 1]
        half[e] = 0.5 * np.sqrt(vec[e, 0] ** 2 + vec[e, 1] ** 2)
    return mid, half


@pjit
def _gather_edges(order, vec, ei, ej):
    """Half vectors (E, 2) and end particles (E, 2) in bin order."""
    ne = order.shape[0]
    sh = np.empty((ne, 2))
    se = np.empty((ne, 2), np.int64)
    for p in prange(ne):
        e = order[p]
        sh[p, 0] = 0.5 * vec[e, 0]
        sh[p, 1] = 0.5 * vec[e, 1]
        se[p, 0] = ei[e]
        se[p, 1] = ej[e]
    return sh, se


def find_crossing(positions, cell, edge_i, edge_j, edge_vec, count_all: bool = False):
    """First pair of crossing edges (indices into the edge list) or None. O(E).

    Two crossing segments have midpoints closer than (|l_a| + |l_c|) / 2, so the bin-stencil walk
    of :mod:`gransim.geometry.bins` over the wrapped midpoints with reach |l| / 2 finds every
    crossing (each pair and image once); the proper-crossing test runs on those candidates.
    With ``count_all`` returns ``(first_pair_or_None, number_of_crossing_pairs)``; the pair
    returned (smaller edge index first) is the first crossing found from the edge of smallest
    index that finds one (deterministic). Edges sharing a particle are never counted (they meet
    at that particle).
    """
    ne = edge_i.shape[0]
    if ne < 2:
        return (None, 0) if count_all else None
    cell = np.ascontiguousarray(cell, np.float64)
    vec = np.ascontiguousarray(edge_vec, np.float64)
    ei = np.ascontiguousarray(edge_i, np.int64)
    ej = np.ascontiguousarray(edge_j, np.int64)
    mid, half = _midpoints(np.ascontiguousarray(positions, np.float64), ei, vec)
    mid, s, _ = wrap_fractional(mid, cell)
    nb1, nb2, k1, k2 = bin_layout(cell, 2.0 * float(half.max()), ne)
    start, order, xs, rs = bin_points(mid, s, half, nb1, nb2)
    v = _CrossingVisitor(*_gather_edges(order, vec, ei, ej), np.full(ne, -1, np.int64))
    counts = walk_pairs(v, xs, rs, order, cell, 0.0, start, nb1, nb2, k1, k2, np.zeros(ne, np.int64), True)
    found = int(counts.sum())
    first = None
    if found:
        ps = np.flatnonzero(counts)
        p = int(ps[np.argmin(order[ps])])
        a, c = int(order[p]), int(order[v.partner[p]])
        first = (min(a, c), max(a, c))
    return (first, found) if count_all else first
