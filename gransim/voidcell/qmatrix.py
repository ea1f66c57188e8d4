"""The consistent matrix Q^m of eq (7) (Kuhn 002, eqs 10-12).

For a polygonal face with m vertices labelled 0..m-1 counter-clockwise, edge j joins
vertex j to vertex j+1, v^j_hat = v^{j+1} - v^j is the edge's relative velocity (eq 5) and
b^j its outward normal scaled by its length (Fig. 2b). The average velocity gradient of the
face is (eq 7)

    L_pq = 1/(6 A) sum_{j1, j2} Q^m_{j1 j2} v^{j1}_hat_p b^{j2}_q.

Q^m is made unique by the consistency condition (eq 10): Q^m_{pq} depends only on the directed
separation d = q - p (mod m). It follows from the recursion (eq 11) started at Q^2 = 0 (eq 12):

    Q^{m+1}(d) = 0                                        d = 0
               = (m Q^m(1) + 3) / (m+1)                   d = 1
               = ((m+1-d) Q^m(d) + d Q^m(d-1)) / (m+1)    2 <= d <= m-1
               = (m Q^m(m-1) - 3) / (m+1)                 d = m

Reading of the last case: the printed text has ``Q^m_{pq}`` with q - p = m, i.e. separation 0 (mod
m), which is zero and would make Q^{m+1}(m) = -3/(m+1), contradicting Table 1 (e.g. Q^4(3) = -6/4)
and the antisymmetry Q(m - d) = -Q(d) that eq (7) needs (the first line of Table 1 is matrix 8_1).
The separation m - 1 (the last non-zero entry of Q^m, the mirror of case d = 1) reproduces every
row of Table 1 and is used here. The recursion solves to Q^m(d) = 3 (m - 2 d) / m for d != 0; the
tests check this, eq (7) against the boundary integral (1/A) sum_j (v^j + v^{j+1})/2 (x) b^j, and
Table 1.
"""

from __future__ import annotations

from fractions import Fraction
from functools import lru_cache

import numpy as np

from ..errors import InputError

#: the seed valence of the recursion (eq 12)
_SEED_M = 2


_ROWS: dict = {_SEED_M: (Fraction(0), Fraction(0))}


def _q_row(m: int) -> tuple:
    """Q^m as a function of the directed separation d = 0..m-1, exact rationals (eq 11)."""
    k = max(v for v in _ROWS if v <= m)
    while k < m:
        prev = _ROWS[k]  # step from valence k to k + 1
        row = [Fraction(0)] * (k + 1)
        for d in range(1, k + 1):
            if d == 1:
                row[d] = (k * prev[1] + 3) / (k + 1)
            elif d == k:
                row[d] = (k * prev[k - 1] - 3) / (k + 1)
            else:
                row[d] = ((k + 1 - d) * prev[d] + d * prev[d - 1]) / (k + 1)
        k += 1
        _ROWS[k] = tuple(row)
    return _ROWS[m]


def q_separations(m: int) -> np.ndarray:
    """Consistent Q^m as a function of the directed separation d = q - p (mod m), shape (m,)."""
    m = _check_m(m)
    return np.array([float(v) for v in _q_row(m)])


@lru_cache(maxsize=64)
def _q_matrix_cached(m: int) -> np.ndarray:
    row = q_separations(m)
    d = (np.arange(m)[None, :] - np.arange(m)[:, None]) % m
    Q = row[d]
    Q.flags.writeable = False
    return Q


def q_matrix(m: int) -> np.ndarray:
    """The consistent (m, m) matrix Q^m of eq (7), from the recursion eqs (10)-(12).

    Parameters
    ----------
    m : int
        Valence of the polygon (number of vertices = number of edges), m >= 2 (Q^2 = 0).

    Returns
    -------
    (m, m) float64 array (read-only), Q[p, q] = Q^m(q - p mod m).
    """
    return _q_matrix_cached(_check_m(m))


def _check_m(m) -> int:
    try:
        mi = int(m)
    except (TypeError, ValueError):
        raise InputError(f"m: expected an integer valence >= 2, got {m!r}") from None
    if mi != m or mi < _SEED_M:
        raise InputError(f"m: expected an integer valence >= 2, got {m!r}")
    if mi > 4096:
        raise InputError(f"m: valence {mi} is implausibly large for a void cell (max 4096)")
    return mi
