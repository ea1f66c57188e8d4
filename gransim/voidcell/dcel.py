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
no two edges of a vertex in the same direction; no two edges crossing (explicit segment test with
the bin-stencil walk of :mod:`gransim.geometry.bins` over the edge midpoints, O(E)); ``next``
leaving the particle each half-edge arrives at; every face closed -- its half-edge vectors add
up to zero within ``AREA_RTOL`` of its perimeter, otherwise it winds around the torus (a wrong
image shift or an inconsistent rotation system) and the error names the face and its particles;
every face of positive area; face areas adding up to the cell area; Euler's formula for the
torus, F - E + V = 0 (eq 16) (a rotation system that is not the drawing's, e.g. two half-edges
exchanged at one particle, embeds the graph in a surface of higher genus and fails it).
:func:`faces_from_next` runs the face checks on any ``next`` array.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._numba import njit, pjit, prange
from ..errors import InputError
from ..geometry.cell import cell_area

# _CrossingVisitor: a numba cache index of an earlier version names it here (unpickled before its
# stamp is checked: a missing name would crash the process that loads the walk)
from ..geometry.segments import _CrossingVisitor, find_crossing  # noqa: F401

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
        hs = self.face_halfedges[self.face_ptr[f] : self.face_ptr[f + 1]]
        return np.cumsum(np.vstack([np.zeros(2), self.vec[hs[:-1]]]), axis=0)


@pjit
def _halfedges(x, C, ei, ej, es):
    """Half-edges of the edges (2e: i -> j with +n, 2e + 1: j -> i with -n): origin, dest (H,),
    shift (H, 2), lifted vector vec = x_dest - x_origin + C n_h (H, 2) and its angle (H,)."""
    ne = ei.shape[0]
    origin = np.empty(2 * ne, np.int64)
    dest = np.empty(2 * ne, np.int64)
    hs = np.empty((2 * ne, 2), np.int64)
    vec = np.empty((2 * ne, 2))
    angle = np.empty(2 * ne)
    for e in prange(ne):
        for s in range(2):
            h = 2 * e + s
            o = ei[e] if s == 0 else ej[e]
            d = ej[e] if s == 0 else ei[e]
            n0 = es[e, 0] if s == 0 else -es[e, 0]
            n1 = es[e, 1] if s == 0 else -es[e, 1]
            origin[h] = o
            dest[h] = d
            hs[h, 0] = n0
            hs[h, 1] = n1
            v0 = (x[d, 0] - x[o, 0]) + (n0 * C[0, 0] + n1 * C[0, 1])
            v1 = (x[d, 1] - x[o, 1]) + (n0 * C[1, 0] + n1 * C[1, 1])
            vec[h, 0] = v0
            vec[h, 1] = v1
            angle[h] = np.arctan2(v1, v0)
    return origin, dest, hs, vec, angle


@njit
def _first_bad_next(nxt, origin):
    """First half-edge h whose next does not leave the particle h arrives at (origin of h ^ 1),
    or whose next is not a half-edge; -1 if none."""
    H = nxt.shape[0]
    for h in range(H):
        g = nxt[h]
        if g < 0 or g >= H or origin[g] != origin[h ^ 1]:
            return h
    return -1


