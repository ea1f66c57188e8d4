"""Start-up: ``gransim --help`` wall time (heavy imports must stay lazy), first-call JIT with a warm cache."""

import subprocess
import sys
import time


def _wall(cmd, repeat=5):
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        ts.append(time.perf_counter() - t0)
    ts.sort()
    return ts[len(ts) // 2], ts[0], ts[-1]


def run(quick: bool):
    med, lo, hi = _wall([sys.executable, "-m", "gransim", "--help"], repeat=3 if quick else 7)
    out = [{"name": "gransim --help wall time", "value": med, "unit": "s", "target": "< 1 s", "meets": med < 1.0,
            "note": f"median, spread {lo:.2f}-{hi:.2f} s"}]
    code = ("import time,numpy as np;t=time.perf_counter();"
            "from gransim.contacts import find_neighbours;"
            "find_neighbours(np.random.rand(50,2),np.full(50,0.05),np.eye(2));"
            "print(time.perf_counter()-t)")
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)  # fill the cache
    vals = sorted(float(subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                                       text=True).stdout) for _ in range(3))
    out.append({"name": "first neighbour search incl. import, warm numba cache", "value": vals[1], "unit": "s",
                "target": "< 2 s", "meets": vals[1] < 2.0, "note": "median of 3 fresh processes"})
    return out
