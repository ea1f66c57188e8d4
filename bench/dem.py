"""DEM throughput and memory: the native fast path (gransim.dem.fast, 1 and 2 threads) and the
bitwise engine (DEMEngine, 1 and 2 threads) vs LAMMPS (29 Sep 2021, Debian ``lammps``, the speed
anchor) and LIGGGHTS 3.8.0, each serial and ``mpirun -np 2``, on the same assembly, contact law
and steps, at about 1e3, 1e4, 1e5 and 1e6 disks (docs/performance.md).

LAMMPS runs the LAMMPS form of the same deck (``write_biaxial_deck(..., engine="lammps")``:
``pair_style gran/hooke/history`` with the same kn, kt, dampings and friction, 2D masses by
``set density/disc``, ``fix nve/sphere disc``, sorting off, ``newton off``), timed by its own
``Loop time of`` like LIGGGHTS; its memory is the VmHWM of the ``lmp`` processes, and its profile
is its ``Pair/Neigh/Comm/Output/Modify/Other`` table (average over ranks).

What is timed: the steady state. Every job first runs WARM steps untimed (from rest the first
rebuild comes at about step 36, then one every 10 to 15 steps), then a timed window of STEPS
steps that holds many rebuilds (their number is in each record's note). The codes run the deck
with two ``run`` commands (``run WARM`` then ``run STEPS``) and the second ``Loop time of`` is
the window; the native job advances WARM steps, then times ``advance(STEPS)``. Both loops
include their rebuilds and per-step output (codes: thermo every STEPS/10; native: stress etc.
every step). Throughput = N * STEPS / loop time, in particle-steps per second. Beside it, the
whole-process time: the wall time of the job from its start to its end (native: interpreter
start, imports, kernels from numba's cache, warm-up, packing, set-up, WARM steps and the window;
codes: ``run_job`` from launch to exit: reading the data file, set-ups, both runs).

Memory. Every measured job runs in its own process (bench/_dem_job.py), so its peak memory is its
own: native jobs report their VmHWM; the codes the VmHWM of each ``liggghts``/``lmp`` process
sampled at 20 Hz (np 2: the sum over both ranks). "Above baseline" subtracts the process's
footprint without the assembly: for native jobs the same imports, kernels and warm-up with no
packing (a ``baseline`` job), for a code its VmHWM on the smallest assembly of the sweep (1,020
disks, arrays < 1 MB). The configurations are interleaved within each repeat (the order rotates),
because the 2 cores are shared; records give the median over repeats with min..max, and each
job's 1-minute load average (os.getloadavg) is kept in its record's note.

Targets (docs/performance.md, "Performance targets and where they stand"): fast 1 thread >= 2.5 x
LAMMPS serial; bitwise 1 thread >= 1.9 x LAMMPS serial; fast 2 threads >= 1.75 x fast 1 thread; the
fast order's sheared cell (``sheared_assembly``, 99,960 disks) >= 0.9 x its orthogonal cell in
the same arithmetic (LAMMPS', "fast 1 thread LAMMPS arithmetic") and on
2 threads >= 1.75 x 1 thread; ns per particle-step flat within 20% from 1e3 to 1e6; fast peak
above baseline <= 0.6 x LAMMPS serial at 1e6. Also "a core taken": fast and bitwise on 2 threads
while a spinning process (started and stopped here) holds one core, against 1 thread under the
same condition; and a profile at 1e5 disks (native phases and the codes' own tables).

Assembly: jittered triangular lattice of polydisperse disks overlapping ~8% of a radius
(coordination ~4.9, gransim.dem.lattice) relaxing in a fixed periodic box (sizes are the nearest
lattice: 1,020, 10,058, 99,960, 999,750 disks), kn = kt = 1e5 N/m, damping and friction on,
LIGGGHTS deck of reference_runs.decks.biaxial (sorting off, ``newton off``) without its dump.

Run: ``python -m bench --only dem [--quick]`` (quick: 1 repeat, 1,020 and 10,058 disks, LIGGGHTS
and LAMMPS only at 1,020 disks, no target judged; under 2 minutes); absent LIGGGHTS, LAMMPS or
mpirun only drops their records (noted). ``make bench`` runs the whole suite.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench import median, print_records
from bench._memory import run_child
from reference_runs.decks.biaxial import write_biaxial_deck

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np

from bench._deck import LOADING, SETTINGS, assembly  # noqa: F401 - the deck, re-exported

#: the sheared cell of the benchmark (the fast ordering's cell="sheared", LAMMPS' arithmetic: the
#: sheared cell moves its tilt in LAMMPS' ``fix deform ... remap v`` only): the bench assembly in a
#: cell tilted by SHEAR_TILT of Lx, rounded to whole lattice spacings (the lattice stays periodic
#: across the tilted boundary), sheared at 0.01/s (the tilt stays about the same over a window, as
#: the orthogonal bench's box stays fixed)
SHEAR_TILT = 0.2
#: lattice spacing of the bench assembly (m): 2 x gransim.dem.lattice.lattice_packing's radius
LATTICE_SPACING = 2e-3


def _shear_deck():
    # lazy: the sheared cell's module (its kernels decorate at import)
    from gransim.dem import DEMSettings
    from gransim.dem.sheared import ShearLoading

    return DEMSettings(**{**SETTINGS.to_dict(), "flavour": "lammps"}), ShearLoading(erate=0.01)


SHEAR_SETTINGS, SHEAR_LOADING = _shear_deck()


def sheared_assembly(n: int):
    """:func:`assembly` of ``n`` disks in the benchmark's sheared cell (:data:`SHEAR_TILT`)."""
    from gransim import Packing

    p = assembly(n)
    C = np.array(p.cell, np.float64)
    C[0, 1] = round(SHEAR_TILT * C[0, 0] / LATTICE_SPACING) * LATTICE_SPACING
    return Packing(positions=p.positions, radii=p.radii, cell=C, density=p.density)


