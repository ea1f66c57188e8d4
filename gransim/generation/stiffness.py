"""Second derivatives of the packing enthalpy H = U + P A: the stiffness matrix and the Newton step.

The potential is that of :mod:`.fire`: U = sum_c Phi(eps_c), Phi = k_n/2 [H(eps) eps]^2 (eqs 3-4 of
Meier, Steinmann & Kuhl, "Towards completeness, a multiscale approach of confined particulate
systems"), in reduced units (k_n = 1, lengths in mean diameters), over the disk centres x (N, 2) and
the scale L of a square periodic cell, A = L^2. A contact c = (i, j, n) has the branch vector
l_c = x_j + L n - x_i, length d_c, normal n_c = l_c / d_c and overlap eps_c = r_i + r_j - d_c.

* Gradient: dH/dx_i = sum_c (+-) eps_c n_c (+ for i, - for j): minus the net contact force.
* Pair stiffness (the Hessian of Phi in l_c): K_c = n_c n_c^T - (eps_c / d_c)(I - n_c n_c^T), the
  elastic term and the (destabilising) geometric term of a compressed contact.
* Positions block: K = sum_c B_c^T K_c B_c (B_c: l_c = x_j - x_i + L n), shape (2N, 2N), symmetric;
  its null space holds the two rigid translations and the free motions of the rattlers.
* The cell enters through the affine mode lambda: x -> (1 + lambda) x, L -> (1 + lambda) L, which
  scales every l_c by (1 + lambda). Then dH/dlambda = -(sum_c eps_c d_c - 2 P A) (virial minus
  imposed pressure, as the cell force of :mod:`.fire`), the coupling d^2H/dx_i dlambda =
  sum_c (-+) d_c n_c (K_c l_c = d_c n_c), and d^2H/dlambda^2 = sum_c d_c^2 + 2 P A.

The Newton step on (x, lambda) solves the bordered system [[K, c], [c^T, h]] [dx; lambda] = -[g; g_l]
by the Schur complement on the cell mode: two solves with K (one factorisation).

Measured use (docs/generation.md, "Newton and the last pass"; ``python -m bench --only generation``):
the exact stationary point of the current contact network is not where the FIRE criterion stops.
From a 1000-disk packing that meets the default criterion (largest residual 9.6e-4 of the mean
contact force), the Newton step on the backbone moves disks by a median of 1.3e-3 mean diameters
(4.8 mean overlaps, largest 5.6e-3) and has closed 5 new contacts at 1 % of its length: the soft
modes of a jammed packing (lowest non-zero eigenvalue of the backbone stiffness 2.4e-5 k_n) turn a
residual force of 1e-3 <f> into a position error of ~1e-2 d_mean. So Newton does not replace the
last FIRE pass; this module is kept for the stability analysis of packings and the tests of that
finding.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from ..contacts import find_neighbours
from .stats import rattlers


@dataclass(frozen=True)
class EnthalpyDerivatives:
    """First and second derivatives of H = U + P A at one state (reduced units, k_n = 1).

    ``K`` (2N, 2N) CSR positions block; ``coupling`` (2N,) d^2H/dx dlambda; ``h`` d^2H/dlambda^2;
    ``gradient`` (2N,) dH/dx (minus the net forces, disk-major: x0, y0, x1, ...); ``cell_gradient``
    dH/dlambda; ``i``, ``j`` (M,) and ``shift`` (M, 2) the pairs used; ``energy`` H.
    """

    K: sp.csr_matrix
    coupling: np.ndarray
    h: float
    gradient: np.ndarray
    cell_gradient: float
    i: np.ndarray
    j: np.ndarray
    shift: np.ndarray
    energy: float


def contact_pairs(x, r, L) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The overlapping pairs (i, j, image shift) of disks x (N, 2), r (N,) in the square cell L."""
    nl = find_neighbours(x, r, L * np.eye(2), 0.0)
    c = nl.overlaps(r) > 0
    return nl.i[c], nl.j[c], nl.shift[c]


