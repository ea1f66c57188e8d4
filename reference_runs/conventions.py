"""Units and sign conventions shared by every LIGGGHTS reference run (stated once, used everywhere).

Units
-----
LIGGGHTS runs with ``units si`` and ``dimension 2``: lengths in m, forces in N, stiffnesses
kn, kt in N/m (force per overlap, F = kn delta), masses in kg with the data file's density
column read as mass per area (kg/m^2, m = pi r^2 rho). "Volumes" are areas (m^2) and
stresses are force per length (N/m), as in gransim.

Stress sign
-----------
**gransim: tension positive.** The Cauchy stress of a set of contacts in a cell of area A is

    sigma = (1/A) sum_c f_c (x) l_c,

with l_c = x_j - x_i the branch vector from i to j and f_c the force that j exerts on i
(Meier, Steinmann & Kuhl, "Towards completeness, a multiscale approach of confined particulate systems"
(2007), eqs 2 and 10: P = (1/V) sum f_ij (x) L_ij, sigma = P F^T / det F).
A repulsive contact has f_c antiparallel to l_c, so compression is negative.

**LIGGGHTS: compression positive.** ``compute pressure <temp> virial`` reports
p_ab = (1/A) sum_c (x_i - x_j)_a f_b, the same sum with the branch vector reversed, so

    sigma_gransim = -p_liggghts        (component by component: xx = [1], yy = [2], xy = [4]).

``compute stress/atom`` returns minus the per-atom virial, so its sum over atoms equals
-p A = sigma A (already tension positive): sigma_gransim = (sum of stress/atom) / A.

Use only the helpers below to convert; never flip signs by hand elsewhere.
"""

from __future__ import annotations

import numpy as np

#: sigma_gransim = PRESSURE_SIGN * p_liggghts (component-wise)
PRESSURE_SIGN = -1.0


def _tensor(xx, yy, xy) -> np.ndarray:
    xx, yy, xy = np.broadcast_arrays(np.asarray(xx, float), np.asarray(yy, float), np.asarray(xy, float))
    out = np.empty(xx.shape + (2, 2))
    out[..., 0, 0] = xx
    out[..., 1, 1] = yy
    out[..., 0, 1] = xy
    out[..., 1, 0] = xy
    return out


def cauchy_from_pressure(pxx, pyy, pxy) -> np.ndarray:
    """gransim Cauchy stress (tension positive, N/m) from LIGGGHTS ``compute pressure`` components.

    Parameters
    ----------
    pxx, pyy, pxy : scalars or arrays (T,) of ``c_p[1]``, ``c_p[2]``, ``c_p[4]`` (N/m, compression
        positive).

    Returns
    -------
    (..., 2, 2) symmetric tensor sigma = -p.
    """
    return PRESSURE_SIGN * _tensor(pxx, pyy, pxy)


def cauchy_from_stress_atom_sum(sxx, syy, sxy, area) -> np.ndarray:
    """gransim Cauchy stress from sums of ``compute stress/atom`` over a group (N m, tension positive).

    sigma = (sum_i s_i) / A with A the area of the periodic cell (m^2). Returns (..., 2, 2).
    """
    area = np.asarray(area, float)
    if np.any(~np.isfinite(area)) or np.any(area <= 0):
        raise ValueError("area must be finite and > 0")
    return _tensor(sxx, syy, sxy) / area[..., None, None]


def pressure_from_cauchy(sigma) -> np.ndarray:
    """Inverse of :func:`cauchy_from_pressure`: (..., 2, 2) -> (..., 3) as (pxx, pyy, pxy)."""
    s = np.asarray(sigma, float)
    return PRESSURE_SIGN * np.stack([s[..., 0, 0], s[..., 1, 1], s[..., 0, 1]], axis=-1)


__all__ = ["PRESSURE_SIGN", "cauchy_from_pressure", "cauchy_from_stress_atom_sum", "pressure_from_cauchy"]