#: (nominal disks, warm-up steps, timed steps). The warm-up holds the first 2 to 3 rebuilds (the
#: first comes at about step 36), the window 10 to 15 steps per rebuild: 3000 steps at 1e3 (~6e6
#: particle-steps), 600 at 1e4, 200 at 1e5 (about 15 rebuilds), 100 at 1e6 (about 8)
SIZES = ((1_000, 100, 3000), (10_000, 100, 600), (100_000, 60, 200), (1_000_000, 50, 100))
QUICK_SIZES = ((1_000, 60, 300), (10_000, 50, 60))
QUICK_LIGGGHTS_MAX = 2_000  # quick mode runs LIGGGHTS and LAMMPS only up to this many disks
REPEATS = 3
PROFILE = (100_000, 60)
QUICK_PROFILE = (10_000, 40)  # the first rebuild comes at about step 37
LIGGGHTS_TIMEOUT = 600.0
#: "a core taken": (nominal disks, warm-up, steps) of the runs beside a spinning process
BUSY = (100_000, 60, 200)
#: the sweep runs the sheared cell at this size only (99,960 disks: the size of its targets)
SHEARED_SIZE = 99_960
QUICK_BUSY = (10_000, 50, 60)

NATIVE_1 = "native 1 thread"  # the bitwise engine (DEMEngine, LIGGGHTS' order)
NATIVE_2 = "native 2 threads"
FAST_1 = "fast 1 thread"  # gransim.dem.fast.FastEngine
FAST_2 = "fast 2 threads"
FAST_LMP_1 = "fast 1 thread LAMMPS arithmetic"  # the orthogonal cell in the sheared cell's arithmetic
FAST_SH_1 = "fast sheared 1 thread"  # FastEngine(cell="sheared"), sheared_assembly
FAST_SH_2 = "fast sheared 2 threads"
LIG_1 = "LIGGGHTS serial"
LIG_2 = "LIGGGHTS np 2"
LMP_1 = "LAMMPS serial"
LMP_2 = "LAMMPS np 2"
#: configuration: (job kind, native mode or MPI processes, threads)
CONFIGS = {
    NATIVE_1: ("native", "serial", 1),
    NATIVE_2: ("native", "parallel", 2),
    FAST_1: ("native", "fast", 1),
    FAST_2: ("native", "fast", 2),
    FAST_LMP_1: ("native", "fast-lammps", 1),
    FAST_SH_1: ("native", "fast-sheared", 1),
    FAST_SH_2: ("native", "fast-sheared", 2),
    LIG_1: ("liggghts", 1, 1),
    LIG_2: ("liggghts", 2, 1),
    LMP_1: ("lammps", 1, 1),
    LMP_2: ("lammps", 2, 1),
}
ALL_CONFIGS = [FAST_1, FAST_2, FAST_LMP_1, FAST_SH_1, FAST_SH_2, NATIVE_1, NATIVE_2, LMP_1, LMP_2, LIG_1, LIG_2]
MIB = 1024.0


