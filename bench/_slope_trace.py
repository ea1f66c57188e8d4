"""A slope run that prints every Newton iteration as it happens (docs/slope.md).

``gransim slope`` writes its tables at the end; on a slow relaxed run this shows where it is:
per RVE evaluation the wall time, the residual norm |r| (N/m), and (relaxed RVE) the Newton
iterations of the RVE relaxations (max, sum), the Gauss points with held rattlers and with an
unstable (shifted) W_ww, and the mean pressure range -tr P / 2 (Pa).

    PYTHONPATH=. python bench/_slope_trace.py PACKING.h5 relaxed|taylor COLSxROWS LOAD_STEPS [OUT.npz]

With OUT.npz, every converged (sub-)increment overwrites it with the load, the Gauss points'
positions and their Cauchy stresses (Pa), and the summary line prints, at the last converged
state, the Mohr shear over the mean pressure tau / p of the Gauss points (percentiles).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from gransim.fem import solver
from gransim.fem.mesh import SlopeGeometry
from gransim.fem.run import make_material
from gransim.fem.slope import run_slope, setup_for


def main(packing, rve, mesh, load_steps, out=None):
    cols, rows = (int(v) for v in mesh.split("x"))
    mat = make_material("taylor", packing, "most-uniform", 4 * cols * rows, rve=rve)
    inner = mat.rve
    orig_eval = inner.evaluate
    t_start = time.perf_counter()

    def evaluate(F, *a, **k):
        t0 = time.perf_counter()
        b = orig_eval(F, *a, **k)
        dt = time.perf_counter() - t0
        extra = ""
        if hasattr(b, "n_newton"):
            held = int(np.count_nonzero(b.n_held)) if b.n_held is not None else 0
            extra = (
                f" rve newton max {int(b.n_newton.max())} sum {int(b.n_newton.sum())}, held at {held} pts,"
                f" unstable {int(np.count_nonzero(~b.stable))} pts"
            )
        p = -0.5 * (b.piola[:, 0, 0] + b.piola[:, 1, 1])
        print(
            f"  [{time.perf_counter() - t_start:7.1f} s] eval {len(F)} pts {dt:6.2f} s, "
            f"p in [{p.min():.3g}, {p.max():.3g}]{extra}",
            flush=True,
        )
        return b

    inner.evaluate = evaluate
    orig_newton = solver.newton
    last = {}

    def newton(problem, q0, load, **kw):
        print(f"newton at load {tuple(float(v) for v in load)}", flush=True)
        try:
            res = orig_newton(problem, q0, load, **kw)
        except solver.NewtonFailure as exc:
            print(f"  FAILED: {exc}; energy norms {[f'{e:.2e}' for e in exc.energy_norms]}", flush=True)
            raise
        print(f"  converged: energy norms {[f'{e:.2e}' for e in res.energy_norms]}", flush=True)
        last["load"], last["cauchy"] = np.asarray(load, float), np.asarray(res.material.cauchy)
        if out:
            np.savez(out, load=last["load"], cauchy=last["cauchy"], points=last["points"])
        return res

    solver.newton = newton
    setup = setup_for("service", SlopeGeometry(columns=cols, rows=rows), load_steps)
    import gransim.fem.slope as slope_mod  # noqa: PLC0415

    slope_mod.run_load_steps.__globals__["newton"] = newton
    from gransim.fem.element import Q1Geometry  # noqa: PLC0415
    from gransim.fem.mesh import slope_mesh  # noqa: PLC0415

    last["points"] = Q1Geometry.from_mesh(slope_mesh(setup.geometry)).points.reshape(-1, 2)
    t0 = time.perf_counter()
    _, res = run_slope(mat, setup)
    print(
        f"done in {time.perf_counter() - t0:.1f} s: completed {res.completed}, "
        f"limit {res.limit and res.limit['reason']}"
    )
    if "cauchy" in last:
        S = last["cauchy"]
        pm = -0.5 * (S[:, 0, 0] + S[:, 1, 1])
        tau = np.sqrt(0.25 * (S[:, 0, 0] - S[:, 1, 1]) ** 2 + 0.25 * (S[:, 0, 1] + S[:, 1, 0]) ** 2)
        q = [5, 25, 50, 75, 95, 100]
        ratio = np.percentile(tau / pm, q)
        print(f"last converged load {last['load']}: tau/p percentiles {q}: " + ", ".join(f"{v:.3f}" for v in ratio))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4]), *sys.argv[5:6])
