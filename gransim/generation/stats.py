"""Statistics of a periodic disk packing: contacts, rattlers, coordination, overlaps, fabric.

Contacts are the pairs (with periodic image) with overlap eps = r_i + r_j - |l_ij| > 0 (eq 3 of
Meier, Steinmann & Kuhl, "Towards completeness, a multiscale approach of confined particulate
systems"). Rattlers are the disks with fewer than :data:`MIN_CONTACTS` contacts after iteratively
removing other rattlers (3 is the minimum for a frictionless disk in 2D: d + 1).
"""

from __future__ import annotations

import numpy as np

from ..contacts import find_neighbours
from ..errors import InputError
from ..geometry import Packing

#: minimum number of contacts of a non-rattler (frictionless disks in 2D: d + 1)
MIN_CONTACTS = 3


def contact_counts(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Contacts per disk (N,) from contact pairs (a contact with its own image counts twice)."""
    return np.bincount(i, minlength=n) + np.bincount(j, minlength=n)


def rattlers(n: int, i: np.ndarray, j: np.ndarray, min_contacts: int = MIN_CONTACTS) -> np.ndarray:
    """Boolean mask (N,) of rattlers: disks left with fewer than ``min_contacts`` contacts after
    repeatedly discarding rattlers and their contacts."""
    rat = np.zeros(n, dtype=bool)
    keep = np.ones(i.shape[0], dtype=bool)
    while True:
        z = contact_counts(n, i[keep], j[keep])
        new = (z < min_contacts) & ~rat
        if not new.any():
            return rat
        rat |= new
        keep &= ~(rat[i] | rat[j])


def packing_stats(packing: Packing) -> dict:
    """Geometry and contact statistics of a packing.

    Contacts are the pairs (with periodic image) with overlap eps = r_i + r_j - |l_ij| > 0 (eq 3 of
    Meier et al.). Returns a dict with

    ``n``, ``cell`` (2x2 list, m), ``area`` (m^2), ``solid_fraction`` phi (overlaps not subtracted),
    ``void_ratio`` e = (1 - phi)/phi, ``n_contacts``, ``coordination`` Z = 2 N_c / N,
    ``n_rattlers``, ``rattler_fraction``, ``coordination_nonrattler`` (2 N_c' / N' over the
    non-rattlers; Kuhn's "effective coordination number" 2M/N), ``mean_overlap``/``max_overlap``
    (m), the same relative to D50 (``*_d50``) and to the number-mean diameter (``*_dmean``),
    ``d50`` (area-weighted median, m), ``mean_diameter``, ``d_min``, ``d_max`` (m) and
    ``fabric_anisotropy`` a = 2 (lambda_1 - lambda_2) of the contact-normal fabric
    F = <n (x) n> (0 for an isotropic network).
    """
    if not isinstance(packing, Packing):
        raise InputError(f"packing: expected a gransim.Packing, got {type(packing).__name__}")
    nl = find_neighbours(packing.positions, packing.radii, packing.cell, 0.0)
    eps = nl.overlaps(packing.radii)
    c = eps > 0
    i, j, eps = nl.i[c], nl.j[c], eps[c]
    N = packing.n
    rat = rattlers(N, i, j)
    keep = ~(rat[i] | rat[j])
    n_nr = int(N - rat.sum())
    d = 2 * packing.radii
    d50 = packing.d50
    dmean = float(d.mean())
    mean_eps = float(eps.mean()) if eps.size else 0.0
    max_eps = float(eps.max()) if eps.size else 0.0
    if eps.size:
        nrm = nl.branch[c] / np.linalg.norm(nl.branch[c], axis=1)[:, None]
        lam = np.linalg.eigvalsh(nrm.T @ nrm / nrm.shape[0])
        aniso = float(2 * (lam[1] - lam[0]))
    else:
        aniso = 0.0
    phi = packing.solid_fraction
    return {
        "n": N,
        "cell": packing.cell.tolist(),
        "area": packing.area,
        "solid_fraction": phi,
        "void_ratio": (1 - phi) / phi,
        "n_contacts": int(eps.size),
        "coordination": 2 * eps.size / N,
        "n_rattlers": int(rat.sum()),
        "rattler_fraction": float(rat.mean()),
        "coordination_nonrattler": 2 * int(keep.sum()) / n_nr if n_nr else 0.0,
        "mean_overlap": mean_eps,
        "max_overlap": max_eps,
        "mean_overlap_d50": mean_eps / d50,
        "max_overlap_d50": max_eps / d50,
        "mean_overlap_dmean": mean_eps / dmean,
        "max_overlap_dmean": max_eps / dmean,
        "d50": d50,
        "mean_diameter": dmean,
        "d_min": float(d.min()),
        "d_max": float(d.max()),
        "fabric_anisotropy": aniso,
    }
