"""The stress ratio tau / p a relaxed frictionless RVE can carry (docs/slope.md).

Isochoric-to-first-order pure shear F = 1 + g D, D = sym(e1 x e2) (``gransim.fem.stability.SHEAR``),
ramped in steps of ``dg`` from F = 1, each state relaxed warm from the previous minimiser
(``RelaxedMaterial(...)(F, start=...)``). Prints g, tau = sigma_xy (Cauchy, Pa at unit thickness),
p = -tr sigma / 2, tau / p, the RVE's Newton iterations and held rattlers, and the largest tau / p
reached; drops of tau between steps are the rearrangements (plastic events). The same ramp with the
Taylor RVE gives tau / p growing linearly without limit. Frictionless disk packs have a macroscopic
friction coefficient of about 0.1 (Peyneau & Roux 2008, "Frictionless bead packs have macroscopic
friction, but no dilatancy", Phys. Rev. E 78, 011307).

    PYTHONPATH=. python bench/_rve_shear_ratio.py PACKING.h5 [G_MAX [DG]]
"""

from __future__ import annotations

import sys
import time

import numpy as np

from gransim.errors import ConvergenceError
from gransim.fem.slope import NORMAL_STIFFNESS
from gransim.fem.stability import SHEAR, mean_overlap_strain
from gransim.io import load_packing
from gransim.rve import RelaxedMaterial


def main(path, g_max=0.02, dg=2e-4):
    pk = load_packing(path)
    m = RelaxedMaterial(pk, NORMAL_STIFFNESS)
    prev = m(np.eye(2))
    best, drops, first, stop, t0 = 0.0, 0, None, "", time.perf_counter()
    tau_prev = 0.0
    print(f"{path}: overlap strain {mean_overlap_strain(pk):.3e}")
    print("| g | tau (Pa) | p (Pa) | tau/p | RVE Newton | held |")
    print("|---|---|---|---|---|---|")
    n = int(round(g_max / dg))
    for k in range(1, n + 1):
        g = k * dg
        try:
            r = m(np.eye(2) + g * SHEAR, start=prev)
        except ConvergenceError as exc:
            stop = f"; the RVE fails at g = {g:.4f}: {exc}"
            break
        s = np.asarray(r.cauchy)
        tau, p = 0.5 * (s[0, 1] + s[1, 0]), -0.5 * np.trace(s)
        if tau < tau_prev:
            drops += 1
            first = g if first is None else first
        tau_prev = tau
        best = max(best, tau / p)
        if k % max(1, n // 20) == 0 or k <= 3:
            print(
                f"| {g:.4f} | {tau:.4e} | {p:.4e} | {tau / p:.4f} | {r.n_newton} | {getattr(r, 'n_held', 0)} |",
                flush=True,
            )
        prev = r
    print(
        f"max tau/p = {best:.4f} over g <= {g:.4f}, {drops} drops of tau (first at g = {first}), "
        f"{time.perf_counter() - t0:.1f} s{stop}"
    )


if __name__ == "__main__":
    a = sys.argv[1:]
    main(a[0], *(float(v) for v in a[1:]))
