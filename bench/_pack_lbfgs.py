"""Experiment: L-BFGS instead of FIRE for a packing's last pass (docs/generation.md).

``PYTHONPATH=. python bench/_pack_lbfgs.py N SEED``

From the state ``make_packing(..., residual="rms", force_tol=1e-2)`` returns (the start of the
default protocol's last pass), minimise the enthalpy H = U + P L^2 over the fractional centres and
ln L (harmonic contacts, k_n = 1, lengths in mean diameters, P the packing's reduced pressure) with
scipy's L-BFGS-B (20 corrections, pairs from a periodic cKDTree at every evaluation) until the
largest net force is <= 1e-3 of the mean contact force and the virial pressure within 1e-3 of P:
the default criterion. Prints the evaluations it took against the FIRE steps of the default
protocol's last pass (default packing's steps minus the rms packing's). Not a timed test.
"""

import sys
import time

import numpy as np
from scipy.optimize import minimize
from scipy.spatial import cKDTree

from gransim.generation import make_packing


def main():
    N, seed = int(sys.argv[1]), int(sys.argv[2])
    t0 = time.perf_counter()
    p0 = make_packing("quartz-sand", N, seed, residual="rms", force_tol=1e-2)
    t_rms = time.perf_counter() - t0
    steps_rms = p0.metadata["fire_steps"]
    P = p0.metadata["pressure_reduced"]
    d = 2 * np.asarray(p0.radii).mean()  # number-mean diameter (the packer's unit)
    r = np.asarray(p0.radii) / d
    L0 = p0.cell[0, 0] / d
    s0 = (np.asarray(p0.positions) / d / L0) % 1.0

    def eval_(z):
        s = z[:-1].reshape(-1, 2) % 1.0
        L = np.exp(z[-1])
        x = s * L
        tree = cKDTree(x, boxsize=L)
        pr = tree.query_pairs(2 * r.max(), output_type="ndarray")
        i, j = pr[:, 0], pr[:, 1]
        dx = x[i] - x[j]
        dx -= L * np.rint(dx / L)
        dist = np.sqrt((dx * dx).sum(1))
        delta = r[i] + r[j] - dist
        m = delta > 0
        i, j, dx, dist, delta = i[m], j[m], dx[m], dist[m], delta[m]
        U = 0.5 * (delta**2).sum()
        f = (delta / dist)[:, None] * dx  # force on i (repulsive)
        F = np.zeros_like(x)
        np.add.at(F, i, f)
        np.add.at(F, j, -f)
        H = U + P * L * L
        # dH/ds = -L F ; dH/dlnL = -sum delta*dist + 2 P L^2
        g = np.empty_like(z)
        g[:-1] = (-L * F).ravel()
        g[-1] = -(delta * dist).sum() + 2 * P * L * L
        return H, g, F, delta, dist, L

    def resid(z):
        H, g, F, delta, dist, L = eval_(z)
        fmean = delta.mean()
        return (
            np.abs(np.sqrt((F * F).sum(1))).max() / fmean,
            np.sqrt((F * F).sum(1).mean()) / fmean,
            abs((delta * dist).sum() / (2 * L * L) - P) / P,
        )

    z0 = np.concatenate([s0.ravel(), [np.log(L0)]])
    print(
        f"N {N} seed {seed}: rms packing {steps_rms} FIRE steps {t_rms:.1f} s; start residual max/rms/pressure",
        resid(z0),
        flush=True,
    )
    nev = [0]

    class Done(Exception):
        pass

    def fun(z):
        nev[0] += 1
        H, g, F, delta, dist, L = eval_(z)
        return H, g

    def cb(z):
        mx, rms, pr = resid(z)
        if mx <= 1e-3 and pr <= 1e-3:
            raise Done

    t1 = time.perf_counter()
    try:
        res = minimize(
            fun,
            z0,
            jac=True,
            method="L-BFGS-B",
            callback=cb,
            options={"maxiter": 200000, "maxfun": 400000, "maxcor": 20, "ftol": 0, "gtol": 0},
        )
        print("L-BFGS stopped:", res.message, "evals", nev[0], "final", resid(res.x))
    except Done:
        print(f"L-BFGS reached max residual 1e-3: {nev[0]} evaluations, {time.perf_counter() - t1:.1f} s")
    t2 = time.perf_counter()
    pf = make_packing("quartz-sand", N, seed)
    total = pf.metadata["fire_steps"]
    print(
        f"FIRE default (max 1e-3): {total} steps total, so the last pass ~ {total - steps_rms} steps, "
        f"{time.perf_counter() - t2:.1f} s"
    )


if __name__ == "__main__":
    main()
