"""Benchmark of FEM x DEM (``gransim femxdem --rve dem``): the RVE call, and where a run's time goes.

``python -m bench.femxdem [--full] [--calls 60] [--workers 2] [--steps K] [--skip-run] [--tangent T]``,
``python -m bench.femxdem --base REV [--windows 12] [--window 10] [--iterates 1]``,
``python -m bench.femxdem --tangent-study H,H,... [--steps 40] [--mesh 1x1] [--start CHECKPOINT]``

1. **The RVE call** (in this process, compilation excluded: a warm-up call first). Guo & Zhao's
   400-disk RVE (the prepared state of ``gransim/fem/data/guo_zhao_rve.h5``) driven by a chain of
   ``--calls`` strain increments of a biaxial load step (max|D| = 1e-3: ns = 100 DEM steps a call),
   each call from the state the last one left, made read-only as a Gauss point's committed state.
   Per call, medians and minima (ms; CPU time of this process, and wall time for the first
   update): ``DemRVE.update`` (what a worker runs: the call, then the stress and tangent) as the
   first Newton iterate of a load step runs it (the set-up computed, then kept) and as the later
   iterates run it (the set-up restored), and the parts of ``rve_run_rotation`` on the one engine
   (:mod:`gransim.dem.yade_cell`): loading the saved scene into the thread's engine with its
   set-up computed (``rve_engine``: ``Engine.restore`` of the scene, the container filled, step 0's
   cell update, the collider's first run, i.e. the initial sort a deserialised scene needs and
   findOverlaps, and the interaction loop), ``start_run(VelGradRun)``, ``advance(ns)`` (the
   engine's step loop ``Engine._run``) of which the compiled steps (the cell's block, the kernel
   ``rve_block``: one jitted call), and the saved scene (``YadeCell.scene``); per DEM step = the
   kernel / ns, split into the interaction loop and the integrator (each run 100 times in one
   compiled loop). Rates in particle-steps/s: the call's (N ns / call time) and the steady state
   (N / per-step time).
2. **A short run** ``run_femxdem`` (default the quick 2 x 4 mesh, 10 steps; ``--full``: the 8 x 16
   mesh of the full benchmark, ``--steps`` (default 2) load steps) on ``--workers`` Dask workers
   (0: in process), with its wall time split: **DEM** = the time in the point law's updates summed
   over the chunks, measured on the workers (``GaussChunk.timing``); its share = DEM / (workers x
   wall of the steps); the driver's wait for the Gauss points (``material_s``), the FE work
   (``wall_s - material_s`` per step: assembly, solve, the predictor), and the rest (checkpoints,
   field outputs). Overhead = 1 - DEM share (Dask, serialisation, FE, idle workers while the
   other finishes its chunk).
3. ``--base REV``: the RVE call of commit REV against this checkout, interleaved in one run (two
   long-lived processes, one per tree, each with its own numba cache, asked in turn A B B A ... for
   windows of ``--window`` states of the same chain, each updated ``--iterates`` times from the
   read-only state as the Newton iterates of a load step do): median of the per-window
   ratio base/head of the wall time, i.e. the speed-up, with its range, and the same of the CPU
   time (``time.process_time``: on a loaded machine the wall time also counts the time the process
   waited for a core).
4. ``--tangent-study H,H,...``: Newton iterations, RVE calls, DEM steps and CPU time of ``--steps``
   (default 40) load steps on ``--mesh`` (default 1 x 1) in process with the contact-stiffness
   tangent (h = 0) and with the perturbation tangent of each h (``gransim femxdem --tangent
   perturbation --tangent-step h``, :mod:`gransim.fem.perturbation`), ``--max-iter 100``, the
   tangents interleaved step by step in one process (:func:`tangent_ab`); ``--start CHECKPOINT``
   continues a ``--rve dem`` run's checkpoint (its mesh and last step) instead.

The machine's load average is printed before and after each part (2 shared cores: the absolute
times follow the load, ratios within one interleaved run much less). ``run(quick)`` gives the
records of ``python -m bench`` (part 1, and part 2 on a 1 x 2 mesh for 2 steps in process).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

#: the strain increments of the chain (a biaxial load step's D = f - 1: axial -1e-3, lateral and
#: shear of either sign; max|D| = 1e-3 gives ns = 100 steps a call, the benchmark's typical call)
INCREMENTS = (
    ((3e-4, 1e-4), (0.0, -1e-3)),
    ((4e-4, -2e-4), (1e-4, -1e-3)),
    ((2e-4, 0.0), (0.0, -1e-3)),
    ((5e-4, 1e-4), (-1e-4, -1e-3)),
)


def load() -> str:
    """The 1, 5 and 15 minute load averages, as text."""
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def _stats(xs) -> dict:
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs)}


def rve_call_split(calls: int = 60) -> dict:
    """Part 1 of the module docstring: {name: {median, min, max} (s)} plus the rates and counts.
    The parts are timed in CPU time (``time.process_time``: this process's, one thread), robust to
    the other processes of a shared machine; ``update`` also in wall time."""
    from gransim.dem import yade_arithmetic as ya
    from gransim.dem.yade_cell import VelGradRun, rve_engine
    from gransim.fem.dem_rve import DemRVE
    from gransim.fem.material_points import freeze

    clock = time.process_time
    law = DemRVE.prepared()
    st = freeze(law.initial_state(0))
    eye = np.eye(2)
    law.update(eye + np.array(INCREMENTS[0]), st)  # compile or load the cache
    names = ("update", "update_cpu", "update_kept", "update_kept_cpu", "run", "load", "start", "advance", "kernel",
             "unpack")  # fmt: skip
    t = {k: [] for k in names}
    ns_all, contacts = [], []
    for i in range(calls):
        f = eye + np.array(INCREMENTS[i % len(INCREMENTS)])
        D = f - eye  # DemRVE.update's D, to the bit
        rve = st.rve
        ns = ya.n_steps_of(D)
        # the call in its parts, the set-up computed (kept by it: dropped again below)
        ya._FIRST_RUNS.pop(rve, None)
        t0 = clock()
        with rve_engine(rve, st.disk_rotation()) as eng:
            t1 = clock()
            eng.start_run(VelGradRun(D / (ns * rve.dt)), ns)
            t2 = clock()
            kernel = _timed_advance(eng, ns, clock)
            t3 = clock()
            new, rot = eng.cell_ops.scene(eng), eng.yb.theta.copy()
        t4 = clock()
        t["load"].append(t1 - t0)
        t["start"].append(t2 - t1)
        t["advance"].append(t3 - t2)
        t["kernel"].append(kernel)
        t["unpack"].append(t4 - t3)
        t["run"].append(t4 - t0)
        ya._FIRST_RUNS.pop(rve, None)
        # the worker's calls from the committed (read-only) state: the first iterate of a load step
        # computes the set-up and keeps it, the next iterates restore it
        for key in ("update", "update_kept"):
            t0, c0 = time.perf_counter(), clock()
            _, _, nxt = law.update(f, st)
            t[key].append(time.perf_counter() - t0)
            t[f"{key}_cpu"].append(clock() - c0)
            if not (np.array_equal(nxt.rve.positions, new.positions) and np.array_equal(nxt.disk_rotation(), rot)):
                raise SystemExit("bench.femxdem: the split call differs from DemRVE.update (not the same computation)")
        ns_all.append(ns)
        contacts.append(len(nxt.rve.kn))
        st = freeze(nxt)
    n = st.rve.n
    out = {k: _stats(v) for k, v in t.items()}
    ns = statistics.median(ns_all)
    per_step = out["kernel"]["median"] / ns
    out["per_step"] = per_step
    out["n"] = n
    out["ns"] = ns
    out["contacts"] = statistics.median(contacts)
    out["rate_call"] = n * ns / out["run"]["median"]
    out["rate_call_best"] = n * ns / out["run"]["min"]
    out["rate_steady"] = n / per_step
    out.update(_step_split(st.rve, np.array(INCREMENTS[0])))
    return out


def _timed_advance(eng, ns: int, clock) -> float:
    """``eng.advance(ns)``, returning the time ``clock`` counted in the cell's compiled block (the
    kernel; the rest of the step loop is the engine's Python around it)."""
    ops = eng.cell_ops
    block = type(ops).block
    spent = [0.0]

    def timed(*args):
        c0 = clock()
        out = block(ops, *args)
        spent[0] += clock() - c0
        return out

    ops.block = timed  # this engine only, for this call
    try:
        eng.advance(ns)
    finally:
        del ops.block
    return spent[0]


def _step_split(rve, D, steps: int = 100) -> dict:
    """CPU time of one DEM step's two loops, each repeated ``steps`` times inside one compiled
    loop (no dispatch per step) on the container of an engine holding ``rve`` after 5 steps of
    ``D``: the interaction loop ``_interactions`` (s), the damped integrator ``_newton_damped``
    (s), and the container's entries and real ones."""
    from gransim._numba import njit
    from gransim.dem import yade_arithmetic as ya
    from gransim.dem.yade_cell import LAW_POISSON, LAW_TAN, LAW_YOUNG, VelGradRun, scene_engine

    @njit
    def interactions(k, pos, vel, spin, radius, H, VP, tan, young, poisson, dt, n_intr, ids, cd, real, geom, fs, f, t):
        for _ in range(k):
            ya._interactions(
                pos, vel, spin, radius, H, VP, 0.0, 0.0, tan, young, poisson, dt, True, n_intr, ids, cd, real, geom,
                fs, f, t,
            )  # fmt: skip

    @njit
    def integrator(k, pos, vel, spin, mass, inertia, f, t, L, nextL, changed, Lprev, size, prev, dt, ref, sweep, damp):
        for _ in range(k):
            ya._newton_damped(
                pos, vel, spin, mass, inertia, f, t, L, nextL, changed, Lprev, size, prev, dt, dt * dt, ref, sweep, damp
            )

    eng = scene_engine(rve)
    ns = ya.n_steps_of(D)
    eng.start_run(VelGradRun(D / (ns * rve.dt)), ns)
    eng.advance(5)
    b, c, q, lp, dt = eng.yb, eng.yc, eng.yq, eng.cell_ops.lp, rve.dt
    f, t = np.zeros((rve.n, 2)), np.zeros(rve.n)
    out = {"entries": int(q.n_intr[0]), "real": int(np.sum(q.i_real[: q.n_intr[0]]))}
    for name in ("interactions", "integrator", "interactions", "integrator"):  # the second pair counts
        c0 = time.process_time()
        if name == "interactions":
            interactions(steps, b.pos, b.vel, b.spin, b.radius, c.H, c.VP, lp[LAW_TAN], lp[LAW_YOUNG], lp[LAW_POISSON],
                         dt, q.n_intr, q.i_id, q.i_cd, q.i_real, q.i_geom, q.i_fs, f, t)  # fmt: skip
        else:
            integrator(steps, b.pos.copy(), b.vel.copy(), b.spin.copy(), b.mass, b.inertia, f, t, c.L.copy(),
                       c.nextL.copy(), c.changed.copy(), c.Lprev.copy(), c.size.copy(), c.prev_size.copy(), dt,
                       b.ref_pos, b.sweep, float(c.misc[3]))  # fmt: skip
        out[f"{name}_s"] = (time.process_time() - c0) / steps
    return out


def show_split(r: dict, log=print) -> None:
    ms = 1e3
    log(
        f"RVE call: {r['n']} disks, ns = {r['ns']:g} steps, {r['contacts']:g} contacts; CPU time but the first line "
        "(medians, min in brackets)"
    )
    for k, label in (
        ("update", "DemRVE.update, first iterate, wall"),
        ("update_cpu", "DemRVE.update, first iterate"),
        ("update_kept_cpu", "DemRVE.update, later iterates"),
        ("run", "rve_run_rotation, set-up computed"),
        ("load", "  loading the scene, set-up (rve_engine)"),
        ("start", "  start_run(VelGradRun)"),
        ("advance", "  advance(ns): the engine's step loop"),
        ("kernel", "    of which rve_block (ns steps)"),
        ("unpack", "  the saved scene (YadeCell.scene)"),
    ):
        log(f"  {label:40s} {r[k]['median'] * ms:8.3f} ms  ({r[k]['min'] * ms:.3f})")
    log(f"  {'    per DEM step':40s} {r['per_step'] * 1e6:8.2f} us")
    log(
        f"          of which the interaction loop {r['interactions_s'] * 1e6:.2f} us ({r['entries']} entries, "
        f"{r['real']} real), the integrator {r['integrator_s'] * 1e6:.2f} us (100 steps in one compiled loop each)"
    )
    log(
        f"  rate: call {r['rate_call'] / 1e6:.2f} M particle-steps/s (best {r['rate_call_best'] / 1e6:.2f}), "
        f"steady state {r['rate_steady'] / 1e6:.2f}"
    )


def femxdem_split(nx: int, ny: int, steps: int, workers: int, tangent=None, tangent_step=None, log=print) -> dict:
    """Part 2 of the module docstring: the run's figures (s, shares); ``tangent``, ``tangent_step``
    as ``gransim femxdem --tangent``."""
    from gransim.fem.biaxial import BiaxialSpec
    from gransim.fem.femxdem import run_femxdem
    from gransim.parallel import make_executor

    spec = BiaxialSpec(nx=nx, ny=ny, steps=steps)
    ex = make_executor(workers=workers if workers > 0 else None)
    try:
        with tempfile.TemporaryDirectory(prefix="bench-femxdem-") as tmp:
            t0 = time.perf_counter()
            res = run_femxdem(spec, rve="dem", out=tmp, executor=ex, tangent=tangent, tangent_step=tangent_step)
            total = time.perf_counter() - t0
    finally:
        close = getattr(ex, "close", None)
        if callable(close):
            close()
    tm, recs = res["timing"], res["steps"]
    steps_s = sum(r.wall_s for r in recs)
    wait_s = sum(r.material_s for r in recs)
    fe_s = steps_s - wait_s
    nw = max(workers, 1)
    out = {
        "mesh": f"{nx}x{ny}",
        "tangent": json.dumps(res["parameters"]["tangent"]),
        "gauss_points": spec.n_gauss,
        "steps": steps,
        "workers": workers,
        "newton_iterations": [len(r.errors) for r in recs],
        "total_s": total,
        "setup_s": tm["setup_s"],
        "wall_s": tm["wall_s"],
        "steps_s": steps_s,
        "wait_s": wait_s,
        "fe_s": fe_s,
        "rest_s": tm["wall_s"] - steps_s,
        "dem_s": tm["law_s"],
        "dem_cpu_s": tm["law_cpu_s"],
        "dem_calls": tm["law_calls"],
        "dem_per_chunk_s": [c["law_s"] for c in tm["chunks"]],
        "dem_share": tm["law_s"] / (nw * tm["wall_s"]),
    }
    out["overhead"] = 1.0 - out["dem_share"]
    out["ms_per_call"] = 1e3 * tm["law_s"] / max(tm["law_calls"], 1)
    return out


def show_run(r: dict, log=print) -> None:
    log(
        f"femxdem --rve dem, {r['mesh']} mesh ({r['gauss_points']} Gauss points), {r['steps']} steps, tangent "
        f"{r['tangent']}, "
        f"workers {r['workers'] or 'in process'}: Newton iterations {r['newton_iterations']}"
    )
    log(f"  total {r['total_s']:.2f} s: set-up {r['setup_s']:.2f} s, steps and outputs {r['wall_s']:.2f} s")
    log(
        f"  steps {r['steps_s']:.2f} s = waiting for the Gauss points {r['wait_s']:.2f} s + FE {r['fe_s']:.2f} s; "
        f"checkpoints and outputs {r['rest_s']:.2f} s"
    )
    chunks = ", ".join(f"{v:.2f}" for v in r["dem_per_chunk_s"])
    log(
        f"  DEM (point-law updates, on the workers) {r['dem_s']:.2f} s in {r['dem_calls']} calls "
        f"({r['ms_per_call']:.2f} ms a call; per chunk {chunks}); CPU {r['dem_cpu_s']:.2f} s "
        f"({1e3 * r['dem_cpu_s'] / max(r['dem_calls'], 1):.2f} ms a call)"
    )
    log(f"  DEM share {100 * r['dem_share']:.1f} % of workers x wall, overhead {100 * r['overhead']:.1f} %")


# ---------------------------------------------------------------------------------------------- A/B

_WORKER = r"""
import json, sys, time
import numpy as np
sys.path.insert(0, sys.argv[1])
from gransim.fem.dem_rve import DemRVE
incs = json.loads(sys.argv[2])
from gransim.fem.material_points import freeze
iterates = int(sys.argv[3])
law = DemRVE.prepared()
st = freeze(law.initial_state(0))
law.update(np.eye(2) + np.array(incs[0]), st)
print(json.dumps({"ready": True}), flush=True)
i = 0
for line in sys.stdin:
    k = int(line)
    t = c = 0.0
    for _ in range(k):
        f = np.eye(2) + np.array(incs[i % len(incs)])
        for _ in range(iterates):  # Newton iterates of a load step: each from the committed state
            t0, c0 = time.perf_counter(), time.process_time()
            _, _, nxt = law.update(f, st)
            t += time.perf_counter() - t0
            c += time.process_time() - c0
        st = freeze(nxt)
        i += 1
    r = st.rve
    print(json.dumps({"s": t, "cpu": c, "x": float(np.sum(r.positions)), "c": len(r.kn)}), flush=True)
"""


def ab(base: str, windows: int = 12, window: int = 10, iterates: int = 1, log=print) -> dict:
    """Part 3 of the module docstring; ``iterates`` calls from each committed (read-only) state of
    the chain, as the Newton iterates of a load step, ``window`` states a window."""
    from bench.ab_dem import _tree

    with tempfile.TemporaryDirectory(prefix="bench-femxdem-ab-") as tmp:
        tmp = Path(tmp)
        trees = {"base": _tree(base, tmp), "head": _tree("WORKTREE", tmp)}
        procs = {}
        try:
            for side in ("base", "head"):
                env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp / f"cache-{side}"), "PYTHONPATH": str(trees[side])}
                procs[side] = subprocess.Popen(
                    [sys.executable, "-c", _WORKER, str(trees[side]), json.dumps(INCREMENTS), str(iterates)],
                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env, cwd=str(trees[side]),
                )  # fmt: skip
                if not procs[side].stdout.readline():
                    raise SystemExit(f"bench.femxdem: the {side} worker ended early")
            per = {"base": [], "head": []}
            for k in range(windows):
                for side in ("base", "head") if k % 2 == 0 else ("head", "base"):
                    procs[side].stdin.write(f"{window}\n")
                    procs[side].stdin.flush()
                    line = procs[side].stdout.readline()
                    if not line:
                        raise SystemExit(f"bench.femxdem: the {side} worker ended early")
                    per[side].append(json.loads(line))
        finally:
            for p in procs.values():
                p.stdin.close()
                p.wait(timeout=60)
    same = all(a["x"] == b["x"] and a["c"] == b["c"] for a, b in zip(per["base"], per["head"]))
    ratios = [a["s"] / b["s"] for a, b in zip(per["base"], per["head"])]
    cpu = [a["cpu"] / b["cpu"] for a, b in zip(per["base"], per["head"])]
    out = {
        "base": base,
        "speedup_median": statistics.median(ratios),
        "speedup_min": min(ratios),
        "speedup_max": max(ratios),
        "speedup_cpu_median": statistics.median(cpu),
        "speedup_cpu_min": min(cpu),
        "speedup_cpu_max": max(cpu),
        "base_ms": 1e3 * statistics.median([a["s"] for a in per["base"]]) / (window * iterates),
        "head_ms": 1e3 * statistics.median([b["s"] for b in per["head"]]) / (window * iterates),
        "same_states": same,
        "windows": windows,
        "window": window,
    }
    log(
        f"A/B DemRVE.update, {windows} windows of {window} states x {iterates} calls: head is "
        f"{out['speedup_median']:.3f}x base {base} "
        f"(range {out['speedup_min']:.3f}-{out['speedup_max']:.3f}); per call base {out['base_ms']:.2f} ms, head "
        f"{out['head_ms']:.2f} ms (medians); CPU time: {out['speedup_cpu_median']:.3f}x "
        f"(range {out['speedup_cpu_min']:.3f}-{out['speedup_cpu_max']:.3f}); the chains' states equal on both sides: "
        f"{same}"
    )
    return out


