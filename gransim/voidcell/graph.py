"""The particle graph on the torus and its pruning to the load-bearing framework (Kuhn 002, sec. 3).

Vertices are particle centres, edges are contacts. An edge e = (i, j, n) joins particle i to the
image x_j + C n of particle j (branch vector l_ij = x_j + C n - x_i). Two half-edges belong to
every edge: 2e runs i -> j with image shift +n, 2e + 1 runs j -> i with shift -n.

Pruning (Fig. 4), defined precisely
-----------------------------------
1. Every *bridge* is removed: an edge whose removal disconnects its connected component
   (Tarjan's low-link test; parallel edges with different image shifts are distinct edges).
   A bridge has the same void on both sides and carries no closed void cell.
2. The remaining graph falls into connected components. Lift each component to the plane
   along a spanning tree (vertex k gets an integer image offset u_k); every other edge closes a
   cycle whose net image shift is z = u_i + n - u_j. The component *wraps the torus* when these
   shifts span two independent directions (rank 2). On a torus a planar graph has at most one
   such component, and every other component lies inside one of its faces.
3. The framework kept is that unique rank-2 component; all other vertices and edges are removed.
   If no component wraps the torus there is no void-cell tessellation (:class:`InputError`).

The removed particles are classified, in this order of precedence:

* **isolated** -- no contact at all;
* **island** -- in a connected component of the full contact graph that does not contain the
  framework (a cluster floating in a void);
* **pendant** -- removed by repeated deletion of particles with exactly one contact (a dangling
  particle or a dangling chain), and not in an island;
* **peninsular** -- any other removed particle: a group containing a closed loop of contacts
  that is joined to the framework only through a bridge (e.g. a ring hanging on one contact),
  together with the particles of the bridge chain.

Repeated deletion of degree <= 1 vertices is contained in this rule (a pendant edge is a bridge).
Groups joined to the framework at a single particle (a cut vertex) with at least two contacts
each side are *kept*: each face there is still a closed (weakly simple) polygon, so eq (7), the
face areas and Euler's formula (eq 16) hold unchanged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._numba import njit
from ..errors import InputError

#: codes of ``ParticleGraph.removed`` (0 = kept)
KEPT, ISOLATED, PENDANT, ISLAND, PENINSULAR = 0, 1, 2, 3, 4
REMOVAL_NAMES = {KEPT: "kept", ISOLATED: "isolated", PENDANT: "pendant", ISLAND: "island", PENINSULAR: "peninsular"}


@dataclass(frozen=True, eq=False)
class ParticleGraph:
    """The pruned particle graph (the load-bearing framework) and what was removed.

    Attributes
    ----------
    n_particles : int
        N, particles in the snapshot.
    edge_i, edge_j : (E,) int64
        Kept edges (particle indices).
    edge_shift : (E, 2) int64
        Image shift n of each kept edge (l = x_j + C n - x_i).
    edge_contact : (E,) int64
        Index of each kept edge in the input contact list.
    removed : (N,) int8
        KEPT (0), ISOLATED (1), PENDANT (2), ISLAND (3) or PENINSULAR (4).
    bridge : (M,) bool
        Input contacts that are bridges of the full contact graph.
    """

    n_particles: int
    edge_i: np.ndarray
    edge_j: np.ndarray
    edge_shift: np.ndarray
    edge_contact: np.ndarray
    removed: np.ndarray
    bridge: np.ndarray

    @property
    def vertices(self) -> np.ndarray:
        """Indices of the particles kept as graph vertices, (V,)."""
        return np.flatnonzero(self.removed == KEPT)

    @property
    def n_vertices(self) -> int:
        """N-bar, vertices of the framework."""
        return int(np.count_nonzero(self.removed == KEPT))

    @property
    def n_edges(self) -> int:
        """M-bar, edges of the framework."""
        return int(self.edge_i.shape[0])

    def removal_counts(self) -> dict:
        """Number of particles per removal class, e.g. {"kept": 871, "pendant": 40, ...}."""
        return {name: int(np.count_nonzero(self.removed == code)) for code, name in REMOVAL_NAMES.items()}


@njit
def _csr(n, ei, ej):
    """Half-edges grouped by origin (counting sort, O(N + E)): ptr (n+1,), adj (2E,) half-edge ids
    in increasing order within each vertex, dest (2E,) head of every half-edge."""
    ne = ei.shape[0]
    dest = np.empty(2 * ne, np.int64)
    ptr = np.zeros(n + 1, np.int64)
    for e in range(ne):
        dest[2 * e] = ej[e]
        dest[2 * e + 1] = ei[e]
        ptr[ei[e] + 1] += 1
        ptr[ej[e] + 1] += 1
    for v in range(n):
        ptr[v + 1] += ptr[v]
    fill = ptr[:-1].copy()
    adj = np.empty(2 * ne, np.int64)
    for h in range(2 * ne):
        o = dest[h ^ 1]
        adj[fill[o]] = h
        fill[o] += 1
    return ptr, adj, dest


@njit
def _bridges(n, ptr, adj, dest):
    """Tarjan's bridge test, iterative DFS. Returns (E,) bool."""
    ne = adj.shape[0] // 2
    is_bridge = np.zeros(ne, np.bool_)
    disc = -np.ones(n, np.int64)
    low = np.zeros(n, np.int64)
    pedge = -np.ones(n, np.int64)
    it = ptr[:-1].copy()
    stack = np.empty(n, np.int64)
    t = 0
    for root in range(n):
        if disc[root] >= 0:
            continue
        top = 0
        stack[0] = root
        disc[root] = t
        low[root] = t
        t += 1
        while top >= 0:
            v = stack[top]
            if it[v] < ptr[v + 1]:
                h = adj[it[v]]
                it[v] += 1
                e = h >> 1
                if e == pedge[v]:
                    continue
                w = dest[h]
                if disc[w] < 0:
                    pedge[w] = e
                    disc[w] = t
                    low[w] = t
                    t += 1
                    top += 1
                    stack[top] = w
                elif disc[w] < low[v]:
                    low[v] = disc[w]
            else:
                top -= 1
                if top >= 0:
                    u = stack[top]
                    if low[v] < low[u]:
                        low[u] = low[v]
                    if low[v] > disc[u]:
                        is_bridge[pedge[v]] = True
    return is_bridge