@pjit
def _rotation_next(n, origin, angle):
    """next[h] = the half-edge leaving dest(h) next clockwise from twin(h) = h ^ 1.

    Half-edges are bucketed by origin (counting sort) and each bucket insertion-sorted by angle
    (degrees are small), O(H). Returns (next, v) with v >= 0 a vertex with two half-edges of equal
    angle (the smallest such vertex).
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
    dupv = np.zeros(n, np.bool_)
    for v in prange(n):
        for a in range(ptr[v] + 1, ptr[v + 1]):
            h = order[a]
            b = a - 1
            while b >= ptr[v] and angle[order[b]] > angle[h]:
                order[b + 1] = order[b]
                b -= 1
            order[b + 1] = h
        for a in range(ptr[v] + 1, ptr[v + 1]):
            if angle[order[a]] == angle[order[a - 1]]:
                dupv[v] = True
    dup = -1
    for v in range(n):
        if dupv[v]:
            dup = v
            break
    pos = np.empty(H, np.int64)
    for a in prange(H):
        pos[order[a]] = a
    nxt = np.empty(H, np.int64)
    for h in prange(H):
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
    return face, order, ptr[: nf + 1], True


def build_dcel(positions, cell, edge_i, edge_j, edge_shift, n_vertices: int, check_crossings: bool = True) -> DCEL:
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
    x = np.ascontiguousarray(positions, np.float64)
    C = np.ascontiguousarray(cell, np.float64)
    ei = np.ascontiguousarray(edge_i, np.int64)
    ej = np.ascontiguousarray(edge_j, np.int64)
    origin, dest, hshift, vec, angle = _halfedges(x, C, ei, ej, np.ascontiguousarray(edge_shift, np.int64))
    if check_crossings:
        hit = find_crossing(x, C, ei, ej, vec[0::2])
        if hit is not None:
            a, c = hit
            raise InputError(
                f"contacts: the particle graph is not planar: contact line {int(ei[a])}-"
                f"{int(ej[a])} crosses {int(ei[c])}-{int(ej[c])} (strongly overlapping "
                "particles?)"
            )
    # rotation system: half-edges of each vertex sorted by angle; next = clockwise of the twin
    nxt, dup = _rotation_next(x.shape[0], origin, angle)
    if dup >= 0:
        raise InputError(
            f"contacts: two contact lines leave particle {int(dup)} in the same "
            "direction (coincident edges: non-planar graph)"
        )
    face, fh, ptr, area, centroid_rel = faces_from_next(nxt, origin, vec, C, n_vertices)
    centroid = x[origin[fh[ptr[:-1]]]] + centroid_rel
    return DCEL(
        origin=origin,
        dest=dest,
        shift=hshift,
        vec=vec,
        next=nxt,
        face=face,
        face_ptr=ptr,
        face_halfedges=fh,
        face_area=area,
        face_centroid=centroid,
        n_vertices=int(n_vertices),
    )


def faces_from_next(nxt, origin, vec, cell, n_vertices: int):
    """The faces (cycles of ``next``) of a half-edge structure, checked (module docstring).

    Parameters
    ----------
    nxt : (H,) int64, next half-edge of the same face (twin(h) = h ^ 1)
    origin : (H,) int64, tail particle of each half-edge
    vec : (H, 2) float64, lifted half-edge vectors (m)
    cell : (2, 2) float64 (m); n_vertices : int, V for Euler's formula

    Returns
    -------
    face (H,), face_halfedges (H,), face_ptr (F + 1,), face_area (F,) m^2, centroid (F, 2) m
    relative to each face's first vertex.

    Raises
    ------
    InputError
        ``next`` not a permutation or leaving another particle than the one a half-edge arrives
        at; a face whose half-edge vectors do not add up to zero (it does not close: it winds
        around the torus, from an inconsistent rotation system or a wrong image shift), naming
        the face and its particles; a face of non-positive area; face areas not adding up to the
        cell area; F - E + V != 0 (eq 16).
    """
    nxt = np.ascontiguousarray(nxt, np.int64)
    origin = np.ascontiguousarray(origin, np.int64)
    H = nxt.shape[0]
    bad_next = _first_bad_next(nxt, origin)
    if bad_next >= 0:
        h = bad_next
        g = int(nxt[h])
        leaves = f"leaves particle {int(origin[g])}" if 0 <= g < H else "is not a half-edge"
        raise InputError(
            f"contacts: half-edge {h} arrives at particle {int(origin[h ^ 1])} but "
            f"its next half-edge {g} {leaves} (inconsistent rotation system)"
        )
    face, fh, ptr, ok = _face_cycles(nxt)
    if not ok:
        raise InputError(
            "contacts: the next half-edges are not a permutation (two half-edges "
            "share a successor): inconsistent rotation system"
        )
    nf = ptr.shape[0] - 1
    area, closure, centroid_rel = _face_geometry(ptr, fh, np.ascontiguousarray(vec, np.float64))
    open_faces = np.flatnonzero(~(closure <= AREA_RTOL))
    if open_faces.size:
        f = int(open_faces[0])
        hs = fh[ptr[f] : ptr[f + 1]]
        gap = vec[hs].sum(axis=0)
        parts = origin[hs]
        shown = ", ".join(str(int(k)) for k in parts[:12]) + (", ..." if parts.size > 12 else "")
        raise InputError(
            f"contacts: {open_faces.size} face(s) do not close: face {f} (particles {shown}) has "
            f"half-edge vectors adding up to ({gap[0]:.9g}, {gap[1]:.9g}) m, not zero "
            f"(|sum| / perimeter = {closure[f]:.3g} > {AREA_RTOL:g}): the face winds around the "
            "torus (inconsistent rotation system: a wrong image shift of a contact, or a "
            "non-planar graph)"
        )
    bad = np.flatnonzero(area <= 0)
    if bad.size:
        raise InputError(
            f"contacts: {bad.size} face(s) with non-positive area "
            f"(face {int(bad[0])}: "
            f"{area[bad[0]]:.3g} m^2): crossing contact lines, non-planar graph"
        )
    A = cell_area(np.asarray(cell, np.float64))
    if abs(area.sum() - A) > AREA_RTOL * A:
        raise InputError(
            f"contacts: face areas add up to {area.sum():.12g} m^2, not the cell area "
            f"{A:.12g} m^2 (overlapping faces: non-planar graph)"
        )
    ne = H // 2
    euler = nf - ne + int(n_vertices)
    if euler != 0:
        raise InputError(
            f"contacts: Euler's formula on the torus fails: F - E + V = {nf} - {ne} + {n_vertices} = {euler} != 0"
        )
    return face, fh, ptr, area, centroid_rel
