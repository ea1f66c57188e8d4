"""Packing generation: 700 disks (target < 10 s) and 100,000 disks (target < 2 min), quartz-sand.

700 disks: the default make_packing request (mean overlap 2.7e-4 of the mean diameter, residual force
<= 1e-3 of the mean contact force). 10,000 and 100,000 disks: the same with force_tol = 1e-2 (the
default max-norm criterion at 1e5 disks is far slower: the low-pressure creep of a large jammed
packing keeps some disk out of balance). Timed after compilation, one run each. Run alone:
``python -c "import bench.generation as b; print(b.run(quick=False))"`` or ``python -m bench --only generation``.
"""

import statistics
import time

from gransim.generation import make_packing


def _time(n, seed, **kw):
    t0 = time.perf_counter()
    p = make_packing("quartz-sand", n, seed, **kw)
    return time.perf_counter() - t0, p.metadata


def run(quick: bool):
    make_packing("quartz-sand", 50, 1)  # compile
    out, series = [], []
    times = []
    for seed in (1, 2, 3):
        t, meta = _time(700, seed)
        times.append(t)
    med = statistics.median(times)
    series.append((700, med))
    out.append({"name": "packing 700 disks (quartz-sand)", "value": med, "unit": "s", "target": "< 10 s",
                "meets": med < 10.0, "n": 700,
                "note": f"median of seeds 1-3, spread {min(times):.2f}-{max(times):.2f} s; "
                        f"phi {meta['solid_fraction']:.4f}, {meta['fire_steps']} FIRE steps (seed 3)"})
    sizes = [10_000] if quick else [10_000, 100_000]
    for n in sizes:
        t, meta = _time(n, 1, force_tol=1e-2)
        series.append((n, t))
        rec = {"name": f"packing {n:,} disks (quartz-sand)", "value": t, "unit": "s", "n": n,
               "note": f"seed 1, one run, force_tol 1e-2; phi {meta['solid_fraction']:.4f}, {meta['fire_steps']} FIRE steps, "
                       f"{meta['neighbour_builds']} neighbour builds, residual {meta['residual']:.1e}"}
        if n == 100_000:
            rec.update(target="< 120 s", meets=t < 120.0)
        else:
            rec.update(target="", meets=None)
        out.append(rec)
    out.append({"name": "packing time against N", "value": series[-1][1], "unit": "s", "target": "",
                "series": series, "meets": None})
    return out