def write_bench_deck(job_dir, packing, steps: int, engine: str = "liggghts", warm: int = 0) -> Path:
    """The mirror deck of reference_runs.decks.biaxial (LIGGGHTS or LAMMPS form) without its dump,
    as ``in.bench`` (+ data); with ``warm`` > 0 its ``run STEPS`` becomes ``run WARM`` then
    ``run STEPS`` (the second run's loop time is the steady-state window)."""
    deck = write_biaxial_deck(
        job_dir,
        packing,
        SETTINGS,
        LOADING,
        steps,
        thermo_every=max(steps // 10, 1),
        dump_every=10 * steps,
        engine=engine,
    )
    lines = [ln for ln in deck.read_text().splitlines() if not ln.startswith(("dump ", "dump_modify "))]
    if warm:
        k = max(i for i, ln in enumerate(lines) if ln.startswith("run "))
        lines[k : k + 1] = [f"run {int(warm)}", f"run {int(steps)}"]
    out = Path(job_dir) / "in.bench"
    out.write_text("\n".join(lines) + "\n")
    deck.unlink()
    return out


def _child(*args, timeout: float = 900.0) -> dict:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(":")}
    r = run_child([sys.executable, "-m", "bench._dem_job", *map(str, args)], env=env, cwd=ROOT, timeout=timeout)
    if r.returncode != 0:
        raise RuntimeError(f"bench._dem_job {' '.join(map(str, args))} failed ({r.returncode}):\n{r.stderr[-2000:]}")
    out = json.loads(r.stdout.strip().splitlines()[-1])
    out["whole_s"] = r.wall_s
    out["load"] = os.getloadavg()[0]
    return out


def _rerun(quick: bool) -> str:
    return f"python -m bench --only dem{' --quick' if quick else ''}"


def _spread(xs) -> str:
    return f"median of {len(xs)}, min..max {min(xs):.4g}..{max(xs):.4g}" if len(xs) > 1 else "1 run"


def _sweep(sizes, repeats: int, configs_for, tmp: Path, log) -> dict:
    """{(n, config): [job dicts]} over sizes, repeats and configurations (rotated per repeat)."""
    out = {}
    for nominal, warm, steps in sizes:
        p = assembly(nominal)
        d = tmp / f"n{p.n}"
        d.mkdir()
        np_path = d / "packing.npz"
        np.savez(np_path, positions=p.positions, radii=p.radii, cell=p.cell, density=p.density)
        q = sheared_assembly(nominal)
        np.savez(d / "packing-sheared.npz", positions=q.positions, radii=q.radii, cell=q.cell, density=q.density)
        cfgs = configs_for(p.n)
        for code in ("liggghts", "lammps"):
            if any(CONFIGS[c][0] == code for c in cfgs):
                write_bench_deck(d / code, p, steps, engine=code, warm=warm)
        for k in range(repeats):
            for c in cfgs[k % len(cfgs) :] + cfgs[: k % len(cfgs)]:
                job = _job(c, np_path, d, steps, warm)
                out.setdefault((p.n, c), []).append(job)
                log(
                    f"{c}, {p.n} disks, {steps} steps after {warm}: {job['rate']:.4g} particle-steps/s, "
                    f"{job['rebuilds']} rebuilds, {job['peak_kib'] / MIB:.0f} MiB, whole process "
                    f"{job['whole_s']:.3g} s, load {job['load']:.2f}"
                )
    return out


def _job(c: str, np_path, d: Path, steps: int, warm: int) -> dict:
    kind, a, b = CONFIGS[c]
    if kind == "native":
        if a == "fast-sheared":  # the same assembly in the sheared cell (_sweep writes both)
            np_path = Path(np_path).with_name("packing-sheared.npz")
        job = _child("native", np_path, steps, a, b, warm)
    else:
        job = _child(kind, d / kind, a, LIGGGHTS_TIMEOUT, timeout=LIGGGHTS_TIMEOUT + 60)
        job["peak_kib"] = sum(job["rank_peaks_kib"])
        job["whole_s"] = job["run_job_s"]
    job["rate"] = job["n"] * job["steps"] / job["loop_s"]
    return job


@contextlib.contextmanager
def _spinner():
    """A process spinning on one core for the duration of the block (stopped by its pid)."""
    proc = subprocess.Popen([sys.executable, "-c", "while True: pass"], stdin=subprocess.DEVNULL)
    try:
        time.sleep(0.3)
        yield proc.pid
    finally:
        proc.kill()
        proc.wait()


