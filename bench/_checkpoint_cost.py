"""Cost of the checkpoints of a DEM run (docs/dem.md, "Checkpoints").

The same biaxial run (the ``gransim biaxial`` protocol and output defaults: a series row every 10
steps, a snapshot every 10000) with ``checkpoint_every`` 0, 20000, 5000 and 1000: wall and CPU time of
the run, and the time spent writing the run file (every checkpoint plus the final write), measured
around :func:`gransim.dem.run.write_run` and ``write_checkpoint``. Interleaved over the repeats,
so a change of the machine's load hits every setting alike. Run from the repository root::

    NUMBA_CACHE_DIR=.venv/numba-cache .venv/bin/python -m bench._checkpoint_cost [--n 200] [--repeats 2]

Against another version of the sources (the figures before a change), point PYTHONPATH at its
tree (``git archive <commit> gransim | tar -x -C /tmp/old``) and run this file by its path:
``PYTHONPATH=/tmp/old .venv/bin/python bench/_checkpoint_cost.py``.
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path


def one_run(packing, every: int, out: Path) -> dict:
    import gransim.dem.run as run_mod  # noqa: PLC0415
    from gransim.dem.biaxial import biaxial_phases, default_settings  # noqa: PLC0415
    from gransim.dem.output import OutputSettings  # noqa: PLC0415

    dem, bi = default_settings(packing, strain=0.005)
    spent = {"writes": 0, "s": 0.0}
    names = [n for n in ("write_run", "write_checkpoint") if hasattr(run_mod, n)]  # older: write_run only
    real = {n: getattr(run_mod, n) for n in names}

    def timed(fn):
        def wrapper(*a, **k):
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                spent["writes"] += 1
                spent["s"] += time.perf_counter() - t

        return wrapper

    for n in names:
        setattr(run_mod, n, timed(real[n]))
    try:
        t0, c0 = time.perf_counter(), time.process_time()
        run_mod.run_phases(
            packing,
            dem,
            biaxial_phases(dem, bi),
            out,
            OutputSettings(series_every=10, snapshot_every=10000, checkpoint_every=every),
            show_progress=False,
            metadata={"biaxial": dataclasses.asdict(bi)},
        )
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        for n in names:
            setattr(run_mod, n, real[n])
    return {"every": every, "wall": wall, "cpu": cpu, "writes": spent["writes"], "write_s": spent["s"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=200, help="disks (default 200)")
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--every", type=int, nargs="+", default=[0, 20000, 5000, 1000])
    args = ap.parse_args(argv)

    import gransim  # noqa: PLC0415
    from gransim.generation import make_packing  # noqa: PLC0415

    print(f"gransim from {Path(gransim.__file__).parent}")
    packing = make_packing("quartz-sand", args.n, 1)
    rows = {e: [] for e in args.every}
    with tempfile.TemporaryDirectory() as d:
        one_run(packing, 0, Path(d) / "warm.h5")  # numba's first calls
        for _ in range(args.repeats):
            for e in args.every:
                rows[e].append(one_run(packing, e, Path(d) / f"run{e}.h5"))
        size = {e: (Path(d) / f"run{e}.h5").stat().st_size for e in args.every}
    print(f"{args.n} disks, best of {args.repeats}; file {max(size.values()) / 1e6:.2f} MB at the end")
    print(f"{'checkpoint_every':>16} {'wall s':>8} {'cpu s':>8} {'writes':>6} {'writing s':>9} {'per write ms':>12}")
    for e in args.every:
        r = min(rows[e], key=lambda x: x["wall"])
        print(
            f"{e:>16} {r['wall']:8.2f} {r['cpu']:8.2f} {r['writes']:6d} {r['write_s']:9.2f} "
            f"{1e3 * r['write_s'] / max(r['writes'], 1):12.1f}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