# ---------------------------------------------------------------------------------- the tangent


def _counted_law(h: float):
    """Guo & Zhao's DEM RVE (``DemRVE.prepared()``) counting its calls and their DEM steps in
    ``law.counter`` ([calls, steps]; the perturbation calls included, as they go through the
    wrapped law), with the contact-stiffness tangent (``h`` 0) or the perturbation tangent of
    :mod:`gransim.fem.perturbation` (``h`` > 0)."""
    from dataclasses import dataclass, field

    from gransim.dem.yade_arithmetic import n_steps_of
    from gransim.fem.dem_rve import DemRVE
    from gransim.fem.perturbation import PerturbationTangent

    @dataclass(frozen=True, eq=False)
    class CountedRVE(DemRVE):
        counter: list = field(default_factory=lambda: [0, 0])

        def update(self, f, state):
            self.counter[0] += 1
            self.counter[1] += n_steps_of(np.asarray(f, dtype=float) - np.eye(2))
            return super().update(f, state)

    base = DemRVE.prepared()
    law = CountedRVE(base.initial, base.provenance)
    return (law if h <= 0 else PerturbationTangent(law, h)), law.counter


def _read_start(ckpt: Path):
    """(spec keywords, BiaxialStep, states) of the last step of a ``gransim femxdem --rve dem``
    checkpoint folder (its step record and committed states)."""
    import glob

    import h5py

    from gransim.fem.biaxial import BiaxialStep
    from gransim.fem.dem_rve import DemRVE

    k = max(int(Path(p).stem[7:]) for p in glob.glob(str(ckpt / "states_*.h5")))
    with h5py.File(ckpt / f"step_{k:03d}.h5", "r") as f:
        spec = json.loads(f.attrs["parameters"])["spec"]
        arrays = {n: f[n][()] for n in ("x", "stress", "F", "strain", "errors", "residuals")}
        scalars = {n: float(f.attrs[n]) for n in ("axial_strain", "deviatoric_stress", "volumetric_strain",
                                                  "wall_s", "material_s")}  # fmt: skip
    with h5py.File(ckpt / f"states_{k:03d}.h5", "r") as f:
        states = DemRVE.unpack_states({n: f["states"][n][()] for n in f["states"]})
    return spec, BiaxialStep(step=k, **arrays, **scalars), states