def _busy_records(size, tmp: Path, log, repeats: int) -> list:
    """Fast and bitwise on 2 threads against 1 thread while another process holds a core."""
    nominal, warm, steps = size
    p = assembly(nominal)
    d = tmp / f"busy{p.n}"
    d.mkdir()
    np_path = d / "packing.npz"
    np.savez(np_path, positions=p.positions, radii=p.radii, cell=p.cell, density=p.density)
    res = {}
    cfgs = [FAST_1, FAST_2] + ([NATIVE_1, NATIVE_2] if repeats > 1 else [])  # quick: the fast path only
    for k in range(repeats):
        for c in cfgs[k % len(cfgs) :] + cfgs[: k % len(cfgs)]:
            with _spinner():
                job = _job(c, np_path, d, steps, warm)
            res.setdefault(c, []).append(job)
            log(
                f"{c} beside a spinning process, {p.n} disks: {job['rate']:.4g} particle-steps/s, "
                f"load {job['load']:.2f}"
            )
    recs = []
    for two, one in ((FAST_2, FAST_1), (NATIVE_2, NATIVE_1)):
        if two not in res:
            continue
        r2 = median(j["rate"] for j in res[two])
        r1 = median(j["rate"] for j in res[one])
        loads = [j["load"] for j in res[two] + res[one]]
        recs.append(
            {
                "name": f"{two} / {one}, one core taken, {p.n:,} disks",
                "value": r2 / r1,
                "unit": "x",
                "target": None,
                "n": p.n,
                "note": f"a spinning process holds a core during each job; {two} {r2:.4g}, "
                f"{one} {r1:.4g} particle-steps/s (medians of {repeats}); 1 = no gain, < 1 = "
                f"the second thread hurts; load {min(loads):.2f}..{max(loads):.2f}; rerun: "
                "python -m bench --only dem",
            }
        )
    return recs


#: (numerator, denominator, target, how it is judged): throughput ratios of the records
RATIOS = (
    (FAST_1, LMP_1, 2.5),
    (NATIVE_1, LMP_1, 1.9),
    (FAST_2, FAST_1, 1.75),
    (FAST_SH_1, FAST_LMP_1, 0.9),  # the cell's cost: the same arithmetic (LAMMPS') on both sides
    (FAST_SH_1, FAST_1, None),
    (FAST_SH_2, FAST_SH_1, 1.75),
    (NATIVE_2, NATIVE_1, None),
    (FAST_1, NATIVE_1, None),
    (FAST_2, LMP_2, None),
    (NATIVE_2, LMP_2, None),
    (NATIVE_1, LIG_1, 1.5),
    (NATIVE_2, LIG_2, None),
    (LMP_1, LIG_1, None),
)
#: flat cost per particle-step: max/min over N at most this (the target: within 20%)
FLAT = 1.2
#: peak memory above baseline: fast path / LAMMPS serial at 1e6 disks at most this
MEMORY_TARGET = 0.6


def _loads(jobs) -> str:
    ls = [j["load"] for j in jobs if "load" in j]
    return f"; load {min(ls):.2f}..{max(ls):.2f}" if ls else ""


