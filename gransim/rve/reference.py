"""Independent brute-force Taylor homogenization (plain numpy, all periodic image pairs).

Shares nothing with :mod:`gransim.rve.taylor` but the equations: no neighbour list, no
candidate cache, no numba, no :mod:`gransim.contacts.law` (the law of eqs 3-5 is written
out again here). It scans every pair (i, j) and every image shift n within a box that
provably contains all contacts of the *deformed* cell, so it checks the cell list, the
skin rule and the kernel at once. Cost O(N^2 K^2): for tests and acceptance checks only.
"""

from __future__ import annotations

import numpy as np

from ..geometry import Packing
from .taylor import TaylorMaterial


def homogenize_bruteforce(packing: Packing, F, normal_stiffness: float) -> dict:
    """W, P, A, sigma, n_contacts by summing over all pairs and images (eqs 3-12).

    Returns a dict with keys ``energy``, ``piola``, ``tangent``, ``cauchy``, ``n_contacts``.
    """
    F = np.asarray(F, dtype=float)
    kn = float(normal_stiffness)
    C = np.asarray(packing.cell, dtype=float)
    r = np.asarray(packing.radii, dtype=float)
    # wrap the reference positions into the unit square of fractional coordinates
    s = np.linalg.solve(C, np.asarray(packing.positions, dtype=float).T).T
    s = s - np.floor(s)
    X = s @ C.T
    Cd = F @ C
    area_d = abs(np.linalg.det(Cd))
    heights = np.array([area_d / np.linalg.norm(Cd[:, 1]), area_d / np.linalg.norm(Cd[:, 0])])
    # |F C (ds + n)| < 2 r_max needs |ds_k + n_k| < x_k = 2 r_max / h_k with |ds_k| < 1, so
    # |n_k| < 1 + x_k, i.e. |n_k| <= ceil(x_k)
    K = np.ceil(2.0 * r.max() / heights).astype(int)
    N = r.size
    W = 0.0
    P = np.zeros((2, 2))
    A = np.zeros((2, 2, 2, 2))
    count = 0
    I2 = np.eye(2)
    iu, ju = np.triu_indices(N, k=0)
    dX = X[ju] - X[iu]
    cij = r[iu] + r[ju]
    c2 = cij * cij
    lX = dX @ F.T  # F (X_j - X_i); an image adds F C n
    lx, ly = np.ascontiguousarray(lX[:, 0]), np.ascontiguousarray(lX[:, 1])
    distinct = iu < ju
    for n1 in range(-K[0], K[0] + 1):
        for n2 in range(-K[1], K[1] + 1):
            self_ok = n1 > 0 or (n1 == 0 and n2 > 0)
            off = C @ np.array([n1, n2], float)
            o = F @ off
            ex, ey = lx + o[0], ly + o[1]
            hit = ex * ex + ey * ey < c2 * (1.0 + 1e-9)  # loose pre-filter; exact test below
            if not self_ok:
                hit &= distinct
            if not np.any(hit):
                continue
            L = dX[hit] + off
            l = L @ F.T
            d = np.sqrt(np.sum(l * l, axis=1))
            c = cij[hit]
            keep = d < c  # the same test on the exact branch, as the definition of a contact
            L, l, d, c = L[keep], l[keep], d[keep], c[keep]
            eps = c - d
            n = l / d[:, None]
            count += int(keep.sum())
            W += np.sum(0.5 * kn * eps**2)
            P += np.einsum("m,mi,mJ->iJ", -kn * eps, n, L)
            a = kn * c / d  # material part of eq (12)
            b = -kn * eps / d  # geometric part of eq (12)
            A += np.einsum("m,mi,mk,mJ,mL->iJkL", a, n, n, L, L)
            A += np.einsum("m,ik,mJ,mL->iJkL", b, I2, L, L)
    V = float(np.linalg.det(C))
    W, P, A = W / V, P / V, A / V
    return {
        "energy": W,
        "piola": P,
        "tangent": A,
        "cauchy": P @ F.T / np.linalg.det(F),
        "n_contacts": count,
    }


def crosscheck(packings, normal_stiffness: float, deformations=None, seed: int = 0) -> list[dict]:
    """Compare the numba path with the brute force on every packing and several F.

    ``deformations``: (K, 2, 2) array; default: identity, 5% compression 11 and 22, 5% simple
    shear 12 and 21 and three random F with |F - I| up to 0.1 (seeded). Returns one record per
    (packing, F): relative differences of W, P, A (max-norm relative to the brute force's
    max-norm) and whether the contact counts agree.
    """
    if isinstance(packings, Packing):
        packings = {"rve": packings}
    if deformations is None:
        rng = np.random.default_rng(seed)
        base = [
            np.eye(2),
            np.diag([0.95, 1.0]),
            np.diag([1.0, 0.95]),
            np.array([[1, 0.05], [0, 1.0]]),
            np.array([[1, 0], [0.05, 1.0]]),
        ]
        base += [np.eye(2) + 0.1 * rng.uniform(-1, 1, (2, 2)) for _ in range(3)]
        deformations = np.array(base)
    out = []
    for name, p in packings.items():
        mat = TaylorMaterial(p, normal_stiffness)
        got = mat.evaluate(deformations)
        for k, F in enumerate(deformations):
            ref = homogenize_bruteforce(p, F, normal_stiffness)
            rec = {
                "rve": name,
                "F": np.asarray(F).tolist(),
                "n_contacts": ref["n_contacts"],
                "contacts_equal": int(got.n_contacts[k]) == ref["n_contacts"],
            }
            for key, field in (("energy", "energy"), ("piola", "piola"), ("tangent", "tangent")):
                a = np.asarray(getattr(got, field)[k])
                b = np.asarray(ref[key])
                scale = np.max(np.abs(b))
                rec[f"rel_{key}"] = float(np.max(np.abs(a - b)) / scale) if scale > 0 else float(np.max(np.abs(a)))
            out.append(rec)
    return out
