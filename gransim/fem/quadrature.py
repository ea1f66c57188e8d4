"""Gauss-Legendre quadrature on [-1, 1] and its tensor product on the parent square [-1, 1]^2.

The n-point Gauss-Legendre rule integrates polynomials of degree <= 2n - 1 exactly and no higher
(Abramowitz & Stegun, Handbook of Mathematical Functions, 1964, eq. 25.4.29); the n x n product rule
integrates xi^a eta^b exactly for a, b <= 2n - 1. Points come from :func:`numpy.polynomial.legendre.leggauss`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_int


def gauss_legendre(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Points (n,) and weights (n,) of the n-point Gauss-Legendre rule on [-1, 1] (weights sum to 2)."""
    n = as_int(n, "n (Gauss points per direction)", 1, 20)
    x, w = np.polynomial.legendre.leggauss(n)
    return x, w


@dataclass(frozen=True, eq=False)
class SquareRule:
    """An n x n Gauss rule on the parent square.

    Attributes
    ----------
    points : (n*n, 2)
        (xi, eta) of each point, ordered with xi fastest (row by row from the bottom).
    weights : (n*n,)
        Product weights; they sum to 4 (the parent square's area).
    """

    n: int
    points: np.ndarray
    weights: np.ndarray

    @property
    def size(self) -> int:
        """Number of points n^2."""
        return self.weights.size


def square_rule(n: int) -> SquareRule:
    """The n x n tensor-product Gauss-Legendre rule (2 x 2: the 4 Gauss points of Guo & Zhao's
    reduced integration; 3 x 3: full integration of Q8 and Q9)."""
    x, w = gauss_legendre(n)
    eta, xi = np.meshgrid(x, x, indexing="ij")
    pts = np.stack([xi.ravel(), eta.ravel()], axis=1)
    wts = np.outer(w, w).ravel()
    return SquareRule(int(n), pts, wts)
