"""Benchmark suite: ``python -m bench [--quick] [--only AREA]`` (``make bench``).

Each module ``bench/<area>.py`` defines ``run(quick: bool) -> list[dict]`` returning records
``{"name", "value", "unit", "target", "note"}`` (optionally ``"n"`` and ``"series"`` for scaling
plots, and ``"meets"`` True/False/None). Timings repeat and report medians with spread (see
:func:`timeit`). Results land in results/bench.json and results/report/bench.html.
"""

import statistics
import time


def timeit(func, repeat: int = 5, number: int = 1, warmup: int = 1) -> dict:
    """Median and spread of ``func()`` wall time (s) over ``repeat`` runs of ``number`` calls."""
    for _ in range(warmup):
        func()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            func()
        times.append((time.perf_counter() - t0) / number)
    return {"median": statistics.median(times), "min": min(times), "max": max(times), "repeat": repeat}
