"""Periodic bins (a linked-cell list in fractional coordinates): the one bin-stencil walk of gransim.

For a cell C (columns a1, a2) the unit square of fractional coordinates s = C^{-1} x is cut into
nb1 x nb2 bins. Two points whose bins differ by more than k1 in the first index are farther apart
than ``k1 * h1 / nb1`` (h1 = A / |a2|, the distance between the cell edges parallel to a2), so
scanning bin offsets -k..k in an *unwrapped* bin lattice finds every periodic image within the
cutoff, each (pair, image t) exactly once, for any shear and for cells smaller than the cutoff
(then several images of one partner, or a point's own image, are found). Cost O(N) for bins of
the size of the cutoff.

:func:`walk_pairs` is that walk, shared by the contact search (:mod:`gransim.contacts.neighbours`)
and the crossing test of the void-cell graph (:mod:`gransim.voidcell.dcel`). It visits, for every
point i, every candidate (j, t) with

    |x_j + C t - x_i| < reach_i + reach_j + skin,   and   j > i, or j == i with t > 0

(t lexicographically positive), in a fixed order: points grouped by bin, the stencil offsets
(o1, o2) in increasing order, candidates of a bin in increasing index. For each candidate it calls
:func:`pair_visit` with a *visitor*: an instance of a namedtuple class registered with
:func:`register_pair_visitor` together with a jitted function
``fn(visitor, p, c, i, j, t1, t2, d0, d1, slot) -> bool`` (p, c: bin-order positions of i and j;
(d0, d1) = x_j + C t - x_i; ``slot`` = ``base[p]`` + the number of earlier accepted candidates of
p). The call is resolved by the visitor's numba type at compile time and inlined (the pattern of
:mod:`gransim.contacts.laws`): each visitor gets its own specialised, disk-cached copy of the
walk, and no function objects are passed at run time (numba cannot cache those). The walk returns
the number of accepted candidates per point, so a two-pass use (count, then write at ``base``)
fills a pre-allocated pair list in a deterministic order.

Numba's disk cache of :func:`walk_pairs` tracks this file only: after editing a visitor's
function elsewhere, clear ``NUMBA_CACHE_DIR`` (or touch this file).
"""

from __future__ import annotations

from collections import namedtuple
from collections.abc import Callable

import numpy as np
from numba.extending import overload

from .._numba import njit, pjit, prange
from .cell import cell_heights

#: most bins per point (bounds memory for very sparse or tiny-cutoff inputs)
MAX_BINS_PER_POINT = 4


