"""Periodic neighbour (contact candidate) search: a linked-cell list in fractional coordinates.

The bins and the stencil walk are :mod:`gransim.geometry.bins` (shared with the crossing test of
the void-cell graph): bins of the size of the cutoff 2 max(r) + skin in each lattice direction,
scan offsets -k..k in the unwrapped bin lattice, so every image within the cutoff is found once
for any shear and for cells smaller than the cutoff (then several images of one partner, or a
particle's own image, are returned). Two passes of the walk (count, then write into the
pre-allocated list), O(N) time and memory.

Convention: a pair (i, j, n) means particle j's image x_j + C n is near x_i; its
branch vector is l_ij = x_j + C n - x_i (from i to j, as l_ij in eq (2) of Meier et al.).
Each pair is returned once: i < j, or i == j with n lexicographically positive.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array
from ..errors import InputError
from ..geometry.bins import bin_layout as _bin_layout
from ..geometry.bins import pair_list, wrap_fractional
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


#: names of the visitor classes of an earlier version: numba's cache index of ``walk_pairs`` may
#: still name them, and it is unpickled before its stamp is checked (a missing class would crash)
from ..geometry.bins import _PairCount as _PairCounter  # noqa: F401, E402
from ..geometry.bins import _PairList as _PairWriter  # noqa: F401, E402


def _cell_list_pairs(xw, s, radii, C, skin, nb1, nb2, k1, k2, img):
    """Pairs in the order of the walk, grouped by i: (i, j, shift, branch)."""
    return pair_list(xw, s, radii, C, skin, nb1, nb2, k1, k2, img, by_label=True)


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


def bin_layout(cell: np.ndarray, cutoff: float, n_particles: int) -> tuple[int, int, int, int]:
    """Bins (nb1, nb2) and scan half-widths (k1, k2) for a cutoff (m)
    (:func:`gransim.geometry.bins.bin_layout`)."""
    return _bin_layout(cell, cutoff, n_particles, MAX_BINS_PER_PARTICLE)


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
    xw, sw, nimg = wrap_fractional(x, C)
    cutoff = 2.0 * float(r.max()) + skin
    nb1, nb2, k1, k2 = bin_layout(C, cutoff, x.shape[0])
    i, j, shift, l = _cell_list_pairs(xw, sw, np.ascontiguousarray(r), C, skin, nb1, nb2, k1, k2, nimg)
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
