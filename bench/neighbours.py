"""Neighbour search throughput: 1e4 to 1e6 disks (target: 1e6 in < 2 s after compilation)."""

import numpy as np

from bench import timeit
from gransim.contacts import find_neighbours


def _random_dense(n, rng):
    r = rng.uniform(0.35, 0.65, n)
    L = np.sqrt(np.pi * np.sum(r**2) / 0.8)
    return rng.uniform(0, L, (n, 2)), r, np.array([[L, 0.1 * L], [0.0, L]])


def run(quick: bool):
    rng = np.random.default_rng(0)
    sizes = [10_000, 100_000] if quick else [10_000, 100_000, 1_000_000]
    x, r, C = _random_dense(1000, rng)
    find_neighbours(x, r, C)  # compile
    series, out = [], []
    for n in sizes:
        x, r, C = _random_dense(n, rng)
        t = timeit(lambda: find_neighbours(x, r, C, skin=0.05), repeat=3 if n >= 10**6 else 5)
        series.append((n, t["median"] / n * 1e9))
        if n == 1_000_000:
            out.append({"name": "neighbour search 1e6 disks (sheared cell)", "value": t["median"], "unit": "s",
                        "target": "< 2 s", "meets": t["median"] < 2.0,
                        "note": f"median of {t['repeat']}, spread {t['min']:.2f}-{t['max']:.2f} s"})
    out.append({"name": "neighbour search cost per particle", "value": series[-1][1], "unit": "ns/particle",
                "target": "flat in N", "series": series, "meets": None})
    return out