def bin_layout(
    cell: np.ndarray, cutoff: float, n_points: int, max_bins_per_point: int = MAX_BINS_PER_POINT
) -> tuple[int, int, int, int]:
    """Bins (nb1, nb2) of size >= ``cutoff`` (m) across each pair of cell edges, and the scan
    half-widths (k1, k2) that reach ``cutoff``; at most ``max_bins_per_point * n_points`` bins."""
    h = cell_heights(cell)
    cutoff = float(cutoff)
    max_bins = max(1, int(max_bins_per_point) * int(n_points))
    if not cutoff > 0:  # all reaches zero: one bin, nothing can be within reach
        return 1, 1, 1, 1
    nb = [max(1, int(min(np.floor(hk / cutoff), 2**30))) for hk in h]
    while nb[0] * nb[1] > max_bins:
        nb = [max(1, v // 2) for v in nb]
    k = [max(1, int(np.ceil(cutoff * nbk / hk - 1e-12))) for nbk, hk in zip(nb, h)]
    return nb[0], nb[1], k[0], k[1]


def wrap_fractional(x: np.ndarray, cell: np.ndarray):
    """Wrapped points, their fractional coordinates in [0, 1) and the image counts.

    Returns ``(xw (N, 2), s (N, 2), n (N, 2) int64)`` with ``x = xw + C n`` and ``xw = C s``
    (to round-off), s = C^{-1} x. One compiled pass (no BLAS call: a (N, 2) x (2, 2) product in
    BLAS threads is slow on a busy machine and rounds differently from machine to machine).
    """
    x = _writable(x)
    cell = _writable(cell)
    return _wrap(x, cell, np.ascontiguousarray(np.linalg.inv(cell)))


def _writable(a) -> np.ndarray:
    """``a`` as a writeable C-contiguous float64 array (a copy only when it is not one already).

    numba compiles a read-only array (a frozen :class:`gransim.geometry.Packing`'s positions or
    cell) as another type than a writeable one: the same kernels twice, each loaded from the cache
    (or compiled when it misses) on first use. One type for every caller halves that (the slope's
    pictures, which pass a packing's arrays, loaded 3 kernels more than its candidate sets).
    """
    return np.require(a, np.float64, ["C", "W"])


@pjit
def _wrap(x, C, inv):
    n = x.shape[0]
    xw = np.empty((n, 2))
    sw = np.empty((n, 2))
    img = np.empty((n, 2), np.int64)
    for p in prange(n):
        s0 = inv[0, 0] * x[p, 0] + inv[0, 1] * x[p, 1]
        s1 = inv[1, 0] * x[p, 0] + inv[1, 1] * x[p, 1]
        n0 = np.floor(s0)
        n1 = np.floor(s1)
        s0 -= n0
        s1 -= n1
        if s0 >= 1.0:  # round-off at the upper face: the point belongs to the next image
            s0 = 0.0
            n0 += 1.0
        if s1 >= 1.0:
            s1 = 0.0
            n1 += 1.0
        sw[p, 0] = s0
        sw[p, 1] = s1
        img[p, 0] = int(n0)
        img[p, 1] = int(n1)
        xw[p, 0] = C[0, 0] * s0 + C[0, 1] * s1
        xw[p, 1] = C[1, 0] * s0 + C[1, 1] * s1
    return xw, sw, img


@njit
def bin_sort(s, nb1, nb2):
    """Counting sort of points (fractional coordinates s (N, 2) in [0, 1)) into nb1 x nb2 bins.

    Returns ``start`` (nb1 nb2 + 1,) int64 and ``order`` (N,) int64: the points of bin
    q = b1 nb2 + b2 are ``order[start[q]:start[q + 1]]``, in increasing index (stable). O(N + bins).
    """
    n = s.shape[0]
    nbins = nb1 * nb2
    b = np.empty(n, np.int32)
    start = np.zeros(nbins + 1, np.int64)
    for p in range(n):
        b1 = min(max(int(s[p, 0] * nb1), 0), nb1 - 1)
        b2 = min(max(int(s[p, 1] * nb2), 0), nb2 - 1)
        q = b1 * nb2 + b2
        b[p] = q
        start[q + 1] += 1
    for q in range(nbins):
        start[q + 1] += start[q]
    fill = start[:-1].copy()
    order = np.empty(n, np.int64)
    for p in range(n):
        q = b[p]
        order[fill[q]] = p
        fill[q] += 1
    return start, order


@njit(inline="always")
def _wrap_bin(u, nb):
    """(w, t) with u = w + t nb and 0 <= w < nb (the common case |u| < nb without a division)."""
    if u >= 0 and u < nb:
        return u, 0
    w = u % nb
    return w, (u - w) // nb


# -- the visitor registry (pair callbacks resolved at compile time) ---------------------------
_VISITORS: dict[type, Callable] = {}


def register_pair_visitor(cls: type, fn: Callable) -> None:
    """Register a namedtuple class ``cls`` with its jitted ``fn(visitor, p, c, i, j, t1, t2, d0, d1,
    slot) -> bool`` (True: the candidate is accepted and counted). Define both at module level of
    an importable module: the class is part of the cache key of :func:`walk_pairs`. Jit ``fn``
    with ``njit(inline="always")``: it is inlined into the serial walk over a chunk of bins."""
    if not (isinstance(cls, type) and issubclass(cls, tuple) and hasattr(cls, "_fields")):
        raise TypeError(f"register_pair_visitor: cls must be a namedtuple class, got {cls!r}")
    _VISITORS[cls] = fn


def pair_visit(visitor, p, c, i, j, t1, t2, d0, d1, slot):
    """The registered function of ``visitor``'s class (interpreted: NUMBA_DISABLE_JIT)."""
    return _VISITORS[type(visitor)](visitor, p, c, i, j, t1, t2, d0, d1, slot)


@overload(pair_visit, inline="always")
def _ov_pair_visit(visitor, p, c, i, j, t1, t2, d0, d1, slot):
    fn = _VISITORS.get(getattr(visitor, "instance_class", None))
    if fn is None:
        return None

    def impl(visitor, p, c, i, j, t1, t2, d0, d1, slot):
        return fn(visitor, p, c, i, j, t1, t2, d0, d1, slot)

    return impl


#: bins per task of the parallel walk
CHUNK_BINS = 256


@pjit
def walk_pairs(visitor, xs, rs, labels, C, skin, start, nb1, nb2, k1, k2, base, half=False):
    """The bin-stencil walk (module docstring): call the visitor for every candidate pair.

    Parameters
    ----------
    visitor : instance of a registered namedtuple class
    xs : (N, 2) float64
        Wrapped points in bin order (``x[order]`` of :func:`bin_sort`), m.
    rs : (N,) float64
        Reach of each point in bin order, m (e.g. the disk radius).
    labels : (N,) int64
        Index i of each point in bin order (``order``); pairs are kept once by these indices.
    C : (2, 2) float64, lattice vectors as columns (m); skin : float, m.
    start : (nb1 nb2 + 1,) int64, bins of :func:`bin_sort`.
    nb1, nb2, k1, k2 : int, :func:`bin_layout`.
    base : (N,) int64
        First ``slot`` of each point (bin order), passed through to the visitor.
    half : bool
        Visit each pair (and image) once by the *bins* instead: only the stencil offsets with
        o1 > 0 or (o1 = 0, o2 >= 0), and in the own bin only the later points, so that no
        candidate is read twice (half the work; for symmetric tests whose order does not matter).
        Then (i, j) need not satisfy j >= i: the pair comes from whichever point scans it.

    Returns
    -------
    counts : (N,) int64, accepted candidates of each point (bin order).
    """
    n = xs.shape[0]
    counts = np.zeros(n, np.int64)
    nbins = nb1 * nb2
    nchunk = (nbins + CHUNK_BINS - 1) // CHUNK_BINS
    # the prange body is one call per chunk of bins: the visitor is inlined into the serial loops
    # of _walk_bins, never into the parfor (there numba 0.68 loses writes through the arrays of a
    # namedtuple, measured), and per-candidate calls (refcounts of the visitor's arrays) vanish
    for ch in prange(nchunk):
        _walk_bins(
            visitor,
            xs,
            rs,
            labels,
            C,
            skin,
            start,
            nb1,
            nb2,
            k1,
            k2,
            base,
            half,
            ch * CHUNK_BINS,
            min(nbins, (ch + 1) * CHUNK_BINS),
            counts,
        )
    return counts


@njit
def _walk_bins(visitor, xs, rs, labels, C, skin, start, nb1, nb2, k1, k2, base, half, q0, q1, counts):
    """The walk over bins q0 <= q < q1 (serial); writes ``counts`` of their points."""
    c00 = C[0, 0]
    c01 = C[0, 1]
    c10 = C[1, 0]
    c11 = C[1, 1]
    for bq in range(q0, q1):
        b1 = bq // nb2
        b2 = bq - b1 * nb2
        for p in range(start[bq], start[bq + 1]):
            i = labels[p]
            xi0 = xs[p, 0]
            xi1 = xs[p, 1]
            ri = rs[p]
            m = 0
            for o1 in range(-k1, k1 + 1):
                if half and o1 < 0:
                    continue
                w1, t1 = _wrap_bin(b1 + o1, nb1)
                for o2 in range(-k2, k2 + 1):
                    if half and o1 == 0 and o2 < 0:
                        continue
                    w2, t2 = _wrap_bin(b2 + o2, nb2)
                    off0 = c00 * t1 + c01 * t2
                    off1 = c10 * t1 + c11 * t2
                    q = w1 * nb2 + w2
                    self_ok = t1 > 0 or (t1 == 0 and t2 > 0)
                    c0 = start[q]
                    if half and o1 == 0 and o2 == 0:
                        c0 = p + 1  # the own bin: later points only
                    for c in range(c0, start[q + 1]):
                        j = labels[c]
                        if not half and (j < i or (j == i and not self_ok)):
                            continue
                        d0 = xs[c, 0] + off0 - xi0  # this order of operations is the contract
                        d1 = xs[c, 1] + off1 - xi1
                        cut = ri + rs[c] + skin
                        if d0 * d0 + d1 * d1 < cut * cut and pair_visit(
                            visitor, p, c, i, j, t1, t2, d0, d1, base[p] + m
                        ):
                            m += 1
            counts[p] = m


@pjit
def bin_points(x, s, reach, nb1, nb2):
    """Bins of points and their bin-order copies: ``(start, order, xs, rs)`` for
    :func:`walk_pairs`, from wrapped points ``x`` (N, 2), their fractional coordinates ``s`` (N, 2)
    and reaches (N,)."""
    start, order = bin_sort(s, nb1, nb2)
    n = order.shape[0]
    xs = np.empty((n, 2))
    rs = np.empty(n)
    for p in prange(n):
        k = order[p]
        xs[p, 0] = x[k, 0]
        xs[p, 1] = x[k, 1]
        rs[p] = reach[k]
    return start, order, xs, rs


#: visitors of the pair list (:func:`pair_list`): store each pair at its slot, with the image
#: t + img_i - img_j of j relative to the given (unwrapped) points / only count (the first pass)
_PairList = namedtuple("_PairList", ["out_i", "out_j", "out_t", "out_d", "img"])
_PairCount = namedtuple("_PairCount", ["unused"])


@njit(inline="always")
def _store_pair(v, p, c, i, j, t1, t2, d0, d1, slot):
    v.out_i[slot] = i
    v.out_j[slot] = j
    v.out_t[slot, 0] = t1 + v.img[i, 0] - v.img[j, 0]
    v.out_t[slot, 1] = t2 + v.img[i, 1] - v.img[j, 1]
    v.out_d[slot, 0] = d0
    v.out_d[slot, 1] = d1
    return True


@njit(inline="always")
def _count_only(v, p, c, i, j, t1, t2, d0, d1, slot):
    return True


register_pair_visitor(_PairList, _store_pair)
register_pair_visitor(_PairCount, _count_only)


@njit
def _slots(counts, order, by_label):
    """First slot of each point (bin order) and the number of pairs: pairs grouped by point
    index i (``by_label``) or in bin order."""
    n = counts.shape[0]
    base = np.empty(n, np.int64)
    if by_label:
        by_i = np.zeros(n + 1, np.int64)
        for p in range(n):
            by_i[order[p] + 1] = counts[p]
        for k in range(n):
            by_i[k + 1] += by_i[k]
        for p in range(n):
            base[p] = by_i[order[p]]
        return base, by_i[n]
    m = 0
    for p in range(n):
        base[p] = m
        m += counts[p]
    return base, m


def pair_list(xw, s, reach, C, skin, nb1, nb2, k1, k2, img, by_label=True, half=False):
    """The pair list of :func:`walk_pairs` (count, then write into pre-allocated arrays).

    ``xw`` (N, 2) wrapped points with fractional coordinates ``s``, ``reach`` (N,), ``img`` (N, 2)
    int64 their image counts (``x = xw + C img``). Returns i, j (M,) int64, t (M, 2) int64 (image
    of j relative to the unwrapped points) and d (M, 2) = xw_j + C t_bins - xw_i (m); grouped by
    i in increasing order (``by_label``), else in bin order; in each group in walk order.
    """
    start, order, xs, rs = bin_points(xw, s, reach, nb1, nb2)
    C = _writable(C)
    n = xw.shape[0]
    counts = walk_pairs(_PairCount(0), xs, rs, order, C, skin, start, nb1, nb2, k1, k2, np.zeros(n, np.int64), half)
    base, m = _slots(counts, order, by_label)
    out = _PairList(np.empty(m, np.int64), np.empty(m, np.int64), np.empty((m, 2), np.int64), np.empty((m, 2)), img)
    walk_pairs(out, xs, rs, order, C, skin, start, nb1, nb2, k1, k2, base, half)
    return out.out_i, out.out_j, out.out_t, out.out_d


def pairs_within(x, reach, cell, skin: float = 0.0, half: bool = False):
    """All pairs (i, j, t) of points with |x_j + C t - x_i| < reach_i + reach_j + skin, once each.

    Parameters
    ----------
    x : (N, 2) float64, points (m), anywhere; reach : (N,) float64 >= 0 (m); cell : (2, 2) (m);
    skin : float (m); half : bool, the half-stencil walk (then i > j occurs).

    Returns
    -------
    i, j : (M,) int64; t : (M, 2) int64 image of j relative to the *wrapped* points;
    d : (M, 2) float64 = xw_j + C t - xw_i (m), xw the wrapped points (:func:`wrap_fractional`).
    """
    x = np.ascontiguousarray(x, np.float64)
    reach = np.ascontiguousarray(reach, np.float64)
    cell = np.ascontiguousarray(cell, np.float64)
    xw, s, _ = wrap_fractional(x, cell)
    n = x.shape[0]
    nb1, nb2, k1, k2 = bin_layout(cell, 2.0 * float(reach.max(initial=0.0)) + float(skin), n)
    return pair_list(
        xw, s, reach, cell, float(skin), nb1, nb2, k1, k2, np.zeros((n, 2), np.int64), by_label=False, half=bool(half)
    )
