"""Doubly connected edge list of the particle graph and the void-cell faces (Kuhn 002, sec. 3).

Half-edge h (0 <= h < 2E) of edge e = h >> 1 runs from ``origin[h]`` to ``dest[h]``; its branch
vector ``vec[h]`` is the lifted edge x_dest + C n_h - x_origin with image shift n_h (+n for
h = 2e, -n for h = 2e + 1), so ``twin(h) = h ^ 1`` and ``vec[twin] = -vec``.

Face walk (O(N)): the half-edges leaving each vertex are sorted by angle once. A face lies on the
left of its half-edges and is traversed counter-clockwise: after arriving at v along h, the walk
leaves v along the half-edge next *clockwise* from twin(h) (the sharpest clockwise corner,
Fig. 5), ``next[h] = cw(twin(h))``. Every half-edge is visited exactly once. Because vectors
carry the image shifts, a void cell that straddles the periodic boundary closes: the sum of its
half-edge vectors is zero. Face areas follow from the lifted polygon (shoelace formula).

Validity checks (a non-planar graph, e.g. from strongly overlapping particles, fails one):
no two edges of a vertex in the same direction; no two edges crossing (explicit segment test on
a periodic grid, O(E)); every face closed and of positive area; face areas adding up to the cell
area; Euler's formula for the torus, F - E + V = 0 (eq 16).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._numba import njit
from ..errors import InputError
from ..geometry.cell import cell_area, cell_heights
from .graph import halfedge_shifts

#: relative tolerance of the closure and area checks (round-off of sums of O(N) terms)
AREA_RTOL = 1e-8


@dataclass(frozen=True, eq=False)
class DCEL:
    """Half-edge structure of the framework on the torus (arrays, read-only by convention).

    Attributes
    ----------
    origin, dest : (H,) int64
        Particle index at the tail / head of each half-edge (H = 2E).
    shift : (H, 2) int64
        Image shift n_h of the head.
    vec : (H, 2) float64
        Lifted edge vector x_dest + C n_h - x_origin (m).
    next : (H,) int64
        Next half-edge of the same face (counter-clockwise).
    face : (H,) int64
        Face on the left of each half-edge.
    face_ptr : (F + 1,) int64, face_halfedges : (H,) int64
        Half-edges of face f in walk order: face_halfedges[face_ptr[f]:face_ptr[f+1]].
    face_area : (F,) float64
        Area of each void cell (m^2), > 0.
    face_centroid : (F, 2) float64
        Centroid of each face polygon, lifted from its first vertex (m); not wrapped.
    n_vertices : int
    """

    origin: np.ndarray
    dest: np.ndarray
    shift: np.ndarray
    vec: np.ndarray
    next: np.ndarray
    face: np.ndarray
    face_ptr: np.ndarray
    face_halfedges: np.ndarray
    face_area: np.ndarray
    face_centroid: np.ndarray
    n_vertices: int

    @property
    def twin(self) -> np.ndarray:
        """twin[h] = h ^ 1, (H,)."""
        return np.arange(self.origin.shape[0], dtype=np.int64) ^ 1

    @property
    def n_halfedges(self) -> int:
        return int(self.origin.shape[0])

    @property
    def n_edges(self) -> int:
        return self.n_halfedges // 2

    @property
    def n_faces(self) -> int:
        return int(self.face_ptr.shape[0] - 1)

    @property
    def valence(self) -> np.ndarray:
        """Number of edges m of each face, (F,)."""
        return np.diff(self.face_ptr)

    @property
    def euler_characteristic(self) -> int:
        """F - E + V (0 on the torus, eq 16)."""
        return self.n_faces - self.n_edges + self.n_vertices

    def face_polygon(self, f: int) -> np.ndarray:
        """Lifted vertex coordinates of face f, (m, 2), counter-clockwise, from its first vertex."""
        hs = self.face_halfedges[self.face_ptr[f]:self.face_ptr[f + 1]]
        return np.cumsum(np.vstack([np.zeros(2), self.vec[hs[:-1]]]), axis=0)


@njit
def _rotation_next(n, origin, angle):
    """next[h] = the half-edge leaving dest(h) next clockwise from twin(h) = h ^ 1.

    Half-edges are bucketed by origin and each bucket insertion-sorted by angle (degrees are
    small), O(H). Returns (next, v) with v >= 0 a vertex with two half-edges of equal angle.
    """
    H = origin.shape[0]
    ptr = np.zeros(n + 1, np.int64)
    for h in range(H):
        ptr[origin[h] + 1] += 1
    for v in range(n):
        ptr[v + 1] += ptr[v]
    fill = ptr[:-1].copy()
    order = np.empty(H, np.int64)
    for h in range(H):
        order[fill[origin[h]]] = h
        fill[origin[h]] += 1
    dup = -1
    for v in range(n):
        for a in range(ptr[v] + 1, ptr[v + 1]):
            h = order[a]
            b = a - 1
            while b >= ptr[v] and angle[order[b]] > angle[h]:
                order[b + 1] = order[b]
                b -= 1
            order[b + 1] = h
        for a in range(ptr[v] + 1, ptr[v + 1]):
            if angle[order[a]] == angle[order[a - 1]] and dup < 0:
                dup = v
    pos = np.empty(H, np.int64)
    for a in range(H):
        pos[order[a]] = a
    nxt = np.empty(H, np.int64)
    for h in range(H):
        t = h ^ 1
        v = origin[t]
        r = pos[t]
        nxt[h] = order[r - 1] if r > ptr[v] else order[ptr[v + 1] - 1]
    return nxt, dup


@njit
def _face_geometry(ptr, fh, vec):
    """Per face: shoelace area, closure |sum of vectors| / perimeter, centroid relative to the
    first vertex (lifted polygon)."""
    nf = ptr.shape[0] - 1
    area = np.empty(nf)
    closure = np.empty(nf)
    cen = np.empty((nf, 2))
    for f in range(nf):
        px = 0.0
        py = 0.0
        a2 = 0.0
        cx = 0.0
        cy = 0.0
        per = 0.0
        for k in range(ptr[f], ptr[f + 1]):
            h = fh[k]
            qx = px + vec[h, 0]
            qy = py + vec[h, 1]
            c = px * qy - py * qx
            a2 += c
            cx += (px + qx) * c
            cy += (py + qy) * c
            per += np.sqrt(vec[h, 0] ** 2 + vec[h, 1] ** 2)
            px = qx
            py = qy
        area[f] = 0.5 * a2
        closure[f] = np.sqrt(px * px + py * py) / per if per > 0 else 0.0
        cen[f, 0] = cx / (3.0 * a2) if a2 != 0 else 0.0
        cen[f, 1] = cy / (3.0 * a2) if a2 != 0 else 0.0
    return area, closure, cen


@njit
def _face_cycles(nxt):
    """Cycles of the permutation ``nxt``: face label per half-edge, CSR of half-edges in order."""
    H = nxt.shape[0]
    face = -np.ones(H, np.int64)
    order = np.empty(H, np.int64)
    ptr = np.zeros(H + 1, np.int64)
    nf = 0
    pos = 0
    for h in range(H):
        if face[h] >= 0:
            continue
        g = h
        while face[g] < 0:
            face[g] = nf
            order[pos] = g
            pos += 1
            g = nxt[g]
        if g != h:  # not a permutation: cannot happen for a valid rotation system
            return face, order, ptr[:1], False
        nf += 1
        ptr[nf] = pos
    return face, order, ptr[:nf + 1], True


@njit
def _first_crossing(mid, vec, ends, C, nb1, nb2, k1, k2, count_all):
    """First pair of edges (a, b) whose segments cross properly on the torus, or (-1, -1), and the
    number of crossing pairs found (all of them with ``count_all``, else at most 1).

    ``mid`` are wrapped midpoints (E, 2) with fractional coordinates in [0, 1); two crossing
    segments have midpoints closer than (|l_a| + |l_b|) / 2 <= max |l|, so a bin grid of size
    >= max |l| in each lattice direction and a scan of neighbouring bins finds every crossing.
    Edges are copied in bin order first so that the scan reads contiguous memory.
    """
    ne = mid.shape[0]
    det = C[0, 0] * C[1, 1] - C[0, 1] * C[1, 0]
    nbins = nb1 * nb2
    b = np.empty(ne, np.int64)
    start = np.zeros(nbins + 1, np.int64)
    for a in range(ne):
        s0 = (C[1, 1] * mid[a, 0] - C[0, 1] * mid[a, 1]) / det
        s1 = (-C[1, 0] * mid[a, 0] + C[0, 0] * mid[a, 1]) / det
        b1 = min(max(int(s0 * nb1), 0), nb1 - 1)
        b2 = min(max(int(s1 * nb2), 0), nb2 - 1)
        b[a] = b1 * nb2 + b2
        start[b[a] + 1] += 1
    for q in range(nbins):
        start[q + 1] += start[q]
    fill = start[:-1].copy()
    order = np.empty(ne, np.int64)
    for a in range(ne):
        order[fill[b[a]]] = a
        fill[b[a]] += 1
    # sorted copies: midpoint, half vector, length, end vertices
    sm = np.empty((ne, 2))
    sh = np.empty((ne, 2))
    sl = np.empty(ne)
    se = np.empty((ne, 2), np.int64)
    for p in range(ne):
        a = order[p]
        sm[p, 0] = mid[a, 0]
        sm[p, 1] = mid[a, 1]
        sh[p, 0] = 0.5 * vec[a, 0]
        sh[p, 1] = 0.5 * vec[a, 1]
        sl[p] = np.sqrt(vec[a, 0] ** 2 + vec[a, 1] ** 2)
        se[p, 0] = ends[a, 0]
        se[p, 1] = ends[a, 1]
    found = 0
    first_a = -1
    first_c = -1
    for q0 in range(nbins):
        ba1 = q0 // nb2
        ba2 = q0 % nb2
        for pa in range(start[q0], start[q0 + 1]):
            ha0 = sh[pa, 0]
            ha1 = sh[pa, 1]
            for o1 in range(-k1, k1 + 1):
                u1 = ba1 + o1
                w1 = u1 % nb1
                t1 = (u1 - w1) // nb1
                for o2 in range(-k2, k2 + 1):
                    u2 = ba2 + o2
                    w2 = u2 % nb2
                    t2 = (u2 - w2) // nb2
                    off0 = C[0, 0] * t1 + C[0, 1] * t2
                    off1 = C[1, 0] * t1 + C[1, 1] * t2
                    q = w1 * nb2 + w2
                    for pc in range(max(start[q], pa + 1), start[q + 1]):
                        d0 = sm[pc, 0] + off0 - sm[pa, 0]
                        d1 = sm[pc, 1] + off1 - sm[pa, 1]
                        reach = 0.5 * (sl[pa] + sl[pc])
                        if d0 * d0 + d1 * d1 > reach * reach:
                            continue
                        if (se[pc, 0] == se[pa, 0] or se[pc, 0] == se[pa, 1]
                                or se[pc, 1] == se[pa, 0] or se[pc, 1] == se[pa, 1]):
                            continue
                        hc0 = sh[pc, 0]
                        hc1 = sh[pc, 1]
                        # segment a: -ha .. +ha ; segment c: d - hc .. d + hc (orientation tests)
                        o_c0 = ha0 * (d1 - hc1 + ha1) - ha1 * (d0 - hc0 + ha0)
                        o_c1 = ha0 * (d1 + hc1 + ha1) - ha1 * (d0 + hc0 + ha0)
                        o_a0 = hc0 * (-ha1 - d1 + hc1) - hc1 * (-ha0 - d0 + hc0)
                        o_a1 = hc0 * (ha1 - d1 + hc1) - hc1 * (ha0 - d0 + hc0)
                        if o_c0 * o_c1 < 0.0 and o_a0 * o_a1 < 0.0:
                            if found == 0:
                                first_a = min(order[pa], order[pc])
                                first_c = max(order[pa], order[pc])
                            found += 1
                            if not count_all:
                                return first_a, first_c, found
    return first_a, first_c, found


def find_crossing(positions, cell, edge_i, edge_j, edge_vec, count_all: bool = False):
    """First pair of crossing edges (indices into the edge list) or None. O(E).

    With ``count_all`` returns ``(first_pair_or_None, number_of_crossing_pairs)``. Edges sharing
    a particle are never counted (they meet at that particle).
    """
    ne = edge_i.shape[0]
    if ne < 2:
        return (None, 0) if count_all else None
    cutoff = float(np.sqrt((edge_vec[:, 0] ** 2 + edge_vec[:, 1] ** 2).max()))
    mid = positions[edge_i] + 0.5 * edge_vec
    s = mid @ np.linalg.inv(cell).T
    s -= np.floor(s)
    s[s >= 1.0] = 0.0
    mid = np.ascontiguousarray(s @ cell.T)
    h = cell_heights(cell)
    nb = [max(1, int(np.floor(hk / cutoff))) for hk in h]
    while nb[0] * nb[1] > 4 * ne:
        nb = [max(1, v // 2) for v in nb]
    k = [max(1, int(np.ceil(cutoff * nbk / hk - 1e-12))) for nbk, hk in zip(nb, h)]
    ends = np.ascontiguousarray(np.column_stack([edge_i, edge_j]))
    a, c, found = _first_crossing(mid, np.ascontiguousarray(edge_vec), ends,
                                  np.ascontiguousarray(cell), nb[0], nb[1], k[0], k[1], count_all)
    first = None if a < 0 else (int(a), int(c))
    return (first, int(found)) if count_all else first


def build_dcel(positions, cell, edge_i, edge_j, edge_shift, n_vertices: int,
               check_crossings: bool = True) -> DCEL:
    """Build the half-edge structure and identify the void-cell faces (see module docstring).

    Parameters
    ----------
    positions : (N, 2) float64, particle centres (m)
    cell : (2, 2) float64, columns = lattice vectors (m)
    edge_i, edge_j : (E,) int64, edge_shift : (E, 2) int64
        Edges of the pruned framework (:class:`~gransim.voidcell.graph.ParticleGraph`).
    n_vertices : int
        Number of framework vertices V (for Euler's formula).
    check_crossings : bool
        Run the explicit O(E) segment-crossing test (default). The face checks below run always.

    Raises
    ------
    InputError
        crossing or coincident edges, a face that does not close or has non-positive area, face
        areas not adding up to the cell area, or F - E + V != 0.
    """
    x = np.asarray(positions, np.float64)
    C = np.asarray(cell, np.float64)
    ne = edge_i.shape[0]
    origin = np.empty(2 * ne, np.int64)
    origin[0::2] = edge_i
    origin[1::2] = edge_j
    dest = np.empty_like(origin)
    dest[0::2] = edge_j
    dest[1::2] = edge_i
    hshift = halfedge_shifts(edge_shift)
    vec = x[dest] - x[origin]
    vec += hshift[:, 0:1] * C[:, 0] + hshift[:, 1:2] * C[:, 1]
    evec = vec[0::2]
    if check_crossings:
        hit = find_crossing(x, C, edge_i, edge_j, evec)
        if hit is not None:
            a, c = hit
            raise InputError(
                f"contacts: the particle graph is not planar: contact line {int(edge_i[a])}-"
                f"{int(edge_j[a])} crosses {int(edge_i[c])}-{int(edge_j[c])} (strongly overlapping "
                "particles?)")
    # rotation system: half-edges of each vertex sorted by angle; next = clockwise of the twin
    angle = np.arctan2(vec[:, 1], vec[:, 0])
    nxt, dup = _rotation_next(x.shape[0], origin, angle)
    if dup >= 0:
        raise InputError(f"contacts: two contact lines leave particle {int(dup)} in the same "
                         "direction (coincident edges: non-planar graph)")
    face, fh, ptr, ok = _face_cycles(nxt)
    if not ok:  # pragma: no cover - next is a permutation by construction
        raise InputError("contacts: face walk failed (the rotation system is not a permutation)")
    nf = ptr.shape[0] - 1
    area, closure, centroid_rel = _face_geometry(ptr, fh, vec)
    A = cell_area(C)
    bad = np.flatnonzero(closure > AREA_RTOL)
    bad = np.flatnonzero(area <= 0)
    if bad.size:
        raise InputError(f"contacts: {bad.size} face(s) with non-positive area "
                         f"(face {int(bad[0])}: "
                         f"{area[bad[0]]:.3g} m^2): crossing contact lines, non-planar graph")
    if abs(area.sum() - A) > AREA_RTOL * A:
        raise InputError(f"contacts: face areas add up to {area.sum():.12g} m^2, not the cell area "
                         f"{A:.12g} m^2 (overlapping faces: non-planar graph)")
    euler = nf - ne + int(n_vertices)
    if euler != 0:
        raise InputError(f"contacts: Euler's formula on the torus fails: F - E + V = {nf} - {ne} + "
                         f"{n_vertices} = {euler} != 0")
    centroid = x[origin[fh[ptr[:-1]]]] + centroid_rel
    return DCEL(origin=origin, dest=dest, shift=hshift, vec=vec, next=nxt, face=face, face_ptr=ptr,
                face_halfedges=fh, face_area=area, face_centroid=centroid,
                n_vertices=int(n_vertices))
