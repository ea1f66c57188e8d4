"""DEM throughput and memory: native gransim (1 thread, 2 threads) vs LIGGGHTS 3.8.0 and LAMMPS
(29 Sep 2021, Debian ``lammps``), each serial and ``mpirun -np 2``, on the same assembly, contact
law and number of steps, at about 1e3, 1e4, 1e5 and 1e6 disks.

LAMMPS runs the LAMMPS form of the same deck (``write_biaxial_deck(..., engine="lammps")``:
``pair_style gran/hooke/history`` with the same kn, kt, dampings and friction, 2D masses by
``set density/disc``, ``fix nve/sphere disc``, sorting off, ``newton off``), timed by its own
``Loop time of`` like LIGGGHTS; its memory is the VmHWM of the ``lmp`` processes, and its profile
is its ``Pair/Neigh/Comm/Output/Modify/Other`` table (average over ranks).

What is timed. LIGGGHTS prints ``Loop time of``: the wall time of its step loop, after the run's
set-up (data file read, first neighbour build, ghost exchange, first forces) and without it. The
native job is timed the same way: :class:`gransim.dem.DEMEngine` construction (its set-up: first
list build and forces) is outside the timer, ``advance(steps)`` inside; both loops include their
neighbour rebuilds (the same rule, so the same rebuild steps in serial) and their per-step output
(LIGGGHTS: thermo every steps/10 with a ``compute pressure``; native: stress etc. every step).
Throughput = N * steps / loop time, in particle-steps per second.

How. Every measured job runs in its own process (bench/_dem_job.py), so its peak memory is its
own: native jobs report their VmHWM (interpreter, numba, kernels, warm-up, packing, engine; the
bare interpreter + numba + kernels is recorded separately as the baseline), LIGGGHTS jobs the
VmHWM of each ``liggghts`` process sampled at 20 Hz (np 2: the sum over both ranks; the largest
rank is in the note). The four configurations are interleaved within each repeat (the order
rotates), because the 2 cores are shared; records give the median over repeats with min..max.
LIGGGHTS runs through ``reference_runs.runner.run_job`` (np 2: ``mpirun -np 2``; LIGGGHTS splits
the 2D box 2 by 1 by itself, no ``processors`` command needed).

Assembly: jittered triangular lattice of polydisperse disks overlapping ~8% of a radius
(coordination ~4.9, gransim.dem.lattice) relaxing in a fixed periodic box (sizes are the nearest
lattice: 1,020, 10,058, 99,960, 999,750 disks), kn = kt = 1e5 N/m, damping and friction on,
LIGGGHTS deck of reference_runs.decks.biaxial (sorting off, ``newton off``) without its dump.
Targets: native 1 thread >= 1.5 x LIGGGHTS serial; ns per particle-step flat in N.
Also a profile at 1e5 disks: native phases (forces, integration, rebuilds) and LIGGGHTS' own
Pair/Neigh/Comm/Outpt/Other breakdown at np 1 and np 2.

Run: ``python -m bench --only dem [--quick]`` (quick: 1 repeat, small sizes, LIGGGHTS and LAMMPS
only at 1,020 disks, no timing judged); absent LIGGGHTS, LAMMPS or mpirun only drops their records
(noted). ``make bench`` runs the whole suite.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import statistics
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from gransim.dem import DEMSettings, Loading  # noqa: E402
from gransim.dem.lattice import lattice_packing  # noqa: E402

SETTINGS = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
# fixed box: under a strain rate or servo the box displacement eats the skin (LIGGGHTS' rebuild
# rule) faster in larger boxes, so rebuilds per step would grow with N in both codes alike
LOADING = Loading()

#: (nominal disks, steps): 6e6 particle-steps (about 1 s of LIGGGHTS serial) up to 1e5; at 1e6 the
#: same 60 steps as at 1e5 (LIGGGHTS serial: 11 s loop + 3 s set-up). From rest the first rebuild
#: comes at about step 36 and then every 10 to 15 steps: 60 steps hold 2 rebuilds at 1e5 and 1e6,
#: the longer small-N runs relatively more (rebuild counts are in the notes)
SIZES = ((1_000, 6000), (10_000, 600), (100_000, 60), (1_000_000, 60))
QUICK_SIZES = ((1_000, 300), (10_000, 30))
QUICK_LIGGGHTS_MAX = 2_000  # quick mode runs LIGGGHTS and LAMMPS only up to this many disks
REPEATS = 3
PROFILE = (100_000, 60)
QUICK_PROFILE = (10_000, 40)  # the first rebuild comes at about step 37
LIGGGHTS_TIMEOUT = 300.0

NATIVE_1 = "native 1 thread"
NATIVE_2 = "native 2 threads"
LIG_1 = "LIGGGHTS serial"
LIG_2 = "LIGGGHTS np 2"
LMP_1 = "LAMMPS serial"
LMP_2 = "LAMMPS np 2"
#: configuration: (job kind, native mode or MPI processes, threads)
CONFIGS = {NATIVE_1: ("native", "serial", 1), NATIVE_2: ("native", "parallel", 2),
           LIG_1: ("liggghts", 1, 1), LIG_2: ("liggghts", 2, 1),
           LMP_1: ("lammps", 1, 1), LMP_2: ("lammps", 2, 1)}
ALL_CONFIGS = [NATIVE_1, NATIVE_2, LIG_1, LIG_2, LMP_1, LMP_2]
MIB = 1024.0


def assembly(n: int):
    """The benchmark assembly nearest to ``n`` disks (triangular lattice, even rows)."""
    nx = max(3, round(math.sqrt(n * 2 / math.sqrt(3))))
    ny = max(4, round(n / nx))
    ny += ny % 2
    return lattice_packing(nx, ny, seed=1, spread=0.1, compression=0.08)


def write_bench_deck(job_dir, packing, steps: int, engine: str = "liggghts") -> Path:
    """The mirror deck of reference_runs.decks.biaxial (LIGGGHTS or LAMMPS form) without its dump,
    as ``in.bench`` (+ data)."""
    from reference_runs.decks.biaxial import write_biaxial_deck

    deck = write_biaxial_deck(job_dir, packing, SETTINGS, LOADING, steps, thermo_every=max(steps // 10, 1),
                              dump_every=10 * steps, engine=engine)
    lines = [ln for ln in deck.read_text().splitlines() if not ln.startswith(("dump ", "dump_modify "))]
    out = Path(job_dir) / "in.bench"
    out.write_text("\n".join(lines) + "\n")
    deck.unlink()
    return out


def _child(*args, timeout: float = 900.0) -> dict:
    from bench._memory import run_child

    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(":")}
    r = run_child([sys.executable, "-m", "bench._dem_job", *map(str, args)], env=env, cwd=ROOT, timeout=timeout)
    if r.returncode != 0:
        raise RuntimeError(f"bench._dem_job {' '.join(map(str, args))} failed ({r.returncode}):\n{r.stderr[-2000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def _spread(xs) -> str:
    return f"median of {len(xs)}, min..max {min(xs):.4g}..{max(xs):.4g}" if len(xs) > 1 else "1 run"


def _sweep(sizes, repeats: int, configs_for, tmp: Path, log) -> dict:
    """{(n, config): [job dicts]} over sizes, repeats and configurations (rotated per repeat)."""
    out = {}
    for nominal, steps in sizes:
        p = assembly(nominal)
        d = tmp / f"n{p.n}"
        d.mkdir()
        np_path = d / "packing.npz"
        np.savez(np_path, positions=p.positions, radii=p.radii, cell=p.cell, density=p.density)
        cfgs = configs_for(p.n)
        for code in ("liggghts", "lammps"):
            if any(CONFIGS[c][0] == code for c in cfgs):
                write_bench_deck(d / code, p, steps, engine=code)
        for k in range(repeats):
            for c in cfgs[k % len(cfgs):] + cfgs[:k % len(cfgs)]:
                kind, a, b = CONFIGS[c]
                if kind == "native":
                    job = _child("native", np_path, steps, a, b)
                else:
                    job = _child(kind, d / kind, a, LIGGGHTS_TIMEOUT, timeout=LIGGGHTS_TIMEOUT + 60)
                    job["peak_kib"] = sum(job["rank_peaks_kib"])
                job["rate"] = job["n"] * job["steps"] / job["loop_s"]
                out.setdefault((p.n, c), []).append(job)
                log(f"{c}, {p.n} disks, {steps} steps: {job['rate']:.4g} particle-steps/s, "
                    f"{job['peak_kib'] / MIB:.0f} MiB")
    return out


def _records(res: dict, sizes_n, configs, judge: bool = True) -> list:
    recs = []
    for n in sizes_n:
        for c in configs:
            jobs = res.get((n, c))
            if not jobs:
                continue
            rates = [j["rate"] for j in jobs]
            steps = jobs[0]["steps"]
            reb = sorted({j["rebuilds"] for j in jobs})
            recs.append({"name": f"{c}, {n:,} disks", "value": statistics.median(rates), "unit": "particle-steps/s",
                         "target": None, "n": n, "samples": rates,
                         "note": f"{_spread(rates)}; {steps} steps, loop time only (set-up excluded); "
                                 f"neighbour rebuilds {'/'.join(map(str, reb))}"
                                 + (f"; contacts {jobs[0]['contacts']}" if "contacts" in jobs[0] else "")})
            mem = [j["peak_kib"] / MIB for j in jobs]
            if CONFIGS[c][0] == "native":
                how = "VmHWM of the job's process (includes the baseline: interpreter, numba, kernels)"
            else:
                ranks = [max(j["rank_peaks_kib"], default=0) / MIB for j in jobs]
                code = CONFIGS[c][0]
                how = (f"VmHWM of the {'lmp' if code == 'lammps' else 'liggghts'} process" if CONFIGS[c][1] == 1 else
                       f"sum of the VmHWM of the {CONFIGS[c][1]} ranks (largest rank {statistics.median(ranks):.0f} MiB)")
                how += (f", sampled at 20 Hz (lower bound); {'LAMMPS' if code == 'lammps' else 'LIGGGHTS'}' own "
                        f"estimate {jobs[0]['memory_mb_estimate']} MB per process")
                short = [len(j["rank_peaks_kib"]) for j in jobs if len(j["rank_peaks_kib"]) != CONFIGS[c][1]]
                if short:
                    how += f"; WARNING: only {short} of {CONFIGS[c][1]} processes sampled in some runs"
            recs.append({"name": f"{c} peak memory, {n:,} disks", "value": statistics.median(mem), "unit": "MiB",
                         "target": None, "n": n, "samples": mem, "note": f"{_spread(mem)}; {how}"})
        for num, den, target in ((NATIVE_1, LIG_1, 1.5), (NATIVE_2, LIG_2, None), (NATIVE_1, LMP_1, None),
                                 (NATIVE_2, LMP_2, None), (LMP_1, LIG_1, None)):
            a, b = res.get((n, num)), res.get((n, den))
            if not a or not b:
                continue
            ratio = statistics.median(j["rate"] for j in a) / statistics.median(j["rate"] for j in b)
            paired = [x["rate"] / y["rate"] for x, y in zip(a, b)]
            recs.append({"name": f"{num} / {den}, {n:,} disks", "value": ratio, "unit": "x", "target": target,
                         "meets": None if target is None or not judge else ratio >= target, "n": n,
                         "note": f"ratio of medians; per-repeat ratios {min(paired):.3g}..{max(paired):.3g}"})
    for c in configs:
        pts = [(n, 1e9 / statistics.median(j["rate"] for j in res[(n, c)])) for n in sizes_n if (n, c) in res]
        if not pts:
            continue
        ys = [y for _, y in pts]
        recs.append({"name": f"{c}: ns per particle-step", "value": ys[-1], "unit": "ns/particle-step",
                     "target": None, "n": pts[-1][0], "series": pts,
                     "note": f"value at {pts[-1][0]:,} disks; series over N = "
                             + ", ".join(f"{n:,}: {y:.0f}" for n, y in pts)
                             + f"; max/min over N {max(ys) / min(ys):.2f} (flat = 1); wall-clock time, "
                               "not per core"})
    return recs


def _profile_records(prof: dict, res: dict, n_lig: int | None) -> list:
    recs = []
    n = prof["n"]
    total = prof["replay_s"]
    ph = dict(prof["phases_s"])
    ph["other (Python calls between kernels, stress, timers)"] = total - sum(ph.values())
    per_reb = (f"{prof['phases_s']['rebuild'] / prof['rebuilds'] * 1e3:.3g} ms each" if prof["rebuilds"]
               else "none in this window")
    common = (f"native 1 thread, {prof['steps']} steps replayed phase by phase from the engine's kernels; "
              f"replay {total:.3g} s vs advance {prof['advance_s']:.3g} s, final state bitwise equal: "
              f"{'yes' if prof['identical'] else 'NO'}; {prof['rebuilds']} rebuilds ({per_reb}); one step "
              f"{1e3 * (total - prof['phases_s']['rebuild']) / prof['steps']:.3g} ms without rebuilds")
    for name, sec in ph.items():
        recs.append({"name": f"native profile, {n:,} disks: {name}", "value": 100 * sec / total, "unit": "% of loop",
                     "target": None, "note": common})
    for c in (LIG_1, LIG_2, LMP_1, LMP_2):
        jobs = res.get((n_lig, c)) if n_lig is not None else None
        if not jobs:
            continue
        for part in jobs[0]["breakdown"]:
            pct = [100 * j["breakdown"][part] / j["loop_s"] for j in jobs]
            note = ("LAMMPS' timing table (average over ranks), " if CONFIGS[c][0] == "lammps" else
                    "LIGGGHTS' timing breakdown (process 0), ")
            note += _spread(pct) + ("; Modify = integrator and fixes" if CONFIGS[c][0] == "lammps" else
                                    "; Other = integrator and fixes (no Modify line in 3.8.0)")
            recs.append({"name": f"{c} profile, {n_lig:,} disks: {part}", "value": statistics.median(pct),
                         "unit": "% of loop", "target": None, "note": note})
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
        cfg = [NATIVE_1, NATIVE_2]
        if not quick or n <= QUICK_LIGGGHTS_MAX:
            for have, serial, par in ((have_lig, LIG_1, LIG_2), (have_lmp, LMP_1, LMP_2)):
                if have:
                    cfg.append(serial)
                    if have_mpi:
                        cfg.append(par)
        return cfg

    load0 = os.getloadavg()
    recs = []
    for mode, threads, c in (("serial", 1, NATIVE_1), ("parallel", 2, NATIVE_2)):
        base = [_child("baseline", mode, threads)["peak_kib"] / MIB for _ in range(1 if quick else 2)]
        recs.append({"name": f"{c} baseline peak memory (no packing)", "value": statistics.median(base),
                     "unit": "MiB", "target": None,
                     "note": "the native job's process with its imports (numpy, numba, gransim.dem), kernels loaded "
                             "from the numba cache and the 110-disk warm-up, before its packing; included in every "
                             f"native memory figure; {_spread(base)}"})
    if not have_lig:
        recs.append({"name": "LIGGGHTS comparison", "value": 0, "unit": "runs", "target": None,
                     "note": "liggghts not on PATH: LIGGGHTS records omitted (apt-get install liggghts)"})
    if not have_lmp:
        recs.append({"name": "LAMMPS comparison", "value": 0, "unit": "runs", "target": None,
                     "note": "lmp not on PATH: LAMMPS records omitted (apt-get install lammps)"})
    if (have_lig or have_lmp) and not have_mpi:
        recs.append({"name": "np 2 runs", "value": 0, "unit": "runs", "target": None,
                     "note": "mpirun not on PATH: LIGGGHTS and LAMMPS np 2 records omitted"})
    with tempfile.TemporaryDirectory(prefix="bench-dem-") as tmp:
        res = _sweep(sizes, repeats, configs_for, Path(tmp), log)
        sizes_n = sorted({n for n, _ in res})
        recs += _records(res, sizes_n, ALL_CONFIGS, judge=not quick)
        nominal, steps = QUICK_PROFILE if quick else PROFILE
        p = assembly(nominal)
        pk = Path(tmp) / "profile.npz"
        np.savez(pk, positions=p.positions, radii=p.radii, cell=p.cell, density=p.density)
        prof = _child("profile", pk, steps)
        lig_n = [n for n in sizes_n if any((n, c) in res for c in (LIG_1, LIG_2, LMP_1, LMP_2))]
        n_lig = p.n if p.n in lig_n else (max(lig_n) if lig_n else None)
        recs += _profile_records(prof, res, n_lig)
    load1 = os.getloadavg()
    recs.append({"name": "machine load during the DEM benchmark", "value": load1[0], "unit": "load average",
                 "target": None,
                 "note": f"1-minute load average at the end {load1[0]:.2f} (5-minute {load1[1]:.2f}), at the start "
                         f"{load0[0]:.2f}, on {os.cpu_count()} cores: above the benchmark's own 1 to 2 processes, "
                         "other jobs shared the cores"})
    return recs


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        tgt = "" if r["target"] is None else f"  (target {r['target']})"
        print(f"{r['name']:56s} {r['value']:12.4g} {r['unit']}{tgt}  [{r['note']}]")
