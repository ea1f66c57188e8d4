"""Benchmark of the slope solver (issue 8): each protocol end to end on 1520 Gauss points.

On a shared machine the wall time depends on the load; the process CPU time (summed over threads)
is also reported: it bounds the wall time the run would take on an idle machine.

Material: the Taylor RVE (gransim.rve) of the most uniform standard 700-particle RVE when
gransim.generation provides it, otherwise a stand-in 700-disk jittered triangular lattice (noted in
the records). Compilation is excluded (one warm-up evaluation), outputs are not written. Each record
splits the wall time into RVE evaluation, assembly and the linear solve.
"""

from __future__ import annotations

import time

import numpy as np


def standin_packing(n_x: int = 28, n_y: int = 25, swell: float = 1.0005, jitter: float = 0.02, seed: int = 0):
    """700 disks on a jittered triangular lattice (spacing 1 mm, overlaps ~5e-4 mm): timing stand-in."""
    from gransim import Packing

    a = 1e-3
    h = a * np.sqrt(3) / 2
    ii, jj = np.meshgrid(np.arange(n_x), np.arange(n_y), indexing="ij")
    x = np.column_stack([(ii + 0.5 * (jj % 2)).ravel() * a, jj.ravel() * h])
    x += np.random.default_rng(seed).uniform(-jitter, jitter, x.shape) * a
    return Packing(positions=x, radii=np.full(len(x), 0.5 * a * swell), cell=np.diag([n_x * a, n_y * h]),
                   metadata={"kind": "fem-bench-standin-lattice"})


def _material():
    from gransim.errors import GransimError
    from gransim.fem.run import default_rve_packing, make_material

    try:
        packing, note = default_rve_packing(), "most uniform standard 700-particle RVE"
    except (ImportError, GransimError) as exc:  # generation/rve selection not available
        packing, note = standin_packing(), f"stand-in 700-disk lattice ({type(exc).__name__})"
    return make_material("taylor", packing), note


def run(quick: bool = False) -> list[dict]:
    """Records {"name", "value", "unit", "target", "note"} per protocol (wall, material, assembly, solve)."""
    from gransim.fem.slope import run_slope, setup_for

    mat, note = _material()
    mat.evaluate(np.broadcast_to(np.eye(2), (1520, 2, 2)).copy())  # compile / warm the caches
    out = []
    for protocol in ("service", "paper"):
        setup = setup_for(protocol)
        t0, c0 = time.perf_counter(), time.process_time()
        _, res = run_slope(mat, setup)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        t = res.timer
        status = "completed" if res.completed else (
            f"stopped at footing fraction {res.limit['last_converged_load'][1]:.4f} (step {res.limit['step']})")
        n = f"{t.iterations} Newton iterations, {status}; {note}"
        out += [{"name": f"fem.slope.{protocol}.wall", "value": wall, "unit": "s", "target": "< 10", "note": n},
                {"name": f"fem.slope.{protocol}.cpu", "value": cpu, "unit": "s", "target": "< 10",
                 "note": "process CPU time (all threads): an upper bound of the wall time on an idle machine"},
                {"name": f"fem.slope.{protocol}.rve_evaluation", "value": t.material, "unit": "s", "target": "",
                 "note": "batched Taylor RVE, all 1520 Gauss points per call"},
                {"name": f"fem.slope.{protocol}.assembly", "value": t.assembly, "unit": "s", "target": "",
                 "note": "element residual/stiffness + sparse assembly + constraint reduction"},
                {"name": f"fem.slope.{protocol}.solve", "value": t.solve, "unit": "s", "target": "",
                 "note": "SuperLU factorisation and solve"},
                {"name": f"fem.slope.{protocol}.per_iteration", "value": wall / max(t.iterations, 1), "unit": "s",
                 "target": "", "note": ""}]
        if quick:
            break
    return out


if __name__ == "__main__":  # pragma: no cover
    for r in run(quick=False):
        print(f"{r['name']:40s} {r['value']:10.4f} {r['unit']:3s} {r['target']:6s} {r['note']}")