def _records(
    res: dict,
    sizes_n,
    configs,
    judge: bool = True,
    baselines: dict | None = None,
    rerun: str = "python -m bench --only dem",
) -> list:
    """Records of the sweep ``res``: throughput, whole-process time, peak memory (raw and above
    ``baselines`` {config: MiB}), the ratios of :data:`RATIOS`, ns per particle-step over N."""
    recs = []
    above = {}
    for n in sizes_n:
        for c in configs:
            jobs = res.get((n, c))
            if not jobs:
                continue
            rates = [j["rate"] for j in jobs]
            steps = jobs[0]["steps"]
            reb = sorted({j["rebuilds"] for j in jobs})
            warm = jobs[0].get("warm")
            recs.append(
                {
                    "name": f"{c}, {n:,} disks",
                    "value": median(rates),
                    "unit": "particle-steps/s",
                    "target": None,
                    "n": n,
                    "samples": rates,
                    "note": f"{_spread(rates)}; {steps} steps"
                    + (f" after {warm} warm-up steps" if warm else "")
                    + f", loop time only (set-up excluded); neighbour rebuilds in the window "
                    f"{'/'.join(map(str, reb))}"
                    + (f"; contacts {jobs[0]['contacts']}" if "contacts" in jobs[0] else "")
                    + _loads(jobs)
                    + f"; rerun: {rerun}",
                }
            )
            if all("whole_s" in j for j in jobs):
                whole = [j["whole_s"] for j in jobs]
                recs.append(
                    {
                        "name": f"{c} whole process, {n:,} disks",
                        "value": median(whole),
                        "unit": "s",
                        "target": None,
                        "n": n,
                        "samples": whole,
                        "note": f"{_spread(whole)}; wall time of the job's process from start to exit "
                        f"(loop {median(j['loop_s'] for j in jobs):.3g} s of it)" + _loads(jobs),
                    }
                )
            mem = [j["peak_kib"] / MIB for j in jobs]
            if CONFIGS[c][0] == "native":
                how = "VmHWM of the job's process (includes the baseline: interpreter, numba, kernels)"
            else:
                ranks = [max(j["rank_peaks_kib"], default=0) / MIB for j in jobs]
                code = CONFIGS[c][0]
                how = (
                    f"VmHWM of the {'lmp' if code == 'lammps' else 'liggghts'} process"
                    if CONFIGS[c][1] == 1
                    else f"sum of the VmHWM of the {CONFIGS[c][1]} ranks (largest rank {median(ranks):.0f} MiB)"  # noqa: E501
                )
                how += (
                    f", sampled at 20 Hz (lower bound); {'LAMMPS' if code == 'lammps' else 'LIGGGHTS'}' own "
                    f"estimate {jobs[0]['memory_mb_estimate']} MB per process"
                )
                short = [len(j["rank_peaks_kib"]) for j in jobs if len(j["rank_peaks_kib"]) != CONFIGS[c][1]]
                if short:
                    how += f"; WARNING: only {short} of {CONFIGS[c][1]} processes sampled in some runs"
            recs.append(
                {
                    "name": f"{c} peak memory, {n:,} disks",
                    "value": median(mem),
                    "unit": "MiB",
                    "target": None,
                    "n": n,
                    "samples": mem,
                    "note": f"{_spread(mem)}; {how}",
                }
            )
            if baselines and c in baselines:
                v = median(mem) - baselines[c]
                above[(n, c)] = v
                what = (
                    "the same process without packing"
                    if CONFIGS[c][0] == "native"
                    else "the code on the smallest assembly"
                )
                recs.append(
                    {
                        "name": f"{c} peak memory above baseline, {n:,} disks",
                        "value": v,
                        "unit": "MiB",
                        "target": None,
                        "n": n,
                        "note": f"median peak {median(mem):.0f} MiB minus the baseline {baselines[c]:.0f} MiB ({what})",
                    }
                )
        for num, den, target in RATIOS:
            a, b = res.get((n, num)), res.get((n, den))
            if not a or not b:
                continue
            ratio = median(j["rate"] for j in a) / median(j["rate"] for j in b)
            paired = [x["rate"] / y["rate"] for x, y in zip(a, b)]
            recs.append(
                {
                    "name": f"{num} / {den}, {n:,} disks",
                    "value": ratio,
                    "unit": "x",
                    "target": target,
                    "meets": None if target is None or not judge else ratio >= target,
                    "n": n,
                    "note": f"ratio of medians; per-repeat ratios {min(paired):.3g}..{max(paired):.3g}"
                    + _loads(a + b)
                    + f"; rerun: {rerun}",
                }
            )
        if (n, FAST_1) in above and (n, LMP_1) in above and above[(n, LMP_1)] > 0:
            v = above[(n, FAST_1)] / above[(n, LMP_1)]
            big = n >= 500_000
            recs.append(
                {
                    "name": f"{FAST_1} / {LMP_1} peak memory above baseline, {n:,} disks",
                    "value": v,
                    "unit": "x",
                    "target": MEMORY_TARGET if big else None,
                    "meets": (v <= MEMORY_TARGET) if big and judge else None,
                    "n": n,
                    "note": f"{above[(n, FAST_1)]:.0f} MiB against {above[(n, LMP_1)]:.0f} MiB "
                    f"(target: at most {MEMORY_TARGET} at 1e6 disks)",
                }
            )
    for c in configs:
        pts = [(n, 1e9 / median(j["rate"] for j in res[(n, c)])) for n in sizes_n if (n, c) in res]
        if not pts:
            continue
        ys = [y for _, y in pts]
        recs.append(
            {
                "name": f"{c}: ns per particle-step",
                "value": ys[-1],
                "unit": "ns/particle-step",
                "target": None,
                "n": pts[-1][0],
                "series": pts,
                "note": f"value at {pts[-1][0]:,} disks; series over N = "
                + ", ".join(f"{n:,}: {y:.0f}" for n, y in pts)
                + f"; max/min over N {max(ys) / min(ys):.2f} (flat = 1); wall-clock time, "
                "not per core",
            }
        )
        if len(pts) > 1:
            flat = max(ys) / min(ys)
            full = pts[0][0] <= 2_000 and pts[-1][0] >= 500_000
            recs.append(
                {
                    "name": f"{c}: ns per particle-step, max/min over N",
                    "value": flat,
                    "unit": "x",
                    "target": FLAT if full else None,
                    "meets": (flat <= FLAT) if full and judge else None,
                    "n": pts[-1][0],
                    "note": f"over N = {pts[0][0]:,}..{pts[-1][0]:,} (target: at most {FLAT} from "
                    "1e3 to 1e6 at equal rebuild rates)",
                }
            )
    return recs