def enthalpy_derivatives(x, r, L: float, P: float, pairs=None) -> EnthalpyDerivatives:
    """Gradient and Hessian of H = U + P L^2 over centres and the affine cell mode (module docstring).

    Parameters
    ----------
    x : (N, 2) centres, r : (N,) radii, L : cell side (mean diameters), P : imposed pressure (k_n).
    pairs : (i, j, shift), optional
        The pairs to sum over. Default: the overlapping pairs (the contacts of eq 3). Given pairs are
        treated as harmonic springs of rest length r_i + r_j that also pull (a frozen network), which
        makes H smooth: the tests use it to check Newton's order of convergence.
    """
    x = np.asarray(x, dtype=float)
    r = np.asarray(r, dtype=float)
    n = x.shape[0]
    i, j, shift = contact_pairs(x, r, L) if pairs is None else pairs
    l = x[j] - x[i] + L * shift
    d = np.sqrt(np.einsum("ca,ca->c", l, l))
    eps = r[i] + r[j] - d
    nrm = l / d[:, None]
    s = eps / d
    Kc = np.einsum("ca,cb->cab", nrm, nrm) * (1.0 + s)[:, None, None] - s[:, None, None] * np.eye(2)[None]
    rows, cols, vals = [], [], []
    for a in range(2):
        for b in range(2):
            for p, q, sign in ((i, i, 1.0), (j, j, 1.0), (i, j, -1.0), (j, i, -1.0)):
                rows.append(2 * p + a)
                cols.append(2 * q + b)
                vals.append(sign * Kc[:, a, b])
    K = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(2 * n, 2 * n))
    g = np.zeros((n, 2))
    np.add.at(g, i, eps[:, None] * nrm)
    np.add.at(g, j, -eps[:, None] * nrm)
    c = np.zeros((n, 2))
    np.add.at(c, i, -d[:, None] * nrm)
    np.add.at(c, j, d[:, None] * nrm)
    A = L * L
    return EnthalpyDerivatives(
        K=K,
        coupling=c.ravel(),
        h=float(np.sum(d * d) + 2.0 * P * A),
        gradient=g.ravel(),
        cell_gradient=float(-(np.sum(eps * d) - 2.0 * P * A)),
        i=i,
        j=j,
        shift=shift,
        energy=float(0.5 * np.sum(eps * eps) + P * A),
    )


def backbone(n: int, i, j) -> np.ndarray:
    """Boolean mask (N,) of the disks that are not rattlers (:func:`gransim.generation.rattlers`)."""
    return ~rattlers(n, np.asarray(i), np.asarray(j))


def newton_step(der: EnthalpyDerivatives, free=None, cell_free: bool = True) -> tuple[np.ndarray, float]:
    """The Newton step (dx (N, 2), lambda) of H for the disks ``free`` (mask (N,), default all).

    The other disks stay put. The translation gauge is fixed by holding the first free disk; with ``cell_free``
    False, lambda = 0 (fixed cell). Solved with one sparse LU factorisation (SuperLU, symmetric mode).
    The positions block restricted to ``free`` must be non-singular once the gauge is fixed: pass
    the backbone (:func:`backbone`) for a contact network with rattlers.
    """
    n2 = der.gradient.size
    free = np.ones(n2 // 2, dtype=bool) if free is None else np.asarray(free, dtype=bool)
    dof = np.flatnonzero(np.repeat(free, 2))[2:]  # gauge: the first free disk held
    K = der.K[dof][:, dof].tocsc()
    lu = spl.splu(K, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
    g = der.gradient[dof]
    a = lu.solve(g)
    lam = 0.0
    du = -a
    if cell_free:
        c = der.coupling[dof]
        b = lu.solve(c)
        lam = float((-der.cell_gradient + c @ a) / (der.h - c @ b))
        du = -(a + b * lam)
    dx = np.zeros(n2)
    dx[dof] = du
    return dx.reshape(-1, 2), lam
