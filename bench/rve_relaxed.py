"""Benchmark: one relaxed-RVE evaluation (P and A) of a 700-disk RVE from a warm start.

Target: < 5 ms per evaluation from a warm start (committed state at a nearby F).

    PYTHONPATH=. python bench/rve_relaxed.py [--packing results/packings/rve-700-1.h5] [--repeat 20]
    python -m bench --only rve_relaxed          # as an area of the benchmark suite (run())

Measures, per step of a small compression path F(t) = diag(1 - t, 1 - t) + shear, the wall time of
``RelaxedMaterial.evaluate`` started from the committed state of the previous step (commit after
each step, as the FE2 solver does at a converged load step), and the Newton iterations; the cold
start (w = 0) at the first F is reported apart. ``fe_iterate_*``: within each step, as in an FE
Newton solve, the evaluation is repeated at F + c1 and F + c1 + c2 (corrections of 1e-2 and 1e-6
of the step, the quadratic approach of the FE iterates) before the commit: with
``--start trial`` each starts from the previous trial, with the default ``warm_start="committed"``
(or code before the option) from the committed state. Not a timed test.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def measure(p, kn: float = 2.8e7, repeat: int = 20, dstrain: float = 1e-5, start: str | None = None) -> dict:
    """Cold and warm evaluation times (ms) and Newton iterations of ``RelaxedMaterial`` on ``p``."""
    from types import SimpleNamespace

    from gransim.rve import TaylorMaterial
    from gransim.rve.relaxed import RelaxedMaterial

    args = SimpleNamespace(kn=kn, repeat=repeat, dstrain=dstrain)
    kw = {} if start is None else {"warm_start": start}
    mat = RelaxedMaterial(p, args.kn, **kw)
    tay = TaylorMaterial(p, args.kn)
    F0 = np.array([[0.999, 0.0005], [0.0, 0.999]])
    mat.evaluate(F0)  # compile
    mat = RelaxedMaterial(p, args.kn, **kw)
    t0 = time.perf_counter()
    b = mat.evaluate(F0)
    cold = time.perf_counter() - t0
    cold_it = int(b.n_newton[0])
    mat.commit()
    times, its = [], []
    dF = args.dstrain * np.array([[-1.0, 0.3], [0.2, -0.8]])
    for k in range(1, args.repeat + 1):
        F = F0 + k * dF
        t0 = time.perf_counter()
        b = mat.evaluate(F)
        times.append(time.perf_counter() - t0)
        its.append(int(b.n_newton[0]))
        mat.commit()
        assert b.energy[0] <= tay(F).energy
    # FE-like iterates within a step: F, F + c1, F + c1 + c2, then commit
    corr = np.array([[0.4, -0.1], [0.3, 0.2]])
    fe_t, fe_it = [[], [], []], [[], [], []]
    for k in range(args.repeat + 1, 2 * args.repeat + 1):
        F = F0 + k * dF
        for j, Fj in enumerate((F, F + 1e-2 * args.dstrain * corr, F + (1e-2 + 1e-6) * args.dstrain * corr)):
            t0 = time.perf_counter()
            b = mat.evaluate(Fj)
            fe_t[j].append(time.perf_counter() - t0)
            fe_it[j].append(int(b.n_newton[0]))
        mat.commit()
    tay(F0)
    t0 = time.perf_counter()
    for _ in range(100):
        tay(F0)
    t_taylor = (time.perf_counter() - t0) / 100
    out = {
        "n": p.n,
        "cold_ms": 1e3 * cold,
        "cold_newton": cold_it,
        "warm_ms_median": 1e3 * float(np.median(times)),
        "warm_ms_min": 1e3 * float(np.min(times)),
        "warm_newton": its,
        "start": getattr(mat, "warm_start", "committed (no option)"),
        "fe_iterate_ms_median": [round(1e3 * float(np.median(t)), 2) for t in fe_t],
        "fe_iterate_newton_median": [float(np.median(i)) for i in fe_it],
        "taylor_ms": 1e3 * t_taylor,
        "builds": mat.n_builds,
        "n_rattlers": int(b.n_rattlers[0]),
        "n_contacts": int(b.n_contacts[0]),
    }
    return out


def run(quick: bool = False) -> list[dict]:
    """Records of the benchmark suite: warm and cold evaluation of the 700-disk study RVE."""
    from bench.rve import _packing700

    p, label = _packing700()
    out = measure(p, repeat=3 if quick else 20)
    its = out["warm_newton"]
    return [
        {
            "name": "rve_relaxed.warm_700",
            "value": out["warm_ms_median"],
            "unit": "ms",
            "target": "< 5",
            "note": f"RelaxedMaterial.evaluate on {label} (N={p.n}) from the committed state of the previous "
            f"step (strain steps of 1e-5), median of {len(its)}; Newton iterations {its}",
        },
        {
            "name": "rve_relaxed.fe_iterate_700",
            "value": out["fe_iterate_ms_median"][-1],
            "unit": "ms",
            "target": "< 5",
            "note": f"the last of three FE-like iterates within a step (corrections 1e-2, 1e-6 of the step), "
            f"started from the previous iterate's trial ({out['start']}), median; Newton iterations "
            f"{out['fe_iterate_newton_median']} at the three iterates",
        },
        {
            "name": "rve_relaxed.cold_700",
            "value": out["cold_ms"],
            "unit": "ms",
            "target": None,
            "note": f"from w = 0, {out['cold_newton']} Newton iterations",
        },
        {
            "name": "rve_relaxed.taylor_700",
            "value": out["taylor_ms"],
            "unit": "ms",
            "target": None,
            "note": "TaylorMaterial on the same RVE, for comparison",
        },
    ]


def main(argv=None) -> dict:
    from gransim.generation import standard_packings
    from gransim.io import load_packing

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--packing", default=None, help="HDF5 packing (default: rve-700-1 of results/packings)")
    ap.add_argument("--repeat", type=int, default=20, help="warm steps measured")
    ap.add_argument("--kn", type=float, default=2.8e7, help="E_n (N/m)")
    ap.add_argument("--dstrain", type=float, default=1e-5, help="strain increment per step")
    ap.add_argument("--start", choices=["trial", "committed"], default=None, help="RelaxedMaterial warm_start")
    args = ap.parse_args(argv)
    path = args.packing or standard_packings("results/packings", names=["rve-700-1"])["rve-700-1"]
    out = measure(load_packing(path), args.kn, args.repeat, args.dstrain, args.start)
    print(json.dumps(out, indent=1))
    return out


if __name__ == "__main__":
    main()
