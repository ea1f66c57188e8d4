"""Deformation measures of the void cells (Kuhn 002, eqs 3, 7, 18-21).

All functions take plain arrays. With velocities (m/s) the gradients are velocity gradients
(1/s); with displacement increments (m) they are displacement-gradient increments
(dimensionless). Index convention: ``L[..., p, q] = dv_p / dx_q``.
"""

from __future__ import annotations

import numpy as np

from .._numba import pjit, prange
from ..errors import InputError
from .qmatrix import q_matrix, q_separations


def edge_normals(vec: np.ndarray) -> np.ndarray:
    """b = outward normal times length of counter-clockwise edges ``vec`` (..., 2): (e_y, -e_x)."""
    return np.stack([vec[..., 1], -vec[..., 0]], axis=-1)


def polygon_gradient(vertices: np.ndarray, velocities: np.ndarray) -> np.ndarray:
    """Average velocity gradient of one polygon by eq (7), (2, 2).

    Parameters
    ----------
    vertices : (m, 2) counter-clockwise vertex positions (m)
    velocities : (m, 2) vertex velocities (m/s)

    Returns
    -------
    L_pq = 1/(6A) sum_{j1,j2} Q^m_{j1 j2} (v^{j1+1} - v^{j1})_p b^{j2}_q, with b^j the outward
    normal of edge j (vertex j to j+1) scaled by its length and A the (shoelace) area.
    """
    x = np.asarray(vertices, float)
    v = np.asarray(velocities, float)
    e = np.roll(x, -1, axis=0) - x
    A = 0.5 * np.sum(x[:, 0] * e[:, 1] - x[:, 1] * e[:, 0])
    vh = np.roll(v, -1, axis=0) - v
    return np.einsum("jk,jp,kq->pq", q_matrix(len(x)), vh, edge_normals(e)) / (6.0 * A)


@pjit
def _face_gradients(ptr, fh, vec, dv, area, qtab):
    nf = ptr.shape[0] - 1
    L = np.zeros((nf, 2, 2))
    for f in prange(nf):
        p0 = ptr[f]
        m = ptr[f + 1] - p0
        s00 = 0.0
        s01 = 0.0
        s10 = 0.0
        s11 = 0.0
        for j1 in range(m):
            h1 = fh[p0 + j1]
            # Qb = sum_j2 Q^m(j2 - j1) b^{j2}, b = (e_y, -e_x)
            qb0 = 0.0
            qb1 = 0.0
            for j2 in range(m):
                d = j2 - j1
                if d < 0:
                    d += m
                q = qtab[m, d]
                h2 = fh[p0 + j2]
                qb0 += q * vec[h2, 1]
                qb1 -= q * vec[h2, 0]
            s00 += dv[h1, 0] * qb0
            s01 += dv[h1, 0] * qb1
            s10 += dv[h1, 1] * qb0
            s11 += dv[h1, 1] * qb1
        c = 1.0 / (6.0 * area[f])
        L[f, 0, 0] = s00 * c
        L[f, 0, 1] = s01 * c
        L[f, 1, 0] = s10 * c
        L[f, 1, 1] = s11 * c
    return L


def q_table(max_m: int) -> np.ndarray:
    """Rows Q^m(d) of :func:`q_separations` for m = 0..max_m, zero-padded, (max_m + 1, max_m)."""
    tab = np.zeros((max_m + 1, max(max_m, 1)))
    for m in range(2, max_m + 1):
        tab[m, :m] = q_separations(m)
    return tab


def face_gradients(face_ptr, face_halfedges, vec, dv, area) -> np.ndarray:
    """Eq (7) for every face of a DCEL, (F, 2, 2). O(sum m^2) in one compiled loop.

    Parameters
    ----------
    face_ptr : (F + 1,), face_halfedges : (H,)
        Half-edges of each face in counter-clockwise order (DCEL).
    vec : (H, 2)
        Lifted half-edge vectors (m).
    dv : (H, 2)
        Relative velocity of each half-edge, v_hat = v_head - v_tail (eq 5), image motion
        included (m/s).
    area : (F,)
        Face areas (m^2).
    """
    max_m = int(np.diff(face_ptr).max()) if face_ptr.shape[0] > 1 else 2
    return _face_gradients(
        np.ascontiguousarray(face_ptr),
        np.ascontiguousarray(face_halfedges),
        np.ascontiguousarray(vec, dtype=np.float64),
        np.ascontiguousarray(dv, dtype=np.float64),
        np.ascontiguousarray(area, dtype=np.float64),
        q_table(max(max_m, 2)),
    )


@pjit
def _halfedge_velocities(origin, dest, shift, v, Cd):
    H = origin.shape[0]
    dv = np.empty((H, 2))
    for h in prange(H):
        o = origin[h]
        d = dest[h]
        s0 = shift[h, 0]
        s1 = shift[h, 1]
        dv[h, 0] = (v[d, 0] - v[o, 0]) + (s0 * Cd[0, 0] + s1 * Cd[0, 1])
        dv[h, 1] = (v[d, 1] - v[o, 1]) + (s0 * Cd[1, 0] + s1 * Cd[1, 1])
    return dv


