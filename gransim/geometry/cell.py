"""Periodic 2D cells.

A cell is a (2, 2) array whose **columns** are the lattice vectors a1, a2 (m).
A point x has fractional coordinates s = C^{-1} x; its periodic images are
x + C n for integer n (2,). Everything here holds for any non-degenerate cell,
sheared (triclinic) cells included.
"""

from __future__ import annotations

import numpy as np

from .._validate import as_array
from ..errors import InputError

#: smallest accepted |det C| relative to |a1| |a2|: below it the cell counts as degenerate
DEGENERACY_TOL = 1e-10


def check_cell(cell, name: str = "cell") -> np.ndarray:
    """Validate a (2, 2) cell with columns = lattice vectors; returns float64 copy.

    Raises :class:`InputError` for a wrong shape, non-finite entries, a
    degenerate cell (parallel or zero lattice vectors) or a left-handed cell
    (det C < 0).
    """
    C = as_array(cell, name, (2, 2))
    norms = np.linalg.norm(C, axis=0)
    det = float(np.linalg.det(C))
    if np.any(norms == 0) or abs(det) <= DEGENERACY_TOL * norms[0] * norms[1]:
        raise InputError(f"{name}: degenerate cell (lattice vectors {C[:, 0]}, {C[:, 1]}; det = {det:.3g})")
    if det < 0:
        raise InputError(f"{name}: lattice vectors must be right-handed (det C = {det:.3g} < 0)")
    return C


def cell_area(cell: np.ndarray) -> float:
    """Area of the cell, det C (m^2)."""
    return float(np.linalg.det(cell))


def cell_heights(cell: np.ndarray) -> np.ndarray:
    """Distances between opposite cell edges, (2,): h_k = A / |a_other|.

    A sphere of diameter < min(h) cannot touch two images of one particle.
    """
    A = abs(cell_area(cell))
    n = np.linalg.norm(cell, axis=0)
    return np.array([A / n[1], A / n[0]])


def to_fractional(x: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """Fractional coordinates s = C^{-1} x of points (..., 2)."""
    return np.linalg.solve(cell, np.asarray(x, dtype=float).reshape(-1, 2).T).T.reshape(np.shape(x))


def to_cartesian(s: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """Cartesian coordinates x = C s of fractional points (..., 2)."""
    return np.asarray(s, dtype=float) @ np.asarray(cell).T


def wrap(x: np.ndarray, cell: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Wrap points into the primary cell (fractional coordinates in [0, 1)).

    Returns ``(xw, n)`` with integer image counts n (..., 2) such that
    ``x = xw + C n``.
    """
    s = to_fractional(x, cell)
    n = np.floor(s)
    sw = s - n
    top = sw >= 1.0  # round-off at the upper face: the point belongs to the next image
    sw[top] = 0.0
    n[top] += 1.0
    return to_cartesian(sw, cell), n.astype(np.int64)


def minimum_image(d: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """Nearest periodic image of separation vectors d (..., 2).

    Searches the 3x3 images around the fractional rounding, which gives the true
    nearest image for every cell whose shear angle is below 60 degrees and still
    a valid (never farther) image otherwise.
    """
    d = np.asarray(d, dtype=float)
    flat = d.reshape(-1, 2)
    s = to_fractional(flat, cell)
    base = flat - to_cartesian(np.round(s), cell)
    best = base.copy()
    best_r2 = np.einsum("ij,ij->i", base, base)
    for n1 in (-1, 0, 1):
        for n2 in (-1, 0, 1):
            if n1 == 0 and n2 == 0:
                continue
            cand = base + cell[:, 0] * n1 + cell[:, 1] * n2
            r2 = np.einsum("ij,ij->i", cand, cand)
            better = r2 < best_r2
            best[better] = cand[better]
            best_r2[better] = r2[better]
    return best.reshape(d.shape)


def image_offsets(shift: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """Cartesian offsets C n for integer image shifts n (M, 2) -> (M, 2)."""
    return np.asarray(shift, dtype=float) @ np.asarray(cell).T
