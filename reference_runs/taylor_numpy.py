"""Taylor (affine) RVE stress in plain numpy, by brute force over periodic image pairs.

An implementation independent of gransim.rve (and of gransim's cell-list search) that the
LIGGGHTS Taylor states are checked against. For a periodic packing (reference centres X_i,
cell C with lattice vectors as columns, reference area V = det C) and a deformation
gradient F (Meier, Steinmann & Kuhl, "Towards completeness, a multiscale approach of confined particulate
systems" (2007), eqs 1-5 and 10):

    L_ij  = X_j + C n - X_i                       reference branch vector, n in {-1, 0, 1}^2
    l_ij  = F L_ij                                deformed branch vector (Taylor assumption, eq 1)
    eps   = r_i + r_j - |l_ij|                    overlap (eq 3), contact when eps > 0
    f_ij  = -E_n eps l_ij / |l_ij|                force on i from j (eq 5; repulsive)
    P     = (1/V) sum_c f_ij (x) L_ij             first Piola stress (eq 10), each contact once
    sigma = P F^T / det F = (1/(det F V)) sum_c f_ij (x) l_ij     Cauchy stress (tension +)

Units: m, N, E_n in N/m, stresses in N/m (2D). Shifts |n_k| <= 1 suffice when every cell
height exceeds the largest contact distance 2 r_max / s_min (s_min the smallest singular
value of F), which :func:`candidate_pairs` checks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gransim.errors import InputError
from gransim.geometry import Packing


@dataclass(frozen=True, eq=False)
class TaylorStress:
    """Result of :func:`taylor_stress_numpy`.

    Attributes
    ----------
    piola : (2, 2) first Piola stress P (N/m).
    cauchy : (2, 2) Cauchy stress from sum f (x) l / (det F V) (N/m, tension positive).
    cauchy_from_piola : (2, 2) P F^T / det F (equals ``cauchy`` to round-off).
    n_contacts : number of overlapping pairs (each periodic contact once).
    i, j : (M,) particle indices of the contacts; shift : (M, 2) image n; force : (M, 2) f_ij (on i);
    overlap : (M,) eps_ij (m); branch : (M, 2) l_ij (m).
    """

    piola: np.ndarray
    cauchy: np.ndarray
    cauchy_from_piola: np.ndarray
    n_contacts: int
    i: np.ndarray
    j: np.ndarray
    shift: np.ndarray
    force: np.ndarray
    overlap: np.ndarray
    branch: np.ndarray


@dataclass(frozen=True, eq=False)
class Candidates:
    """Pairs (i, j, n) that can touch for any F whose smallest singular value is >= s_min."""

    X: np.ndarray  # (N, 2) wrapped reference centres
    radii: np.ndarray  # (N,)
    cell: np.ndarray  # (2, 2)
    i: np.ndarray
    j: np.ndarray
    shift: np.ndarray  # (M, 2)
    L: np.ndarray  # (M, 2) reference branch vectors
    s_min: float


def _wrapped(packing: Packing) -> np.ndarray:
    C = packing.cell
    s = np.linalg.solve(C, packing.positions.T).T
    s -= np.floor(s)
    return s @ C.T


def candidate_pairs(packing: Packing, s_min: float = 0.5) -> Candidates:
    """All (i, j, n), i < j or i == j with n > 0, with |L_ij| < (r_i + r_j) / s_min.

    |F L| >= s_min |L|, so no pair outside this set touches under such an F. Brute force
    O(N^2) over the 9 shifts n in {-1, 0, 1}^2 (vectorised per shift).
    """
    if not 0 < s_min <= 1:
        raise InputError(f"s_min: expected 0 < s_min <= 1, got {s_min!r}")
    C = packing.cell
    X = _wrapped(packing)
    r = packing.radii
    A = abs(np.linalg.det(C))
    heights = A / np.linalg.norm(C, axis=0)[::-1]
    reach = 2 * r.max() / s_min
    if heights.min() <= reach:
        raise InputError(
            f"cell too small for the image search: height {heights.min():.4g} m <= "
            f"largest contact distance {reach:.4g} m"
        )
    n = len(r)
    iu, ju = np.triu_indices(n, k=0)
    I, J, S, Ls = [], [], [], []
    for n1 in (-1, 0, 1):
        for n2 in (-1, 0, 1):
            sh = np.array([n1, n2])
            if n1 == 0 and n2 == 0:
                ii, jj = np.triu_indices(n, k=1)
            elif (n1, n2) > (0, 0):
                ii, jj = iu, ju
            else:
                ii, jj = np.triu_indices(n, k=1)
            L = X[jj] + C @ sh - X[ii]
            d2 = np.einsum("ij,ij->i", L, L)
            keep = d2 < ((r[ii] + r[jj]) / s_min) ** 2
            I.append(ii[keep])
            J.append(jj[keep])
            Ls.append(L[keep])
            S.append(np.repeat(sh[None], keep.sum(), axis=0))
    return Candidates(
        X, r.copy(), C.copy(), np.concatenate(I), np.concatenate(J), np.concatenate(S), np.concatenate(Ls), float(s_min)
    )


def taylor_stress_numpy(packing: Packing, F, kn: float, candidates: Candidates | None = None) -> TaylorStress:
    """Taylor stress of ``packing`` under ``F`` with the normal elastic contact of stiffness ``kn``.

    Parameters
    ----------
    packing : the reference (undeformed) packing.
    F : (2, 2) deformation gradient, det F > 0.
    kn : E_n, normal stiffness (N/m), > 0.
    candidates : from :func:`candidate_pairs` (reused across many F); built when None.
    """
    F = np.asarray(F, float)
    if F.shape != (2, 2) or not np.all(np.isfinite(F)) or np.linalg.det(F) <= 0:
        raise InputError(f"F: expected a finite (2, 2) array with det F > 0, got {F.tolist()}")
    if not kn > 0:
        raise InputError(f"kn: must be > 0, got {kn!r}")
    s_min = float(np.linalg.svd(F, compute_uv=False).min())
    if candidates is None:
        candidates = candidate_pairs(packing, min(1.0, s_min))
    elif s_min < candidates.s_min:
        raise InputError(f"candidates built for s_min = {candidates.s_min}, F has {s_min}")
    c = candidates
    ell = c.L @ F.T
    dist = np.sqrt(np.einsum("ij,ij->i", ell, ell))
    eps = c.radii[c.i] + c.radii[c.j] - dist
    on = eps > 0
    ell, dist, eps, L = ell[on], dist[on], eps[on], c.L[on]
    f = -kn * eps[:, None] * ell / dist[:, None]
    V = abs(np.linalg.det(c.cell))
    J = np.linalg.det(F)
    P = f.T @ L / V
    sigma = f.T @ ell / (J * V)
    return TaylorStress(P, sigma, P @ F.T / J, int(on.sum()), c.i[on], c.j[on], c.shift[on], f, eps, ell)


__all__ = ["Candidates", "TaylorStress", "candidate_pairs", "taylor_stress_numpy"]
