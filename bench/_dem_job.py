"""One measured DEM job, run as its own process by bench/dem.py; prints one JSON line.

``python -m bench._dem_job native PACKING.npz STEPS MODE THREADS [WARM]``
    Import gransim.dem, warm the kernels up on a 110-disk assembly (numba cache load/compile,
    thread pool), build the engine on the packing (LIGGGHTS' run set-up: first list build and
    forces, not timed), advance WARM steps untimed (the first rebuilds: the steady state), then
    time ``advance`` of STEPS steps: the counterpart of the codes' ``Loop time`` of their second
    ``run``. MODE "serial"/"parallel": the bitwise :class:`~gransim.dem.DEMEngine`; "fast": the
    fast path :class:`~gransim.dem.fast.FastEngine` on THREADS threads ("fast-lammps": in LAMMPS'
    arithmetic, the sheared cell's); "fast-sheared": the fast
    path in the sheared cell of PACKING (bench.dem.sheared_assembly) under bench.dem.SHEAR_LOADING.
    Reports loop_s, contacts, rebuilds in the window, the process's peak RSS (VmHWM, KiB) and the
    engine's own array bytes.
``python -m bench._dem_job baseline MODE THREADS``
    The same imports and warm-up only: the memory a native job holds before its packing.
``python -m bench._dem_job profile PACKING.npz STEPS``
    Serial mode, fixed box: the step replayed from the engine's own kernels, one phase at a time
    (first half step + rebuild check, rebuilds, forces, second half step), timed per phase; then
    the same steps with ``advance`` from the same state, and whether both ended bitwise equal.
``python -m bench._dem_job liggghts JOB_DIR NP TIMEOUT``
    Run ``JOB_DIR/in.bench`` (data file ``data.biaxial``) with ``reference_runs.runner.run_job``
    on NP MPI processes while sampling the VmHWM of every ``liggghts`` process; reports the parsed
    loop timing (reference_runs.timing) and the per-process peaks (KiB).
``python -m bench._dem_job lammps JOB_DIR NP TIMEOUT``
    The same with LAMMPS (``run_job(..., engine="lammps")``, the ``lmp`` processes sampled); its
    timing breakdown (``Section | min time | avg time | ...`` table: Pair, Neigh, Comm, Output,
    Modify, Other, average over ranks) and ``Per MPI rank memory allocation`` (max) are read
    from the log here.
"""

from __future__ import annotations

import gc
import json
import os
import re
import sys
import time
from pathlib import Path

from bench._memory import PeakSampler, own_peak_kib

# The OpenMP wait policy is gransim's own (gransim._numba: a short spin, GOMP_SPINCOUNT, then
# sleep), set when gransim is imported, before numba loads its OpenMP layer: the bench measures what
# a user's run gets. An OMP_WAIT_POLICY or GOMP_SPINCOUNT in the environment wins, as for a user.
# (Until 2026-12-04 this job forced OMP_WAIT_POLICY=PASSIVE: libgomp's default spinning had made a
# 2-thread step collapse 10x on a shared machine, docs/performance.md.)


#: the fast ordering's modes: the orthogonal cell in LIGGGHTS' or LAMMPS' arithmetic, the sheared
#: cell (LAMMPS' arithmetic)
FAST_MODES = ("fast", "fast-lammps", "fast-sheared")


def _packing(path):
    # lazy: imports gransim (numpy, numba), which sets the OpenMP spin count at import
    import numpy as np

    from gransim import Packing

    with np.load(path) as z:
        return Packing(positions=z["positions"], radii=z["radii"], cell=z["cell"], density=float(z["density"]))


def _warm(mode: str, threads: int):
    # lazy: imports gransim (numpy, numba), which sets the OpenMP spin count at import
    from bench._deck import LOADING, SETTINGS, assembly
    from gransim.dem import DEMEngine, DEMSettings

    if mode in FAST_MODES:
        # lazy: imports gransim (numpy, numba), which sets the OpenMP spin count at import
        from gransim.dem import fast

        low, fast.MIN_PER_THREAD = fast.MIN_PER_THREAD, 0  # the threaded kernels too, on 110 disks
        try:
            from bench.dem import SHEAR_LOADING, SHEAR_SETTINGS, sheared_assembly

            if mode in ("fast", "fast-lammps"):  # LIGGGHTS' or LAMMPS' arithmetic (the sheared cell's)
                s = SETTINGS if mode == "fast" else SHEAR_SETTINGS
                fast.FastEngine(assembly(100), s, threads=threads).advance(LOADING, 2)
                return s

            eng = fast.FastEngine(sheared_assembly(100), SHEAR_SETTINGS, threads=threads, cell="sheared")
            eng.start_run(SHEAR_LOADING, 2)
            eng.advance(2)
            return SHEAR_SETTINGS
        finally:
            fast.MIN_PER_THREAD = low
    s = DEMSettings(**{**SETTINGS.to_dict(), "mode": mode})
    DEMEngine(assembly(100), s, threads=threads).advance(LOADING, 2)
    return s


