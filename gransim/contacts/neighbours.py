"""Periodic neighbour (contact candidate) search: a linked-cell list in fractional coordinates.

For a cell C (columns a1, a2) the unit square of fractional coordinates is cut into
nb1 x nb2 bins. Two points whose bins differ by more than k1 in the first index are
farther apart than ``k1 * h1 / nb1`` (h1 = A/|a2|, the distance between the edges
parallel to a2), so scanning bin offsets -k..k in an *unwrapped* bin lattice finds
every image within the cutoff, each (pair, image shift) exactly once, for any
shear and for cells smaller than the cutoff (then several images of one partner,
or a particle's own image, are returned). Cost O(N) for bins of size ~ cutoff.

Convention: a pair (i, j, n) means particle j's image x_j + C n is near x_i; its
branch vector is l_ij = x_j + C n - x_i (from i to j, as l_ij in eq (2) of Meier et al.).
Each pair is returned once: i < j, or i == j with n lexicographically positive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._numba import njit, pjit, prange
from .._validate import as_array
from ..errors import InputError
from ..geometry.cell import cell_heights, check_cell

#: most bins per particle (bounds memory for very sparse or tiny-cutoff inputs)
MAX_BINS_PER_PARTICLE = 4


@dataclass(frozen=True)
class NeighbourList:
    """Contact candidates of a periodic packing.

    Attributes
    ----------
    i, j : (M,) int64
        Particle indices (i <= j).
    shift : (M, 2) int64
        Image shift n of j relative to the given (unwrapped) positions.
    branch : (M, 2) float64
        l_ij = x_j + C n - x_i (m).
    """

    i: np.ndarray
    j: np.ndarray
    shift: np.ndarray
    branch: np.ndarray

    def __len__(self) -> int:
        return self.i.shape[0]

    @property
    def distance(self) -> np.ndarray:
        """|l_ij| (M,)."""
        return np.sqrt(np.einsum("ij,ij->i", self.branch, self.branch))

    def overlaps(self, radii: np.ndarray) -> np.ndarray:
        """eps_ij = r_i + r_j - |l_ij| (M,), eq (3) of Meier et al."""
        return radii[self.i] + radii[self.j] - self.distance

    def sorted_keys(self) -> np.ndarray:
        """Rows (i, j, n1, n2) in lexicographic order, for comparing lists."""
        keys = np.column_stack([self.i, self.j, self.shift])
        return keys[np.lexsort(keys.T[::-1])]


@njit
def _bin_sort(s, nb1, nb2):
    n = s.shape[0]
    nbins = nb1 * nb2
    b = np.empty(n, np.int64)
    count = np.zeros(nbins + 1, np.int64)
    for p in range(n):
        b1 = int(s[p, 0] * nb1)
        b2 = int(s[p, 1] * nb2)
        b1 = min(max(b1, 0), nb1 - 1)
        b2 = min(max(b2, 0), nb2 - 1)
        b[p] = b1 * nb2 + b2
        count[b[p] + 1] += 1
    for q in range(nbins):
        count[q + 1] += count[q]
    order = np.empty(n, np.int64)
    fill = count[:-1].copy()
    for p in range(n):
        order[fill[b[p]]] = p
        fill[b[p]] += 1
    return b, count, order


@njit
def _scan_one(i, xw, radii, xs, rs, C, skin, b, start, order, nb1, nb2, k1, k2, out_j, out_t, out_l, base, write):
    """Visit every image near particle i; count (write=False) or store the pairs.

    Candidates are read from ``xs``/``rs``, copies of positions and radii in bin order, so the
    inner loop walks contiguous memory; ``order`` maps them back to particle indices.
    """
    m = 0
    bi1 = b[i] // nb2
    bi2 = b[i] % nb2
    xi0 = xw[i, 0]
    xi1 = xw[i, 1]
    for o1 in range(-k1, k1 + 1):
        u1 = bi1 + o1
        w1 = u1 % nb1
        t1 = (u1 - w1) // nb1
        for o2 in range(-k2, k2 + 1):
            u2 = bi2 + o2
            w2 = u2 % nb2
            t2 = (u2 - w2) // nb2
            off0 = C[0, 0] * t1 + C[0, 1] * t2
            off1 = C[1, 0] * t1 + C[1, 1] * t2
            q = w1 * nb2 + w2
            for p in range(start[q], start[q + 1]):
                j = order[p]
                if j < i:
                    continue
                if j == i and not (t1 > 0 or (t1 == 0 and t2 > 0)):
                    continue
                d0 = xs[p, 0] + off0 - xi0
                d1 = xs[p, 1] + off1 - xi1
                cut = radii[i] + rs[p] + skin
                if d0 * d0 + d1 * d1 < cut * cut:
                    if write:
                        out_j[base + m] = j
                        out_t[base + m, 0] = t1
                        out_t[base + m, 1] = t2
                        out_l[base + m, 0] = d0
                        out_l[base + m, 1] = d1
                    m += 1
    return m


@pjit
def _cell_list_pairs(xw, s, radii, C, skin, nb1, nb2, k1, k2):
    n = xw.shape[0]
    b, start, order = _bin_sort(s, nb1, nb2)
    xs = np.empty((n, 2))
    rs = np.empty(n)
    for p in prange(n):
        xs[p, 0] = xw[order[p], 0]
        xs[p, 1] = xw[order[p], 1]
        rs[p] = radii[order[p]]
    counts = np.zeros(n + 1, np.int64)
    dj = np.empty(0, np.int64)
    dt = np.empty((0, 2), np.int64)
    dl = np.empty((0, 2))
    # particles are visited in bin order (i = order[q]) so consecutive iterations scan the same,
    # cache-resident bins; results still land in the slots of the original index i
    for q in prange(n):
        i = order[q]
        counts[i + 1] = _scan_one(i, xw, radii, xs, rs, C, skin, b, start, order, nb1, nb2, k1, k2,
                                  dj, dt, dl, 0, False)
    for i in range(n):
        counts[i + 1] += counts[i]
    m = counts[n]
    out_i = np.empty(m, np.int64)
    out_j = np.empty(m, np.int64)
    out_t = np.empty((m, 2), np.int64)
    out_l = np.empty((m, 2))
    for q in prange(n):
        i = order[q]
        _scan_one(i, xw, radii, xs, rs, C, skin, b, start, order, nb1, nb2, k1, k2,
                  out_j, out_t, out_l, counts[i], True)
        for e in range(counts[i], counts[i + 1]):
            out_i[e] = i
    return out_i, out_j, out_t, out_l


def _check_inputs(positions, radii, cell, skin):
    x = as_array(positions, "positions", (None, 2))
    r = as_array(radii, "radii", (x.shape[0],))
    if np.any(r <= 0):
        raise InputError(f"radii: must be > 0, radius {int(np.argmax(r <= 0))} is {r[np.argmax(r <= 0)]!r}")
    C = check_cell(cell)
    skin = float(skin)
    if not np.isfinite(skin) or skin < 0:
        raise InputError(f"skin: must be finite and >= 0, got {skin!r}")
    return x, r, C, skin


def _wrap_fractional(x, C):
    """Wrapped positions, their fractional coordinates in [0, 1) and the image counts."""
    s = x @ np.linalg.inv(C).T
    n = np.floor(s)
    sw = s - n
    top = sw >= 1.0  # round-off at the upper face: the point belongs to the next image
    sw[top] = 0.0
    n[top] += 1.0
    return sw @ C.T, sw, n.astype(np.int64)


def bin_layout(cell: np.ndarray, cutoff: float, n_particles: int) -> tuple[int, int, int, int]:
    """Bins (nb1, nb2) and scan half-widths (k1, k2) for a cutoff (m)."""
    h = cell_heights(cell)
    max_bins = max(1, MAX_BINS_PER_PARTICLE * n_particles)
    nb = [max(1, int(np.floor(hk / cutoff))) for hk in h]
    while nb[0] * nb[1] > max_bins:
        nb = [max(1, v // 2) for v in nb]
    k = [max(1, int(np.ceil(cutoff * nbk / hk - 1e-12))) for nbk, hk in zip(nb, h)]
    return nb[0], nb[1], k[0], k[1]


def find_neighbours(positions, radii, cell, skin: float = 0.0) -> NeighbourList:
    """All pairs (with periodic image) whose gap is below ``skin``: |l_ij| < r_i + r_j + skin.

    Parameters
    ----------
    positions : (N, 2) array, m. Need not lie in the primary cell.
    radii : (N,) array, m, > 0.
    cell : (2, 2) array, lattice vectors as columns, m.
    skin : float, m, >= 0. ``skin = 0`` returns the overlapping pairs (contacts).

    Returns
    -------
    NeighbourList, pairs sorted by i. O(N) time and memory.
    """
    x, r, C, skin = _check_inputs(positions, radii, cell, skin)
    xw, sw, nimg = _wrap_fractional(x, C)
    cutoff = 2.0 * float(r.max()) + skin
    nb1, nb2, k1, k2 = bin_layout(C, cutoff, x.shape[0])
    i, j, t, l = _cell_list_pairs(xw, sw, r, C, skin, nb1, nb2, k1, k2)
    shift = t + nimg[i] - nimg[j]
    return NeighbourList(i=i, j=j, shift=shift, branch=l)


def find_neighbours_bruteforce(positions, radii, cell, skin: float = 0.0) -> NeighbourList:
    """O(N^2 K^2) reference search over all image shifts in numpy (for tests)."""
    x, r, C, skin = _check_inputs(positions, radii, cell, skin)
    cutoff = 2.0 * float(r.max()) + skin
    # images farther than this many cell heights cannot be within the cutoff
    extent = np.abs(np.linalg.solve(C, x.T).T)
    K = int(np.ceil(cutoff / cell_heights(C).min() + 2 * extent.max())) + 1
    rows_i, rows_j, rows_t, rows_l = [], [], [], []
    n = x.shape[0]
    for n1 in range(-K, K + 1):
        for n2 in range(-K, K + 1):
            off = C @ np.array([n1, n2], float)
            d = x[None, :, :] + off - x[:, None, :]
            cut = r[:, None] + r[None, :] + skin
            hit = np.einsum("ijk,ijk->ij", d, d) < cut**2
            ii, jj = np.nonzero(hit)
            keep = (ii < jj) | ((ii == jj) & ((n1 > 0) | ((n1 == 0) & (n2 > 0))))
            ii, jj = ii[keep], jj[keep]
            rows_i.append(ii)
            rows_j.append(jj)
            rows_t.append(np.tile([n1, n2], (ii.size, 1)))
            rows_l.append(d[ii, jj])
    i = np.concatenate(rows_i).astype(np.int64)
    j = np.concatenate(rows_j).astype(np.int64)
    t = np.concatenate(rows_t).astype(np.int64).reshape(-1, 2)
    l = np.concatenate(rows_l).reshape(-1, 2)
    order = np.lexsort((t[:, 1], t[:, 0], j, i))
    del n
    return NeighbourList(i=i[order], j=j[order], shift=t[order], branch=l[order])
