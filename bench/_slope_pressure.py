"""The RVE's stress scale against the slope's in-situ stresses (docs/slope.md).

Prints, for a packing (default: the standard default RVE of the slope), its mean overlap strain and
Taylor pressure p = -tr P(F = 1) / 2 (N/m = Pa at unit thickness, gransim.paper), p / (kn <eps>/c),
and the mean pressure and Mohr shear of the slope's linear dead-load stress
sigma = P(1) + A(1) : (F - 1) with that Taylor RVE at every Gauss point (percentiles over the 1520
Gauss points), plus the geostatic rho g (H - y) at the Gauss points.

    PYTHONPATH=. python bench/_slope_pressure.py [PACKING.h5 ...]
"""

from __future__ import annotations

import sys

import numpy as np
import scipy.sparse.linalg as spla

from gransim.fem.materials import RVEMaterial
from gransim.fem.slope import NORMAL_STIFFNESS, setup_for, slope_problem
from gransim.fem.stability import _Uniform, mean_overlap_strain
from gransim.io import load_packing
from gransim.rve import TaylorMaterial


def main(paths):
    if not paths:
        from gransim.fem.run import default_rve_packing  # noqa: PLC0415

        packs = {"default (most uniform rve-700)": default_rve_packing("/tmp/hs3/packings")}
    else:
        packs = {p: load_packing(p) for p in paths}
    for name, pk in packs.items():
        eps = mean_overlap_strain(pk)
        mat = RVEMaterial(TaylorMaterial(pk, NORMAL_STIFFNESS))
        P0 = mat.evaluate(np.eye(2)[None]).piola[0]
        p = -0.5 * np.trace(P0)
        setup = setup_for("service")
        prob = slope_problem(_Uniform(mat), setup)
        r, K, *_ = prob.evaluate(np.zeros(prob.dofs.n_reduced), (1.0, 0.0))
        q = -spla.spsolve(K, r)
        u = prob.dofs.displacement(q)
        F = prob.geometry.deformation_gradient(u)
        A = mat.evaluate(np.eye(2)[None]).tangent[0]
        S = P0[None] + np.einsum("iJkL,gkL->giJ", A, F - np.eye(2))
        pm = -0.5 * (S[:, 0, 0] + S[:, 1, 1])
        tau = np.sqrt(0.25 * (S[:, 0, 0] - S[:, 1, 1]) ** 2 + 0.25 * (S[:, 0, 1] + S[:, 1, 0]) ** 2)
        y = prob.geometry.points.reshape(-1, 2)[:, 1]
        x = prob.geometry.points.reshape(-1, 2)[:, 0]
        surf = setup.geometry.surface(x)
        geo = setup.density * setup.gravity * (surf - y)
        q5 = [5, 25, 50, 75, 95, 100]
        print(
            f"{name}: N = {pk.radii.size}, mean overlap strain {eps:.3e}, Taylor p(F=1) = {p:.4e} Pa, "
            f"p / (kn eps) = {p / (NORMAL_STIFFNESS * eps):.3f}"
        )
        print("  percentiles      " + " ".join(f"{v:>9d}" for v in q5))
        print("  in-situ p (Pa)   " + " ".join(f"{v:9.3e}" for v in np.percentile(pm, q5)))
        print("  in-situ tau (Pa) " + " ".join(f"{v:9.3e}" for v in np.percentile(tau, q5)))
        print("  rho g depth (Pa) " + " ".join(f"{v:9.3e}" for v in np.percentile(geo, q5)))
        print("  tau / p in-situ  " + " ".join(f"{v:9.3e}" for v in np.percentile(tau / np.maximum(pm, 1e-300), q5)))


if __name__ == "__main__":
    main(sys.argv[1:])
