"""Benchmarks of the Taylor RVE: W, P, A of a 700-particle RVE and batched throughput.

``run(quick)`` returns records {"name", "value", "unit", "target", "note"}. The RVE is one of
the standard 700-particle RVEs when gransim.generation is available (``rve-700-1`` in
results/packings), otherwise a stand-in: 700 polydisperse disks (radius ratio 3) placed at
random in a sheared periodic cell at nominal solid fraction 0.85 (heavily overlapping, so
its contact count per particle is higher than a relaxed packing's: a pessimistic case).

Run: ``PYTHONPATH=. python -m bench.rve`` (or ``python bench/rve.py [--quick]``).
"""

from __future__ import annotations

import time

import numba
import numpy as np

from gransim import Packing
from gransim._numba import set_num_threads
from gransim.generation import standard_packings
from gransim.io import load_packing
from gransim.paper import KN_2D
from gransim.rve import TaylorMaterial, homogenize

N_GAUSS = 1520


def _packing700():
    try:
        path = standard_packings("results/packings", names=["rve-700-1"])["rve-700-1"]
        return load_packing(path), "rve-700-1"
    except Exception:  # noqa: BLE001 - generation not merged or not generated: use the stand-in
        rng = np.random.default_rng(700)
        r = rng.uniform(0.5, 1.5, 700) * 1e-4
        side = np.sqrt(np.pi * np.sum(r**2) / 0.85)
        cell = np.array([[side, 0.2 * side], [0.0, side]])
        return Packing(positions=rng.uniform(0, 1, (700, 2)) @ cell.T, radii=r, cell=cell), "stand-in"


def _median_time(fn, repeats: int, inner: int) -> tuple[float, float]:
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for _ in range(inner):
            fn()
        ts.append((time.perf_counter() - t0) / inner)
    ts = np.array(ts)
    return float(np.median(ts)), float(np.percentile(ts, 75) - np.percentile(ts, 25))


def run(quick: bool = False) -> list[dict]:
    packing, label = _packing700()
    kn = KN_2D  # the paper's 2D contact stiffness (N/m)
    mat = TaylorMaterial(packing, kn)
    F = np.array([[1.002, 0.001], [-0.0005, 0.999]])
    mat(F)  # compile + build candidates
    homogenize(packing, F, kn)
    res = mat(F)
    reps, inner = (5, 200) if quick else (15, 2000)
    t_single, spread = _median_time(lambda: mat(F), reps, inner)
    t_func, _ = _median_time(lambda: homogenize(packing, F, kn), reps, inner // 2)
    n_cand = int(mat.evaluate(F).n_candidates[0])
    records = [
        {
            "name": "rve.wpa_700",
            "value": t_single * 1e6,
            "unit": "us",
            "target": "< 100",
            "note": f"TaylorMaterial(F) on {label} (N={packing.n}, {res.n_contacts} contacts, "
            f"{n_cand} "
            f"candidates), median of {reps}x{inner}, IQR {spread * 1e6:.2f} us",
        },
        {
            "name": "rve.homogenize_700",
            "value": t_func * 1e6,
            "unit": "us",
            "target": "< 100",
            "note": "gransim.rve.homogenize(packing, F, kn) incl. per-packing cache look-up",
        },
    ]
    rng = np.random.default_rng(0)
    Fb = np.eye(2) + 0.01 * rng.uniform(-1, 1, (N_GAUSS, 2, 2))
    mat.evaluate(Fb)  # candidate sets for these states
    n_threads = numba.get_num_threads()
    for threads in sorted({1, n_threads}):
        set_num_threads(threads)
        b = mat.evaluate(Fb)
        evals = int(b.n_candidates.sum())
        active = int(b.n_contacts.sum())
        t, spread = _median_time(lambda: mat.evaluate(Fb), 3 if quick else 9, 2 if quick else 10)
        records.append(
            {
                "name": f"rve.batched_evals_per_s_{threads}thread",
                "value": evals / t / threads,
                "unit": "candidate evaluations/s/core",
                "target": ">= 2e7",
                "note": f"{N_GAUSS} Gauss points x {evals // N_GAUSS} candidates "
                f"({active // N_GAUSS} active "
                f"contacts) in {t * 1e3:.2f} ms on {threads} thread(s); active-contact rate "
                f"{active / t / threads:.3g}/s/core; IQR {spread * 1e3:.2f} ms",
            }
        )
    set_num_threads(n_threads)
    return records


if __name__ == "__main__":
    import sys

    from bench import print_records

    sys.exit(print_records(run(quick="--quick" in sys.argv)))  # a NaN or inf figure: FAIL, exit 1