def stream_triad(n: int = 20_000_000, repeats: int = 5) -> float:
    """Memory bandwidth of this machine (bytes/s) by a numpy triad a = b + s c on float64 arrays
    of ``n`` elements (3 x 8 n bytes moved per pass, the write-allocate of ``a`` not counted; best
    of ``repeats``; one core)."""
    b = np.ones(n)
    c = np.full(n, 2.0)
    a = np.empty(n)
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        np.multiply(c, 3.0, out=a)
        np.add(a, b, out=a)
        best = min(best, time.perf_counter() - t0)
    # the two numpy passes move 2 x 2 x 8 n bytes (c read + a written, then a and b read + a
    # written: 5 x 8 n); count the 5 streams actually moved
    return 5 * 8 * n / best


#: bytes the fast path moves per particle-step from memory (its arrays beyond the caches), by
#: pass: force loop, per particle 7 float64 read (x, y, vx, vy, w, r, m), start (int32), fx, fy, t
#: read and written; per list entry nj (int32) + image code (uint8) read, the spring (2 float64)
#: read and written; fused pass 12 float64 read, 8 written. The partners' gathers are cache hits
#: (bin order) and not counted.
def fast_bytes_per_particle_step(entries_per_particle: float) -> float:
    # per entry: owner i and partner j (int32), image code, spring read and written (2 x 16)
    return 7 * 8 + 4 + 3 * 16 + entries_per_particle * (4 + 4 + 1 + 32) + 12 * 8 + 8 * 8


def _bandwidth_records(res: dict, sizes_n) -> list:
    bw = stream_triad()
    recs = [
        {
            "name": "stream bandwidth (numpy triad, 1 core)",
            "value": bw / 1e9,
            "unit": "GB/s",
            "target": None,
            "note": f"a = 3 c, a += b on 2e7 float64 (5 streams of 160 MB), best of 5; load "
            f"{os.getloadavg()[0]:.2f}; bench.dem.stream_triad",
        }
    ]
    big = [n for n in sizes_n if (n, FAST_1) in res and "entries" in res[(n, FAST_1)][0]]
    if big:
        n = big[-1]
        jobs = res[(n, FAST_1)]
        e = jobs[0]["entries"] / n
        byt = fast_bytes_per_particle_step(e)
        floor = byt / bw * 1e9
        meas = 1e9 / median(j["rate"] for j in jobs)
        recs.append(
            {
                "name": f"fast 1 thread: memory-bound floor, {n:,} disks",
                "value": floor,
                "unit": "ns/particle-step",
                "target": None,
                "n": n,
                "note": f"{byt:.0f} bytes per particle-step ({e:.2f} list entries per particle; "
                f"bench.dem.fast_bytes_per_particle_step) at {bw / 1e9:.1f} GB/s; measured "
                f"{meas:.0f} ns/particle-step, {meas / floor:.1f}x the floor: the kernel is "
                "bound by the arithmetic latency of the pair law (sqrt, 3 divisions per "
                "entry), not by memory",
            }
        )
    return recs