def native(path, steps: int, mode: str, threads: int, warm: int = 0) -> dict:
    # lazy: imports gransim (numpy, numba), which sets the OpenMP spin count at import
    from bench._deck import LOADING
    from gransim.dem import DEMEngine

    s = _warm(mode, threads)
    p = _packing(path)
    if mode in ("fast", "fast-lammps"):
        # lazy: imports gransim (numpy, numba), which sets the OpenMP spin count at import
        from gransim.dem.fast import FastEngine

        eng = FastEngine(p, s, threads=threads)

        def go(k):
            return eng.advance(LOADING, k)

    elif mode == "fast-sheared":  # PACKING.npz holds the sheared cell (bench.dem.sheared_assembly)
        from bench.dem import SHEAR_LOADING
        from gransim.dem.fast import FastEngine

        eng = FastEngine(p, s, threads=threads, cell="sheared")
        eng.start_run(SHEAR_LOADING, warm + steps)
        go = eng.advance
    else:
        eng = DEMEngine(p, s, threads=threads)

        def go(k):
            return eng.advance(LOADING, k)

    go(warm)
    r0 = eng.n_rebuilds
    t0 = time.perf_counter()
    go(steps)
    loop = time.perf_counter() - t0
    out = {
        "loop_s": loop,
        "n": p.n,
        "steps": steps,
        "warm": warm,
        "contacts": eng.n_contacts,
        "rebuilds": eng.n_rebuilds - r0,
        "peak_kib": own_peak_kib(),
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
        "gomp_spincount": os.environ.get("GOMP_SPINCOUNT"),
    }
    if mode in FAST_MODES:
        out["engine_bytes"] = eng.memory_bytes()
        out["entries"] = eng.n_entries
    return out


def baseline(mode: str, threads: int) -> dict:
    _warm(mode, threads)
    return {"peak_kib": own_peak_kib()}


def profile(path, steps: int) -> dict:
    # lazy: imports gransim (numpy, numba), which sets the OpenMP spin count at import
    import numpy as np

    from bench._deck import LOADING
    from gransim.dem import DEMEngine
    from gransim.dem import kernels as K

    s = _warm("serial", 1)
    if LOADING.x.mode != "fixed" or LOADING.y.mode != "fixed":
        raise SystemExit("profile: the replay leaves out the box update; it needs a fixed box")
    p = _packing(path)
    eng = DEMEngine(p, s)
    ref = DEMEngine(p, s)
    t = {"integrate": 0.0, "rebuild": 0.0, "forces": 0.0}
    clock = time.perf_counter
    t_all = clock()
    for k in range(steps):
        t0 = clock()
        K.initial_integrate(eng.x, eng.v, eng.w, eng.f, eng.t, eng.m, eng.r, s.dt)
        rebuild, bad = K.check_rebuild(eng.x, eng.xhold, eng.lo, eng.hi, eng.box.lo_hold, eng.box.hi_hold, s.skin)
        t1 = clock()
        if bad >= 0:
            raise SystemExit(f"profile: particle {bad} not finite")
        if rebuild:
            eng.step += 1
            eng._rebuild(carry=True)  # the engine's own rebuild (wrap, list, spring hand-over)
            eng.step -= 1
        t2 = clock()
        L = eng.box_lengths
        K.forces_half(
            eng.x,
            eng.v,
            eng.w,
            eng.r,
            eng.m,
            eng.ea,
            eng.eb,
            eng.esx,
            eng.esy,
            eng.both,
            eng.xi,
            L[0],
            L[1],
            s.kn,
            s.kt,
            s.gamma_n,
            s.gamma_t,
            s.mu,
            s.dt,
            True,
            eng.f,
            eng.t,
            eng.virial,
            eng.slide,
            eng.ef,
            k == steps - 1,
        )
        t3 = clock()
        K.final_integrate(eng.v, eng.w, eng.f, eng.t, eng.m, eng.r, s.dt)
        t4 = clock()
        eng.step += 1
        t["integrate"] += (t1 - t0) + (t4 - t3)
        t["rebuild"] += t2 - t1
        t["forces"] += t3 - t2
    replay = clock() - t_all
    r0 = ref.n_rebuilds
    t0 = clock()
    ref.advance(LOADING, steps)
    adv = clock() - t0
    same = bool(np.array_equal(ref.x, eng.x) and np.array_equal(ref.v, eng.v) and np.array_equal(ref.f, eng.f))
    return {
        "n": p.n,
        "steps": steps,
        "phases_s": t,
        "replay_s": replay,
        "advance_s": adv,
        "rebuilds": eng.n_rebuilds - 1,
        "advance_rebuilds": ref.n_rebuilds - r0,
        "identical": same,
    }


