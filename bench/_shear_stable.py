"""Relaxed shear stiffness of RVEs jammed with a square cell (cell="scale") and over the cell shape
(cell="shape"), same seeds and target (docs/generation.md, "Shear-stabilised packings").

For each N and seed, the request of the standard RVEs (quartz-sand, mean overlap 2.7e-4 d_mean,
:mod:`gransim.generation.standard`) is made in four variants: cell "scale" at force_tol 1e-3 (the
standard RVE itself: asserted equal to the shipped file bit for bit) and 1e-5, cell "shape" at
1e-3 and at its default 1e-5. Columns:

* sxy/p, dsig/p: shear stress sigma_xy / p and (sigma_xx - sigma_yy) / p of the packing (contact
  virial, an independent numpy sum, p = tr sigma / 2);
* mu relaxed, mu Taylor: D:A:D (N/m), D = sym(e1 x e2), by
  :func:`gransim.fem.stability.rve_shear_stiffness` (tangent checked against the energy's second
  difference: column "2nd diff" is |second difference - mu| / |mu| of the relaxed RVE, which is
  large where the relaxed minimiser jumps to another basin at F = 1 +- 1e-6 D), and their ratio;
* mu_min/p: the smallest eigenvalue of the relaxed tangent on the deviatoric plane span(D, D2),
  D2 = (e1 x e1 - e2 x e2)/2 (the softest shear direction at fixed volume), over the RVE pressure.
  A minimum of the enthalpy over centres and cell has mu_min >= p/2 (tests/generation/
  test_cell_shape.py derives it); mu_min < 0 is a relaxed RVE unstable to some shear;
* K0 neg, shear: the slope's reduced FE tangent K(0) with this relaxed RVE at every Gauss point
  (:func:`gransim.fem.stability.reference_stability`, service protocol): its number of negative
  eigenvalues, and the largest shear strain (Mohr radius) of the linear dead-load solution.

Usage: ``PYTHONPATH=. python bench/_shear_stable.py [--n 70 350 700] [--seeds 1 2 3 4 5]``
(about 15 s on one core after compilation; the first run compiles for a minute).
"""

import argparse

import numpy as np

from gransim.contacts import find_neighbours
from gransim.fem.slope import NORMAL_STIFFNESS
from gransim.fem.stability import SHEAR, reference_stability, rve_shear_stiffness
from gransim.generation import STANDARD_PACKINGS, make_packing, shipped_packing
from gransim.generation.standard import RVE_MEAN_OVERLAP
from gransim.io import load_packing
from gransim.rve import RelaxedMaterial

D2 = np.array([[0.5, 0.0], [0.0, -0.5]])
VARIANTS = (("scale", 1e-3), ("scale", 1e-5), ("shape", 1e-3), ("shape", 1e-5))


def residual_shear(p) -> tuple[float, float]:
    """(sigma_xy / p, (sigma_xx - sigma_yy) / p) of the contact virial (compression positive)."""
    nl = find_neighbours(p.positions, p.radii, p.cell, 0.0)
    eps = nl.overlaps(p.radii)
    s = np.einsum("c,ci,cj->ij", eps / nl.distance, nl.branch, nl.branch) / p.area
    pr = 0.5 * np.trace(s)
    return float(s[0, 1] / pr), float((s[0, 0] - s[1, 1]) / pr)


def deviatoric_min(A) -> float:
    """Smallest eigenvalue of D_a:A:D_b on span(D, D2) (N/m); |D|^2 = |D2|^2 = 1/2, as mu's D."""
    B = [SHEAR, D2]
    M = np.array([[np.einsum("ij,ijkl,kl", a, A, b) for b in B] for a in B])
    return float(np.linalg.eigvalsh(0.5 * (M + M.T))[0])


def main(ns, seeds) -> None:
    head = (
        "| N | seed | cell | force_tol | sxy/p | dsig/p | mu relaxed (N/m) | 2nd diff | mu Taylor (N/m) | ratio "
        "| mu_min/p | K0 neg | shear |"
    )
    print(head)
    print("|---" * 13 + "|")
    rows = []
    for n in ns:
        for seed in seeds:
            for cell, tol in VARIANTS:
                p = make_packing("quartz-sand", n, seed, mean_overlap=RVE_MEAN_OVERLAP, cell=cell, force_tol=tol)
                name = f"rve-{n}-{seed}"
                if (cell, tol) == ("scale", 1e-3) and name in STANDARD_PACKINGS:  # the standard RVE itself
                    ref = load_packing(shipped_packing(name))
                    assert all(np.array_equal(getattr(p, a), getattr(ref, a)) for a in ("positions", "radii", "cell"))
                rel = rve_shear_stiffness(p, "relaxed")
                tay = rve_shear_stiffness(p, "taylor")
                r0 = RelaxedMaterial(p, NORMAL_STIFFNESS)(np.eye(2))
                mumin = deviatoric_min(np.asarray(r0.tangent)) / rel["pressure"]
                sxy, sdev = residual_shear(p)
                mu, mt = rel["tangent"], tay["tangent"]
                k0 = reference_stability(p, "relaxed")
                rows.append((cell, tol, mu, mt, mumin, k0["n_negative"]))
                print(
                    f"| {n} | {seed} | {cell} | {tol:.0e} | {sxy:+.1e} | {sdev:+.1e} | {mu:.3e} | "
                    f"{rel['relative_difference']:.0e} | {mt:.3e} | {mu / mt:+.4f} | {mumin:+.1f} | "
                    f"{k0['n_negative']} | {k0['shear_max']:.3f} |",
                    flush=True,
                )
    print()
    for cell, tol in VARIANTS:
        sel = [r for r in rows if r[:2] == (cell, tol)]
        print(
            f"cell={cell} force_tol={tol:.0e}: mu < 0 in {sum(r[2] < 0 for r in sel)} of {len(sel)}, "
            f"mu_min < 0 in {sum(r[4] < 0 for r in sel)}, mu_min < p/2 in {sum(r[4] < 0.5 for r in sel)}, "
            f"K(0) indefinite in {sum(r[5] > 0 for r in sel)}; "
            f"median mu/mu_Taylor = {np.median([r[2] / r[3] for r in sel]):.4f}"
        )


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, nargs="+", default=[70, 350, 700])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5])
    a = ap.parse_args()
    main(a.n, a.seeds)