def _profile_records(prof: dict, res: dict, n_lig: int | None) -> list:
    recs = []
    n = prof["n"]
    total = prof["replay_s"]
    ph = dict(prof["phases_s"])
    ph["other (Python calls between kernels, stress, timers)"] = total - sum(ph.values())
    per_reb = (
        f"{prof['phases_s']['rebuild'] / prof['rebuilds'] * 1e3:.3g} ms each"
        if prof["rebuilds"]
        else "none in this window"
    )
    common = (
        f"native 1 thread, {prof['steps']} steps replayed phase by phase from the engine's kernels; "
        f"replay {total:.3g} s vs advance {prof['advance_s']:.3g} s, final state bitwise equal: "
        f"{'yes' if prof['identical'] else 'NO'}; {prof['rebuilds']} rebuilds ({per_reb}); one step "
        f"{1e3 * (total - prof['phases_s']['rebuild']) / prof['steps']:.3g} ms without rebuilds"
    )
    for name, sec in ph.items():
        recs.append(
            {
                "name": f"native profile, {n:,} disks: {name}",
                "value": 100 * sec / total,
                "unit": "% of loop",
                "target": None,
                "note": common,
            }
        )
    for c in (LIG_1, LIG_2, LMP_1, LMP_2):
        jobs = res.get((n_lig, c)) if n_lig is not None else None
        if not jobs:
            continue
        for part in jobs[0]["breakdown"]:
            pct = [100 * j["breakdown"][part] / j["loop_s"] for j in jobs]
            note = (
                "LAMMPS' timing table (average over ranks), "
                if CONFIGS[c][0] == "lammps"
                else "LIGGGHTS' timing breakdown (process 0), "
            )
            note += _spread(pct) + (
                "; Modify = integrator and fixes"
                if CONFIGS[c][0] == "lammps"
                else "; Other = integrator and fixes (no Modify line in 3.8.0)"
            )
            recs.append(
                {
                    "name": f"{c} profile, {n_lig:,} disks: {part}",
                    "value": median(pct),
                    "unit": "% of loop",
                    "target": None,
                    "note": note,
                }
            )
    return recs


def run(quick: bool = False) -> list[dict]:
    def log(msg):
        print(f"[bench dem] {msg}", flush=True)

    have_lig = shutil.which("liggghts") is not None
    have_lmp = shutil.which("lmp") is not None
    have_mpi = shutil.which("mpirun") is not None
    sizes = QUICK_SIZES if quick else SIZES
    repeats = 1 if quick else REPEATS

    def configs_for(n):
        cfg = [FAST_1, FAST_2, NATIVE_1, NATIVE_2]
        if quick or n == SHEARED_SIZE:  # the sheared cell at 1e5 disks (its targets' size)
            cfg[2:2] = [FAST_LMP_1, FAST_SH_1, FAST_SH_2]
        if not quick or n <= QUICK_LIGGGHTS_MAX:
            for have, serial, par in ((have_lmp, LMP_1, LMP_2), (have_lig, LIG_1, LIG_2)):
                if have:
                    cfg.append(serial)
                    if have_mpi:
                        cfg.append(par)
        return cfg

    load0 = os.getloadavg()
    recs = []
    baselines = {}
    # numba's cache filled, not timed: every variant the baselines below load (the fast path's
    # serial and threaded kernels differ), else a baseline that compiles peaks above its job
    variants = (("serial", 1), ("parallel", 2), ("fast", 1), ("fast", 2), ("fast-lammps", 1), ("fast-sheared", 1))
    for mode, threads in variants:
        _child("baseline", mode, threads)
    bases = (
        (("serial", 1, NATIVE_1), ("fast", 1, FAST_1))
        if quick
        else (("serial", 1, NATIVE_1), ("parallel", 2, NATIVE_2), ("fast", 1, FAST_1), ("fast", 2, FAST_2))
    )
    for mode, threads, c in bases:
        base = [_child("baseline", mode, threads)["peak_kib"] / MIB for _ in range(1 if quick else 2)]
        baselines[c] = median(base)
        recs.append(
            {
                "name": f"{c} baseline peak memory (no packing)",
                "value": median(base),
                "unit": "MiB",
                "target": None,
                "note": "the native job's process with its imports (numpy, numba, gransim.dem), kernels loaded "
                "from the numba cache and the 110-disk warm-up, before its packing; included in every "
                f"native memory figure; {_spread(base)}",
            }
        )
    if quick:  # quick: the 2-thread jobs are measured against the 1-thread baselines
        baselines[NATIVE_2], baselines[FAST_2] = baselines[NATIVE_1], baselines[FAST_1]
    if not have_lig:
        recs.append(
            {
                "name": "LIGGGHTS comparison",
                "value": 0,
                "unit": "runs",
                "target": None,
                "note": "liggghts not on PATH: LIGGGHTS records omitted (apt-get install liggghts)",
            }
        )
    if not have_lmp:
        recs.append(
            {
                "name": "LAMMPS comparison",
                "value": 0,
                "unit": "runs",
                "target": None,
                "note": "lmp not on PATH: LAMMPS records omitted (apt-get install lammps)",
            }
        )
    if (have_lig or have_lmp) and not have_mpi:
        recs.append(
            {
                "name": "np 2 runs",
                "value": 0,
                "unit": "runs",
                "target": None,
                "note": "mpirun not on PATH: LIGGGHTS and LAMMPS np 2 records omitted",
            }
        )
    with tempfile.TemporaryDirectory(prefix="bench-dem-") as tmp:
        res = _sweep(sizes, repeats, configs_for, Path(tmp), log)
        sizes_n = sorted({n for n, _ in res})
        for c in (LIG_1, LIG_2, LMP_1, LMP_2):  # a code's baseline: its peak on the smallest assembly
            small = [n for n in sizes_n if (n, c) in res]
            if small:
                baselines[c] = median(j["peak_kib"] / MIB for j in res[(small[0], c)])
        recs += _records(res, sizes_n, ALL_CONFIGS, judge=not quick, baselines=baselines, rerun=_rerun(quick))
        recs += _busy_records(QUICK_BUSY if quick else BUSY, Path(tmp), log, repeats)
        recs += _bandwidth_records(res, sizes_n)
        nominal, steps = QUICK_PROFILE if quick else PROFILE
        p = assembly(nominal)
        pk = Path(tmp) / "profile.npz"
        np.savez(pk, positions=p.positions, radii=p.radii, cell=p.cell, density=p.density)
        prof = _child("profile", pk, steps)
        lig_n = [n for n in sizes_n if any((n, c) in res for c in (LIG_1, LIG_2, LMP_1, LMP_2))]
        n_lig = p.n if p.n in lig_n else (max(lig_n) if lig_n else None)
        recs += _profile_records(prof, res, n_lig)
    load1 = os.getloadavg()
    recs.append(
        {
            "name": "machine load during the DEM benchmark",
            "value": load1[0],
            "unit": "load average",
            "target": None,
            "note": f"1-minute load average at the end {load1[0]:.2f} (5-minute {load1[1]:.2f}), at the start "
            f"{load0[0]:.2f}, on {os.cpu_count()} cores: above the benchmark's own 1 to 2 processes, "
            "other jobs shared the cores",
        }
    )
    return recs