def tangent_ab(hs, steps: int = 40, mesh=(1, 1), start=None, max_iter: int = 100, log=print) -> list[dict]:
    """Part 4 of the module docstring: the contact-stiffness tangent (h = 0) and the perturbation
    tangent of each h > 0 on the biaxial specimen, ``steps`` load steps each (``--max-iter 100``,
    Guo & Zhao's iter_max), in this process, **interleaved step by step**: one thread per tangent,
    only one of which runs at a time, in the order A B, then B A, ... (each load step of every
    tangent runs before any tangent's next one), so that the machine's load weighs alike on all.
    Per tangent: Newton iterations and q per step, RVE calls and DEM steps (perturbation calls
    included), and the CPU time of its thread (``time.thread_time``: this thread's alone).
    ``start``: a ``--rve dem`` checkpoint folder to continue from (its mesh, last step and
    committed states: e.g. a full benchmark's step at the peak)."""
    import threading

    from gransim.fem.biaxial import BiaxialSpec, biaxial_setup, run_biaxial
    from gransim.fem.incremental import StepFailure
    from gransim.fem.material_points import gauss_points

    first, states = None, None
    if start is not None:
        kw, first, states = _read_start(Path(start))
        kw.update(steps=first.step + steps, max_iter=max_iter)
        spec = BiaxialSpec(**kw)
    else:
        spec = BiaxialSpec(nx=mesh[0], ny=mesh[1], steps=steps, max_iter=max_iter)
    setup = biaxial_setup(spec)
    names = [("contact" if h <= 0 else f"perturbation h={h:g}") for h in hs]
    order = [n for r in range(steps) for n in (names if r % 2 == 0 else names[::-1])]
    cond = threading.Condition()
    pos = {"i": 0}
    done = set()
    out = {
        n: {"h": h, "iterations": [], "q_kpa": [], "cpu_s": [], "dem_steps_per_step": [], "stopped": ""}
        for n, h in zip(names, hs)
    }
    counters = {}

    def advance():  # the next (step, tangent) whose tangent is still running; under cond
        pos["i"] += 1
        while pos["i"] < len(order) and order[pos["i"]] in done:
            pos["i"] += 1
        cond.notify_all()

    def runner(name, law):
        with cond:
            cond.wait_for(lambda: pos["i"] < len(order) and order[pos["i"]] == name)
        c0 = [time.thread_time()]  # the first step counts the committed states' first response (a
        n0 = [counters[name][1]]  # perturbation tangent: 8 calls a point), as a run's commit before it does
        points = gauss_points(law, spec.n_gauss, states=states)

        def on_step(rec, pts):
            r = out[name]
            r["cpu_s"].append(time.thread_time() - c0[0])
            r["dem_steps_per_step"].append(counters[name][1] - n0[0])
            n0[0] = counters[name][1]
            r["iterations"].append(len(rec.errors))
            r["q_kpa"].append(rec.deviatoric_stress / 1e3)
            with cond:
                advance()
                if rec.step < spec.steps:
                    cond.wait_for(lambda: pos["i"] < len(order) and order[pos["i"]] == name)
            c0[0] = time.thread_time()

        try:
            run_biaxial(setup, points, start=first, on_step=on_step)
        except StepFailure as exc:  # no convergence in max_iter: the steps before count
            out[name]["stopped"] = str(exc)
        finally:
            with cond:
                done.add(name)
                if pos["i"] < len(order) and order[pos["i"]] == name:
                    advance()

    threads = []
    for name, h in zip(names, hs):
        law, counters[name] = _counted_law(h)
        threads.append(threading.Thread(target=runner, args=(name, law), name=name))
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    rows = []
    where = f"from step {first.step} of {start}, " if first is not None else ""
    for name in names:
        r = out[name]
        r.update(name=name, calls=counters[name][0], dem_steps=counters[name][1], mesh=f"{spec.nx}x{spec.ny}")
        rows.append(r)
        its, q = r["iterations"], r["q_kpa"]
        log(
            f"{name}: {where}{len(its)} steps, {sum(its)} Newton iterations {its}, {r['calls']} RVE calls, "
            f"{r['dem_steps']} DEM steps, CPU {sum(r['cpu_s']):.1f} s; q {min(q, default=float('nan')):.1f}-"
            f"{max(q, default=float('nan')):.1f} kPa" + (f"; stopped: {r['stopped']}" if r["stopped"] else "")
        )
        log(
            f"  per step: CPU (s) {[round(c, 1) for c in r['cpu_s']]}, DEM steps {r['dem_steps_per_step']}, "
            f"q (kPa) {[round(v, 1) for v in q]}"
        )
    base = rows[0]
    for r in rows[1:]:
        n = min(len(base["iterations"]), len(r["iterations"]))
        if n:
            log(
                f"  {r['name']} against {base['name']} over the {n} steps both ran: Newton iterations "
                f"{sum(base['iterations'][:n]) / max(sum(r['iterations'][:n]), 1):.2f}x fewer, CPU "
                f"{sum(base['cpu_s'][:n]) / max(sum(r['cpu_s'][:n]), 1e-9):.2f}x less"
            )
    return rows


