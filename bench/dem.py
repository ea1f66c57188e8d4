"""DEM throughput: native engine vs LIGGGHTS 3.8.0 serial, side by side on the same assembly,
deck and number of steps (particle-steps per second = N * steps / wall time of the loop).

Records: native serial and LIGGGHTS serial at 1,002 and 100,000 disks (target native >= 1.5x),
native with 2 threads (mode "parallel"), and the native scaling from 1e3 to 1e6 disks (cost per
particle-step should be flat). Assembly: jittered triangular lattice of polydisperse disks
overlapping ~8% of a radius (coordination ~4.9, gransim.dem.lattice) relaxing in a fixed periodic box,
kn = kt = 1e5 N/m, damping and friction on. Run: ``python bench/dem.py [--quick]``.
"""

from __future__ import annotations

import math
import re
import shutil
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gransim.dem import DEMEngine, DEMSettings, Loading
from gransim.dem.lattice import lattice_packing

SETTINGS = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
# fixed box: under a strain rate or servo the box displacement eats the skin (LIGGGHTS' rebuild
# rule) faster in larger boxes, so rebuilds per step would grow with N in both codes alike
LOADING = Loading()


def assembly(n: int):
    nx = max(3, round(math.sqrt(n * 2 / math.sqrt(3))))
    ny = max(4, round(n / nx))
    ny += ny % 2
    return lattice_packing(nx, ny, seed=1, spread=0.1, compression=0.08)


REPEATS = 3  # best of 3, native and LIGGGHTS interleaved: the 2 cores are shared with other jobs


def native(p, steps: int, mode: str = "serial", threads: int | None = None) -> tuple[float, float]:
    """Particle-steps/s of ``steps`` steps from the same initial state (wall clock), coordination."""
    s = DEMSettings(**{**SETTINGS.to_dict(), "mode": mode})
    eng = DEMEngine(p, s, threads=threads)
    eng.advance(LOADING, 2)  # compile / warm up
    eng = DEMEngine(p, s, threads=threads)
    t0 = time.perf_counter()
    eng.advance(LOADING, steps)
    dt = time.perf_counter() - t0
    return p.n * steps / dt, 2 * eng.n_contacts / p.n


def liggghts(p, steps: int) -> float | None:
    if shutil.which("liggghts") is None:
        return None
    from reference_runs.decks.biaxial import run_liggghts, write_biaxial_deck

    with tempfile.TemporaryDirectory(prefix="bench-dem-") as tmp:
        deck = write_biaxial_deck(tmp, p, SETTINGS, LOADING, steps, thermo_every=max(steps // 10, 1),
                                  dump_every=10 * steps)
        log = run_liggghts(deck)
        m = re.search(r"Loop time of ([0-9.eE+-]+) on 1 procs for (\d+) steps with (\d+) atoms", log.read_text())
        return p.n * int(m.group(2)) / float(m.group(1))


def run(quick: bool = False) -> list[dict]:
    recs = []
    for n, steps in ((1002, 2000 if quick else 10000), (100_000, 20 if quick else 200)):
        p = assembly(n)
        nat, lig = 0.0, None
        for _ in range(1 if quick else REPEATS):
            t, z = native(p, steps)
            nat = max(nat, t)
            t = liggghts(p, steps)
            lig = None if t is None else max(lig or 0.0, t)
        note = f"{p.n} disks, {steps} steps, coordination {z:.2f}, same deck, best of {1 if quick else REPEATS}"
        recs.append({"name": f"native serial, {p.n} disks", "value": nat, "unit": "particle-steps/s",
                     "target": None, "note": note})
        if lig is not None:
            recs.append({"name": f"LIGGGHTS 3.8.0 serial, {p.n} disks", "value": lig, "unit": "particle-steps/s",
                         "target": None, "note": note})
            recs.append({"name": f"native / LIGGGHTS, {p.n} disks", "value": nat / lig, "unit": "x",
                         "target": 1.5, "note": "serial, 1 core each"})
        par = max(native(p, steps, mode="parallel", threads=2)[0] for _ in range(1 if quick else REPEATS))
        recs.append({"name": f"native 2 threads (parallel mode), {p.n} disks", "value": par,
                     "unit": "particle-steps/s", "target": None, "note": note})
    sizes = (1000, 10_000, 100_000) if quick else (1000, 10_000, 100_000, 1_000_000)
    for n in sizes:
        p = assembly(n)
        steps = max(10, int(2e7 / n)) if not quick else max(5, int(2e6 / n))
        nat = max(native(p, steps)[0] for _ in range(1 if quick else REPEATS))
        recs.append({"name": f"native serial scaling, {p.n} disks", "value": 1e9 / nat, "unit": "ns/particle-step",
                     "target": None, "note": f"{steps} steps, best of {1 if quick else REPEATS}; flat = O(N)"})
    return recs


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        tgt = "" if r["target"] is None else f"  (target {r['target']})"
        print(f"{r['name']:48s} {r['value']:12.4g} {r['unit']}{tgt}  [{r['note']}]")