@njit
def _lift_components(n, ptr, adj, dest, hshift, active):
    """Connected components over active edges, image offsets u (n, 2) along a BFS tree, and the
    rank (0, 1, 2) of the net image shifts of each component's cycles."""
    comp = -np.ones(n, np.int64)
    off = np.zeros((n, 2), np.int64)
    rank = np.zeros(n, np.int64)
    queue = np.empty(n, np.int64)
    nc = 0
    for root in range(n):
        if comp[root] >= 0:
            continue
        comp[root] = nc
        head = 0
        tail = 1
        queue[0] = root
        r = 0
        z0 = 0
        z1 = 0
        while head < tail:
            v = queue[head]
            head += 1
            for a in range(ptr[v], ptr[v + 1]):
                h = adj[a]
                if not active[h >> 1]:
                    continue
                w = dest[h]
                s0 = off[v, 0] + hshift[h, 0]
                s1 = off[v, 1] + hshift[h, 1]
                if comp[w] < 0:
                    comp[w] = nc
                    off[w, 0] = s0
                    off[w, 1] = s1
                    queue[tail] = w
                    tail += 1
                else:
                    y0 = s0 - off[w, 0]
                    y1 = s1 - off[w, 1]
                    if y0 != 0 or y1 != 0:
                        if r == 0:
                            r = 1
                            z0 = y0
                            z1 = y1
                        elif r == 1 and z0 * y1 - z1 * y0 != 0:
                            r = 2
        rank[nc] = r
        nc += 1
    return comp, off, rank[:nc]


