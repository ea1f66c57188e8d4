"""Stability of the slope's reference state with given RVE packings (docs/slope.md).

For each packing: mean overlap strain, Taylor pressure p = -tr P(1) / 2 (Pa at unit thickness),
mu = D:A:D relaxed and Taylor (``gransim.fem.stability.rve_shear_stiffness``), and per RVE kind the
slope's K(0) negative eigenvalues and the linear dead-load shear strains
(``reference_stability``), also relative to the overlap strain.

    PYTHONPATH=. python bench/_slope_rve_stability.py PACKING.h5 [...]
"""

from __future__ import annotations

import sys
import time

from gransim.fem.stability import mean_overlap_strain, reference_stability, rve_shear_stiffness
from gransim.io import load_packing


def main(paths):
    print(
        "| packing | overlap strain | p (Pa) | mu relaxed (N/m) | mu Taylor (N/m) | rel/Tay | rve | K(0) neg "
        "| max disp (m) | shear median | shear max | median/overlap | max/overlap | s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for path in paths:
        pk = load_packing(path)
        eps = mean_overlap_strain(pk)
        mr = rve_shear_stiffness(pk, "relaxed")
        mt = rve_shear_stiffness(pk, "taylor")
        for kind in ("relaxed", "taylor"):
            t0 = time.perf_counter()
            s = reference_stability(pk, kind)
            dt = time.perf_counter() - t0
            print(
                f"| {path.split('/')[-1]} | {eps:.3e} | {mt['pressure']:.3e} | {mr['tangent']:.3e} | "
                f"{mt['tangent']:.3e} | "
                f"{mr['tangent'] / mt['tangent']:.3f} | {kind} | {s['n_negative']} | {s['max_displacement']:.3g} | "
                f"{s['shear_median']:.3e} | {s['shear_max']:.3e} | {s['shear_median'] / eps:.2f} | "
                f"{s['shear_max'] / eps:.2f} | {dt:.1f} |",
                flush=True,
            )


if __name__ == "__main__":
    main(sys.argv[1:])