def lammps_breakdown(log_text: str) -> tuple[dict, float | None]:
    """LAMMPS' timing table of the (last) run: {section: average seconds over ranks}, and the
    largest ``Per MPI rank memory allocation`` (Mbytes) of the log."""
    parts, mem = {}, None
    for line in log_text.splitlines():
        m = re.match(
            r"^Per MPI rank memory allocation \(min/avg/max\) = ([\d.eE+-]+) \| ([\d.eE+-]+) \| "
            r"([\d.eE+-]+) Mbytes",
            line,
        )
        if m:
            mem = float(m.group(3))
            parts = {}
            continue
        cells = [c.strip() for c in line.split("|")]
        if len(cells) == 6 and cells[0] in ("Pair", "Neigh", "Comm", "Output", "Modify", "Other"):
            try:
                parts[cells[0]] = float(cells[2])
            except ValueError:
                pass
    return parts, mem


def engine_job(job_dir, nprocs: int, timeout: float, engine: str = "liggghts") -> dict:
    # lazy: imports gransim (numpy, numba), which sets the OpenMP spin count at import
    from reference_runs.engines import get_engine
    from reference_runs.runner import run_job
    from reference_runs.timing import parse_loop_timings

    eng = get_engine(engine)
    job = Path(job_dir)
    sampler = PeakSampler(names={eng.binary}, interval=0.05)
    deck = (job / "in.bench").read_text()
    runs = sum(1 for ln in deck.splitlines() if ln.startswith("run "))
    sampler.start()
    t0 = time.perf_counter()
    try:
        res = run_job(
            job,
            deck,
            files={"data.biaxial": job / "data.biaxial"},
            np=nprocs,
            timeout=timeout,
            expected_runs=runs,
            progress=False,
            force=True,
            engine=eng.name,
        )
    finally:
        wall = time.perf_counter() - t0
        peaks = sampler.stop()
    t = parse_loop_timings(res.log_path)[-1]  # the last run: the steady-state window
    breakdown = {k: v[0] for k, v in t.breakdown.items()}
    mem = t.memory_mb
    if eng.name == "lammps":
        breakdown, mem = lammps_breakdown(res.log_path.read_text(errors="replace"))
    return {
        "loop_s": t.loop_s,
        "n": t.atoms,
        "steps": t.steps,
        "procs": t.procs,
        "engine": eng.name,
        "run_job_s": wall,
        "breakdown": breakdown,
        "memory_mb_estimate": mem,
        "version": res.manifest.get("engine_version"),
        "rebuilds": t.neighbour_builds,
        "rank_peaks_kib": sorted(k for _, k in peaks.values()),
    }


def liggghts(job_dir, nprocs: int, timeout: float) -> dict:
    return engine_job(job_dir, nprocs, timeout, "liggghts")


def main(argv) -> int:
    kind, *a = argv
    if kind == "native":
        out = native(a[0], int(a[1]), a[2], int(a[3]), int(a[4]) if len(a) > 4 else 0)
    elif kind == "baseline":
        out = baseline(a[0], int(a[1]))
    elif kind == "profile":
        out = profile(a[0], int(a[1]))
    elif kind in ("liggghts", "lammps"):
        out = engine_job(a[0], int(a[1]), float(a[2]), kind)
    else:
        raise SystemExit(f"unknown job kind {kind!r}")
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    rc = main(sys.argv[1:])
    gc.freeze()  # the exit of the `gransim` command (gransim.cli.entry): no final walk of numba's objects
    sys.exit(rc)
