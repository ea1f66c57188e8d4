"""The elastic normal contact of Meier, Steinmann & Kuhl, eqs (3)-(5), as scalar jitted functions.

These are the single source of the normal law: the Taylor RVE (gransim.rve) and the
DEM (gransim.dem, whose Hooke normal spring, LIGGGHTS' ``hooke/stiffness`` or LAMMPS'
``gran/hooke/history``, is the same law plus damping) call them inside their loops.

Symbols: r_i, r_j radii (m); dist = |l_ij| centre distance (m); eps = r_i + r_j - dist
overlap (m), positive in contact; kn = E_n normal stiffness (N/m).
"""

from __future__ import annotations

from .._numba import njit


@njit(inline="always")
def overlap(ri, rj, dist):
    """eps_ij = r_i + r_j - |l_ij| (m), eq (3)."""
    return ri + rj - dist


@njit(inline="always")
def potential(eps, kn):
    """Phi = E_n/2 [H(eps) eps]^2 (J), eq (4)."""
    if eps > 0.0:
        return 0.5 * kn * eps * eps
    return 0.0


@njit(inline="always")
def force_magnitude(eps, kn):
    """dPhi/deps = E_n H(eps) eps (N): the repulsive normal force magnitude, eq (5).

    The force on particle i is f_ij = -force_magnitude * n_ij with n_ij = l_ij/|l_ij|
    pointing from i to j.
    """
    if eps > 0.0:
        return kn * eps
    return 0.0


@njit(inline="always")
def stiffness(eps, kn):
    """d^2 Phi/deps^2 = E_n H(eps) (N/m)."""
    if eps > 0.0:
        return kn
    return 0.0
