"""Benchmarks of the LIGGGHTS reference runs: process start-up, Taylor states per second.

``run(quick)`` returns records {"name", "value", "unit", "target", "note"}; empty when the
``liggghts`` binary is absent.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from pathlib import Path

from reference_runs.demo_packings import perturbed_lattice
from reference_runs.runner import run_job
from reference_runs.taylor import run_taylor


def run(quick: bool = True) -> list[dict]:
    if shutil.which("liggghts") is None:
        return []

    out = []
    with tempfile.TemporaryDirectory() as tmp:
        t = []
        for k in range(3):
            t0 = time.perf_counter()
            run_job(Path(tmp) / f"empty{k}", "units si\n", progress=False)
            t.append(time.perf_counter() - t0)
        out.append(
            {
                "name": "liggghts_process_start",
                "value": min(t),
                "unit": "s",
                "target": None,
                "note": "run_job of a one-line deck (process start, MPI init, manifest)",
            }
        )
        nx, ny = (26, 28) if not quick else (12, 12)
        p = perturbed_lattice(nx, ny, seed=2)
        stride = 1 if not quick else 5
        t0 = time.perf_counter()
        r = run_taylor(p, 2.8e7, Path(tmp) / "taylor", stride=stride, progress=False)
        wall = time.perf_counter() - t0
        n_states = sum(len(s.k) for s in r.series.values())
        out.append(
            {
                "name": f"taylor_states_{p.n}_disks",
                "value": n_states / wall,
                "unit": "states/s",
                "target": None,
                "note": f"{n_states} states (4 paths, both routes) in one LIGGGHTS job incl. data "
                f"files; LIGGGHTS alone {r.manifest['elapsed_s']:.2f} s",
            }
        )
    return out


if __name__ == "__main__":  # pragma: no cover
    import sys

    from bench import print_records

    sys.exit(print_records(run(quick=False)))  # a NaN or inf figure: FAIL, exit 1