def run(quick: bool = False) -> list[dict]:
    """Records for ``python -m bench``."""
    r = rve_call_split(20 if quick else 60)
    note = f"400-disk RVE, ns = {r['ns']:g}, load {load()}"
    recs = [
        {"name": "femxdem.rve_call", "value": r["update_cpu"]["median"] * 1e3, "unit": "ms CPU", "target": None,
         "note": f"DemRVE.update, a load step's first Newton iterate; {note}"},
        {"name": "femxdem.rve_call_later", "value": r["update_kept_cpu"]["median"] * 1e3, "unit": "ms CPU",
         "target": None, "note": f"DemRVE.update, the later iterates (the set-up kept); {note}"},
        {"name": "femxdem.rve_rate", "value": r["rate_call"] / 1e6, "unit": "M particle-steps/s", "target": None,
         "note": f"rve_run_rotation, CPU time; {note}"},
        {"name": "femxdem.rve_setup", "value": r["load"]["median"] * 1e3, "unit": "ms CPU", "target": None,
         "note": f"a saved scene loaded into the thread's engine with its set-up computed; {note}"},
    ]  # fmt: skip
    s = femxdem_split(1, 2, 2, 0)
    recs.append(
        {"name": "femxdem.dem_share_1x2", "value": s["dem_share"], "unit": "", "target": None,
         "note": f"1 x 2 mesh, 2 steps, in process; {s['dem_calls']} calls, load {load()}"}
    )  # fmt: skip
    return recs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.femxdem", description=__doc__.split("\n\n")[0])
    ap.add_argument("--full", action="store_true", help="part 2 on the full benchmark's 8 x 16 mesh")
    ap.add_argument("--steps", type=int, default=None, help="load steps of part 2 (default 10; 2 with --full)")
    ap.add_argument("--workers", type=int, default=2, help="Dask workers of part 2 (0: in process)")
    ap.add_argument("--calls", type=int, default=60, help="RVE calls of part 1")
    ap.add_argument("--skip-run", action="store_true", help="part 1 only")
    ap.add_argument("--tangent", default=None, choices=["contact", "perturbation"], help="part 2: the tangent")
    ap.add_argument("--tangent-step", type=float, default=None, help="part 2: h of --tangent perturbation")
    ap.add_argument("--base", default=None, help="part 3: A/B of the RVE call against commit BASE")
    ap.add_argument(
        "--tangent-study",
        default=None,
        metavar="H,H,...",
        help="part 4: Newton iterations, DEM steps and CPU time on --mesh (default 1x1; --steps, default 40) for "
        "each perturbation h of the central-difference tangent (0: the contact-stiffness tangent), interleaved "
        "step by step",
    )
    ap.add_argument("--mesh", default="1x1", help="part 4: NXxNY elements")
    ap.add_argument("--start", default=None, metavar="CHECKPOINT",
                    help="part 4: continue from the last step of this --rve dem checkpoint folder")  # fmt: skip
    ap.add_argument("--iterates", type=int, default=1, help="part 3: calls from each committed state (Newton iterates)")
    ap.add_argument("--windows", type=int, default=12, help="part 3: windows, alternately A B and B A")
    ap.add_argument("--window", type=int, default=10, help="part 3: states of the chain per window")
    args = ap.parse_args(argv)
    print(f"load {load()}", flush=True)
    if args.base:
        ab(args.base, args.windows, args.window, args.iterates)
        print(f"load {load()}", flush=True)
        return 0
    if args.tangent_study:
        mesh = tuple(int(v) for v in args.mesh.lower().split("x"))
        tangent_ab([float(h) for h in args.tangent_study.split(",")], args.steps or 40, mesh, args.start)
        print(f"load {load()}", flush=True)
        return 0
    show_split(rve_call_split(args.calls))
    print(f"load {load()}", flush=True)
    if not args.skip_run:
        nx, ny = (8, 16) if args.full else (2, 4)
        steps = args.steps or (2 if args.full else 10)
        show_run(femxdem_split(nx, ny, steps, args.workers, args.tangent, args.tangent_step))
        print(f"load {load()}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