def halfedge_velocities(origin, dest, shift, velocities, cell_velocity) -> np.ndarray:
    """Relative velocity of every half-edge, eq (5): v_hat = v_dest + (dC/dt) n_h - v_origin, (H, 2)
    (m/s); the head's periodic image x_dest + C n_h moves with v_dest + (dC/dt) n_h.

    Parameters
    ----------
    origin, dest : (H,) int, shift : (H, 2) int (DCEL); velocities : (N, 2) m/s;
    cell_velocity : (2, 2) dC/dt, lattice-vector velocities as columns (m/s).
    """
    return _halfedge_velocities(
        np.ascontiguousarray(origin),
        np.ascontiguousarray(dest),
        np.ascontiguousarray(shift),
        np.ascontiguousarray(velocities, np.float64),
        np.ascontiguousarray(cell_velocity, np.float64),
    )


def assembly_average(L: np.ndarray, area: np.ndarray) -> np.ndarray:
    """Area-weighted mean of the face gradients, eq (3): (1/A) sum_i A^i L^i, (2, 2)."""
    return np.einsum("f,fpq->pq", area, L) / area.sum()


def alignment(L: np.ndarray, Lbar: np.ndarray) -> np.ndarray:
    """Alignment alpha = L^i : Lbar / (|L^i| |Lbar|), eqs (18)-(19), (F,). NaN where |L^i| = 0."""
    num = np.einsum("fpq,pq->f", L, Lbar)
    den = np.sqrt(np.einsum("fpq,fpq->f", L, L)) * np.sqrt(np.sum(Lbar * Lbar))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / np.where(den > 0, den, 1.0), np.nan)


def normalised_vorticity(L: np.ndarray, Lbar: np.ndarray) -> np.ndarray:
    """w = -(L^i_12 - L^i_21) / |Lbar|, eq (20), (F,). Positive = counter-clockwise rotation."""
    return -(L[:, 0, 1] - L[:, 1, 0]) / np.sqrt(np.sum(Lbar * Lbar))


#: eq (21) is undefined when |Lbar_22| <= RELATIVE_MOTION_RTOL |Lbar| (:func:`relative_motion_undefined`)
RELATIVE_MOTION_RTOL = 1e-8


def relative_motion_undefined(Lbar: np.ndarray) -> str | None:
    """Why eq (21) has no value for the mean gradient ``Lbar`` (2, 2), or None when it has one.

    Eq (21) scales the non-affine velocity by D50 |Lbar_22|, the loading rate of Kuhn's biaxial
    test. A loading that imposes no L_22 leaves only round-off there: simple shear at constant
    volume gives, for the area-weighted mean of the cells (eq 3), |Lbar_22| / |Lbar| up to 2e-16
    (120 disks, `gransim shear --strain 0.004 --rate 5`) and 4.6e-17 (the 1002-disk Kuhn packing,
    58 snapshots to gamma = 0.002), and exactly 0 for the cell's own gradient: the "relative
    motion" would be the velocity fluctuations times 1e16 (about 1e17 printed). The measure is
    undefined when |Lbar_22| <= RELATIVE_MOTION_RTOL |Lbar| (|.| the norm of eq 19): 1e-8 is
    eight decades above that round-off, and a genuine |Lbar_22| below it would make eq (21) at
    least 1e8 times the same fluctuations measured against |Lbar| (a statement about the
    loading, not about the particles). |Lbar| = 0 (no deformation) is undefined too.

    Returns "undefined (mean L_22 = ... against |L| = ...)" or None.
    """
    Lbar = np.asarray(Lbar, float)
    norm = float(np.sqrt(np.sum(Lbar * Lbar)))
    l22 = float(Lbar[1, 1])
    if abs(l22) > RELATIVE_MOTION_RTOL * norm:
        return None
    return f"undefined (mean L_22 = {l22:.3g} against |L| = {norm:.3g})"


def relative_motion(positions: np.ndarray, velocities: np.ndarray, Lbar: np.ndarray, d50: float) -> np.ndarray:
    """Non-dimensional relative particle motion, eq (21), (N, 2).

    v_rel^k = (v^k - Lbar x^k - c) / (D50 |Lbar_22|). The constant c is the mean of v - Lbar x over
    the particles: in a periodic cell the rigid translation of the assembly is arbitrary (it
    depends on where the origin is), so it is removed; eq (21) has c = 0 for a cell whose centre
    does not move. Call it only when :func:`relative_motion_undefined` returns None (InputError
    otherwise).
    """
    why = relative_motion_undefined(Lbar)
    if why is not None:
        raise InputError(f"relative motion (eq 21): {why}")
    x = positions
    w = np.empty_like(velocities)
    w[:, 0] = velocities[:, 0] - (Lbar[0, 0] * x[:, 0] + Lbar[0, 1] * x[:, 1])
    w[:, 1] = velocities[:, 1] - (Lbar[1, 0] * x[:, 0] + Lbar[1, 1] * x[:, 1])
    w -= w.mean(axis=0)
    return w / (d50 * abs(Lbar[1, 1]))


def d50_area_weighted(radii: np.ndarray) -> float:
    """Area-weighted median diameter (the 2D weight-median D50), as ``Packing.d50``."""
    d = np.sort(2.0 * np.asarray(radii, float))
    w = np.cumsum(d**2)
    return float(d[np.searchsorted(w, 0.5 * w[-1])])