def sweep(nominal_sizes, configs, repeats: int = 1) -> list[dict]:
    """The records of a partial sweep: the sizes of :data:`SIZES` nearest to ``nominal_sizes``
    and the configurations ``configs`` (names of :data:`CONFIGS`), interleaved as in :func:`run`;
    the baselines as :func:`run` measures them (a code's on the 1,020-disk deck)."""
    unknown = [c for c in configs if c not in CONFIGS]
    if unknown:
        raise SystemExit(f"--configs: unknown {unknown}; known: {list(CONFIGS)}")
    sizes = [min(SIZES, key=lambda t: abs(math.log(t[0] / float(n)))) for n in nominal_sizes]

    def log(msg):
        print(f"[bench dem] {msg}", flush=True)

    base = {}
    for c in configs:
        kind, a, b = CONFIGS[c]
        if kind == "native":
            _child("baseline", a, b)  # numba's cache filled
            base[c] = _child("baseline", a, b)["peak_kib"] / MIB
    with tempfile.TemporaryDirectory(prefix="bench-dem-") as tmp:
        res = _sweep(sizes, repeats, lambda n: list(configs), Path(tmp), log)
        codes = [c for c in configs if CONFIGS[c][0] != "native"]
        if codes:
            (Path(tmp) / "small").mkdir()
            small = _sweep(((SIZES[0][0], 60, 300),), 1, lambda n: codes, Path(tmp) / "small", log)
            for c in codes:
                base[c] = small[(min(n for n, _ in small), c)][0]["peak_kib"] / MIB
        return _records(res, sorted({n for n, _ in res}), list(configs), baselines=base)


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(prog="python -m bench.dem", description="a partial DEM sweep (bench/dem.py)")
    ap.add_argument("--sizes", help="nominal disk counts, comma-separated (default: the whole run())")
    ap.add_argument("--configs", default=",".join(ALL_CONFIGS), help="configurations, comma-separated")
    ap.add_argument("--repeats", type=int, default=REPEATS)
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    if args.sizes:
        recs = sweep([float(x) for x in args.sizes.split(",")], args.configs.split(","), args.repeats)
    else:
        recs = run(quick=args.quick)
    sys.exit(print_records(recs))  # a NaN or inf figure: printed as NaN (FAIL), exit 1