@njit
def _join_by_bridges(comp, ci, cj, bridge):
    """Component labels of the full graph from those of the graph without bridges (union-find
    over the bridges, O(N + M))."""
    nc = int(comp.max()) + 1 if comp.shape[0] else 0
    parent = np.arange(nc)
    for e in range(ci.shape[0]):
        if not bridge[e]:
            continue
        a = comp[ci[e]]
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        b = comp[cj[e]]
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        if a != b:
            parent[max(a, b)] = min(a, b)
    out = np.empty(comp.shape[0], np.int64)
    for v in range(comp.shape[0]):
        a = comp[v]
        while parent[a] != a:
            a = parent[a]
        out[v] = a
    return out


def halfedge_shifts(shift: np.ndarray) -> np.ndarray:
    """Image shifts of the half-edges (2E, 2): +n for 2e, -n for 2e + 1."""
    hs = np.empty((2 * shift.shape[0], 2), np.int64)
    hs[0::2] = shift
    hs[1::2] = -shift
    return hs


@njit
def _first_duplicate(n, ptr, adj, dest, hshift):
    """An edge whose (dest, shift) repeats among the half-edges of a vertex, or -1. O(sum deg^2)."""
    for v in range(n):
        for a in range(ptr[v], ptr[v + 1]):
            ha = adj[a]
            for b in range(a + 1, ptr[v + 1]):
                hb = adj[b]
                if dest[ha] == dest[hb] and hshift[ha, 0] == hshift[hb, 0] and hshift[ha, 1] == hshift[hb, 1]:
                    return max(ha, hb) >> 1
    return -1


def check_duplicates(ci, cj, cs, csr=None, hs=None) -> None:
    """Raise :class:`InputError` if a contact is listed twice (also as (j, i, -n))."""
    n = int(max(ci.max(), cj.max())) + 1 if ci.shape[0] else 0
    ptr, adj, dest = csr if csr is not None else _csr(n, ci, cj)
    hs = halfedge_shifts(cs) if hs is None else hs
    k = _first_duplicate(ptr.shape[0] - 1, ptr, adj, dest, hs)
    if k >= 0:
        raise InputError(
            f"contacts: contact {k} (particles {int(ci[k])}, {int(cj[k])}, "
            f"image shift {cs[k].tolist()}) is listed more than once"
        )


def find_bridges(n_particles: int, ci, cj) -> np.ndarray:
    """Bridges of the multigraph with edges (ci[e], cj[e]), (M,) bool. O(N + M)."""
    ci = np.ascontiguousarray(ci, np.int64)
    cj = np.ascontiguousarray(cj, np.int64)
    ptr, adj, dest = _csr(n_particles, ci, cj)
    return _bridges(n_particles, ptr, adj, dest)


def components(n_particles: int, ci, cj, cs, active=None):
    """Connected components of the active edges with their torus-wrapping rank.

    Returns
    -------
    comp : (N,) int64, component label of each particle
    offset : (N, 2) int64, image offset u_k of each particle along the BFS tree
    rank : (n_components,) int64, rank of the net image shifts of the component's cycles
    """
    ci = np.ascontiguousarray(ci, np.int64)
    cj = np.ascontiguousarray(cj, np.int64)
    ptr, adj, dest = _csr(n_particles, ci, cj)
    if active is None:
        active = np.ones(ci.shape[0], np.bool_)
    return _lift_components(
        n_particles, ptr, adj, dest, halfedge_shifts(np.asarray(cs, np.int64)), np.ascontiguousarray(active, np.bool_)
    )


@njit
def _classify(n, ptr, adj, dest, comp, core_label, comp_full):
    """Removal class of every particle (module docstring), (N,) int8. O(N + M).

    Pendant particles: repeated deletion of particles with exactly one remaining contact (a queue;
    the particles left form the 2-core, so the order of deletion does not matter).
    """
    removed = np.full(n, PENINSULAR, np.int8)
    core_full = -1
    for v in range(n):
        if comp[v] == core_label:
            core_full = comp_full[v]
            break
    d = np.empty(n, np.int64)
    for v in range(n):
        d[v] = ptr[v + 1] - ptr[v]
    gone = np.zeros(n, np.bool_)
    alive = np.ones(adj.shape[0] // 2, np.bool_)
    queue = np.empty(n, np.int64)
    tail = 0
    for v in range(n):
        if d[v] == 1:
            queue[tail] = v
            tail += 1
    head = 0
    while head < tail:
        v = queue[head]
        head += 1
        if gone[v] or d[v] != 1:
            continue
        gone[v] = True
        for a in range(ptr[v], ptr[v + 1]):
            h = adj[a]
            e = h >> 1
            if alive[e]:
                alive[e] = False
                w = dest[h]
                d[v] -= 1
                d[w] -= 1
                if d[w] == 1 and not gone[w]:
                    queue[tail] = w
                    tail += 1
                elif d[w] == 0:  # the last two particles of a tree: both are pendant
                    gone[w] = True
    for v in range(n):
        deg = ptr[v + 1] - ptr[v]
        if deg == 0:
            removed[v] = ISOLATED
        elif comp[v] == core_label:
            removed[v] = KEPT
        elif comp_full[v] != core_full:
            removed[v] = ISLAND
        elif gone[v]:
            removed[v] = PENDANT
    return removed


@njit
def _kept_edges(ci, cj, cs, bridge, comp, core_label):
    """Edges of the framework (not bridges, in the wrapping component): i, j, shift, contact index."""
    m = 0
    for e in range(ci.shape[0]):
        if not bridge[e] and comp[ci[e]] == core_label:
            m += 1
    ei = np.empty(m, np.int64)
    ej = np.empty(m, np.int64)
    es = np.empty((m, 2), np.int64)
    idx = np.empty(m, np.int64)
    k = 0
    for e in range(ci.shape[0]):
        if not bridge[e] and comp[ci[e]] == core_label:
            ei[k] = ci[e]
            ej[k] = cj[e]
            es[k, 0] = cs[e, 0]
            es[k, 1] = cs[e, 1]
            idx[k] = e
            k += 1
    return ei, ej, es, idx


def build_graph(n_particles: int, contacts_i, contacts_j, contacts_shift) -> ParticleGraph:
    """Prune the contact graph to the framework (see the module docstring). O(N + M).

    Parameters
    ----------
    n_particles : int
    contacts_i, contacts_j : (M,) int64, checked indices in 0..N-1
    contacts_shift : (M, 2) int64 image shifts

    Raises
    ------
    InputError
        empty contact list, duplicated contacts, no component that wraps the torus in two
        directions, or two such components (impossible without crossing edges).
    """
    n = int(n_particles)
    ci = np.ascontiguousarray(contacts_i, np.int64)
    cj = np.ascontiguousarray(contacts_j, np.int64)
    cs = np.ascontiguousarray(contacts_shift, np.int64).reshape(-1, 2)
    if ci.shape[0] == 0:
        raise InputError("contacts: the contact list is empty, there is no particle graph")
    ptr, adj, dest = _csr(n, ci, cj)
    hs = halfedge_shifts(cs)
    check_duplicates(ci, cj, cs, (ptr, adj, dest), hs)
    bridge = _bridges(n, ptr, adj, dest)
    comp, _, rank = _lift_components(n, ptr, adj, dest, hs, ~bridge)
    wrapping = np.flatnonzero(rank == 2)
    if wrapping.size == 0:
        raise InputError(
            f"contacts: no group of particles spans the periodic cell in two directions "
            f"({n} particles, {ci.shape[0]} contacts, {int(bridge.sum())} bridges): the graph "
            "has no void-cell tessellation"
        )
    if wrapping.size > 1:
        raise InputError(
            f"contacts: {wrapping.size} separate groups of particles each span the periodic cell; "
            "on a torus that needs crossing contact lines (non-planar graph from strongly "
            "overlapping particles?)"
        )
    # components of the full graph = components of the bridge-free graph joined by the bridges
    comp_full = _join_by_bridges(comp, ci, cj, bridge)
    removed = _classify(n, ptr, adj, dest, comp, int(wrapping[0]), comp_full)
    ei, ej, es, idx = _kept_edges(ci, cj, cs, bridge, comp, int(wrapping[0]))
    return ParticleGraph(
        n_particles=n, edge_i=ei, edge_j=ej, edge_shift=es, edge_contact=idx, removed=removed, bridge=bridge
    )
