"""A/B benchmark of the native DEM between two commits, interleaved in one run, in the steady state.

``python -m bench.ab_dem --base REV [--head REV|WORKTREE] [--n 10000] [--window 200] [--windows 12]
[--mode MODE] [--threads 1] [--head-mode MODE] [--head-threads T]``

Each side is the gransim tree of one commit (``git archive`` into a temporary folder; ``WORKTREE``,
the default head, is this checkout as it is) with its own numba cache. One long-lived process per
side builds the bench assembly (``bench.dem.assembly``: the jittered lattice relaxing in a fixed
periodic box, Hooke history, the same settings in both trees), compiles or loads its kernels, runs a
warm-up of ``--warm`` steps (the first rebuilds), and reports the time it took to get there (what a
user waits for before the first step: start-up, compilation or cache load, set-up). Then the driver
asks the two processes in turn, A B B A A B ..., for windows of ``--window`` steps each; both
states evolve bit for bit alike (the same arithmetic), so window k holds the same rebuilds on both
sides. Modes: ``serial``, ``parallel`` (the code order, DEMEngine); ``fast``, ``fast-lammps``
(the fast ordering, :class:`gransim.dem.fast.FastEngine`, in LIGGGHTS' or LAMMPS' arithmetic, on
``--threads``); ``fast-sheared`` (the fast ordering in the sheared cell,
:func:`bench.dem.sheared_assembly` in LAMMPS' arithmetic at :data:`bench.dem.SHEAR_LOADING`);
``sheared`` (the code order's sheared cell in simple shear). ``--head-mode`` / ``--head-threads``
run the head side in another configuration: with ``--base WORKTREE`` the figure compares two
configurations of one tree, interleaved the same way (the sheared cell against the orthogonal one,
2 threads against 1); their states then differ, so their rebuilds do too (reported).
Reported: the median over windows of the per-window throughput ratio head/base (particle-
steps per second), its spread, each side's median throughput, the rebuilds per window, the machine
load (os.getloadavg) before and after. A ratio >= 0.95 means "no slowdown beyond 5%".
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

from bench import median, show

ROOT = Path(__file__).resolve().parents[1]

_WORKER = r"""
import inspect, json, sys, time
t_start = time.perf_counter()
tree, n, mode, threads, warm = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4]), int(sys.argv[5])
sys.path.insert(0, tree)
from bench.dem import LOADING, SETTINGS, assembly
from gransim.dem import DEMEngine, DEMSettings
p = assembly(n)
if mode in ("fast", "fast-lammps"):  # the fast ordering (FastEngine) on THREADS threads, fixed box
    from gransim.dem.fast import FastEngine
    s = SETTINGS if mode == "fast" else DEMSettings(**{**SETTINGS.to_dict(), "flavour": "lammps"})
    eng = FastEngine(p, s, threads=threads)
    if list(inspect.signature(eng.advance).parameters)[0] == "nsteps":  # before 3e4555d: advance(nsteps)
        step = eng.advance
    else:
        step = lambda k: eng.advance(LOADING, k)
elif mode == "fast-sheared":  # the fast ordering in the sheared cell (bench.dem.sheared_assembly)
    from bench.dem import SHEAR_LOADING, SHEAR_SETTINGS, sheared_assembly
    from gransim.dem.fast import FastEngine
    p = sheared_assembly(n)
    eng = FastEngine(p, SHEAR_SETTINGS, threads=threads, cell="sheared")
    eng.start_run(SHEAR_LOADING, 10**9)
    step = eng.advance
elif mode == "sheared":  # the sheared cell (ShearEngine, LAMMPS' arithmetic), simple shear at 0.01/s
    from gransim.dem.sheared import ShearEngine, ShearLoading
    eng = ShearEngine(p, DEMSettings(**{**SETTINGS.to_dict(), "mode": "serial"}), flavour="lammps")
    eng.start_run(ShearLoading(erate=0.01), 10**9)
    step = eng.advance
else:
    s = DEMSettings(**{**SETTINGS.to_dict(), "mode": mode})
    eng = DEMEngine(p, s, threads=threads)
    step = lambda k: eng.advance(LOADING, k)
step(warm)
print(json.dumps({"ready_s": time.perf_counter() - t_start, "n": int(p.n)}), flush=True)
for line in sys.stdin:
    k = int(line)
    r0 = eng.n_rebuilds
    t0 = time.perf_counter()
    step(k)
    dt = time.perf_counter() - t0
    print(json.dumps({"loop_s": dt, "rebuilds": int(eng.n_rebuilds - r0), "contacts": int(eng.n_contacts)}),
          flush=True)
"""

#: the worker's modes (``--mode``, ``--head-mode``)
MODES = ("serial", "parallel", "fast", "fast-lammps", "fast-sheared", "sheared")


def _tree(rev: str, tmp: Path) -> Path:
    """The gransim tree of ``rev`` (``WORKTREE``: this checkout) as a folder."""
    if rev == "WORKTREE":
        return ROOT
    dest = tmp / rev.replace("/", "_")
    dest.mkdir(parents=True)
    arch = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", rev], capture_output=True)
    if arch.returncode != 0:
        raise SystemExit(f"ab_dem: git archive {rev} failed: {arch.stderr.decode().strip()}")
    tar_path = tmp / f"{rev.replace('/', '_')}.tar"
    tar_path.write_bytes(arch.stdout)
    with tarfile.open(tar_path) as tf:
        tf.extractall(dest, filter="data")
    return dest


def _spawn(tree: Path, args, cache: Path, mode: str, threads: int) -> subprocess.Popen:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(tree)}
    if threads:
        env["NUMBA_NUM_THREADS"] = str(max(1, threads))
    return subprocess.Popen(
        [sys.executable, "-c", _WORKER, str(tree), str(args.n), mode, str(threads), str(args.warm)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        cwd=str(tree),
    )


def _ask(proc: subprocess.Popen, steps: int | None) -> dict:
    if steps is not None:
        proc.stdin.write(f"{steps}\n")
        proc.stdin.flush()
    line = proc.stdout.readline()
    if not line:
        raise SystemExit(f"ab_dem: a worker ended early (exit {proc.poll()})")
    return json.loads(line)


def compare(
    base: str,
    head: str = "WORKTREE",
    n: int = 10000,
    window: int = 200,
    windows: int = 12,
    warm: int = 300,
    mode: str = "serial",
    threads: int = 1,
    log=print,
    head_mode: str | None = None,
    head_threads: int | None = None,
) -> dict:
    """Run the A/B comparison (module docstring) and return its figures. ``head_mode`` and
    ``head_threads`` (default: ``mode``, ``threads``) run the head side in another mode or on
    another thread count: with ``base`` = ``head`` the ratio is then that of two configurations of
    one tree (e.g. the sheared cell against the orthogonal one, 2 threads against 1)."""
    head_mode = mode if head_mode is None else head_mode
    head_threads = threads if head_threads is None else head_threads
    args = argparse.Namespace(n=n, warm=warm)
    side_cfg = {"base": (mode, threads), "head": (head_mode, head_threads)}
    load0 = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="gransim-ab-") as tmp:
        tmp = Path(tmp)
        trees = {"base": _tree(base, tmp)}
        trees["head"] = trees["base"] if head == base else _tree(head, tmp)
        procs, ready = {}, {}
        try:
            for side in ("base", "head"):  # start-up one after the other (compilation is CPU-bound)
                procs[side] = _spawn(trees[side], args, tmp / f"cache-{side}", *side_cfg[side])
                ready[side] = _ask(procs[side], None)
                log(f"[ab] {side} ({base if side == 'base' else head}): ready in {ready[side]['ready_s']:.1f} s")
            per = {"base": [], "head": []}
            for k in range(windows):
                order = ("base", "head") if k % 2 == 0 else ("head", "base")
                for side in order:
                    per[side].append(_ask(procs[side], window))
        finally:
            for p in procs.values():
                try:
                    p.stdin.close()
                    p.wait(timeout=30)
                except Exception:
                    p.kill()
    ratios = [b["loop_s"] / h["loop_s"] for b, h in zip(per["base"], per["head"])]
    same = all(
        b["rebuilds"] == h["rebuilds"] and b["contacts"] == h["contacts"] for b, h in zip(per["base"], per["head"])
    )
    npart = ready["head"]["n"]

    def tput(side):
        return median(npart * window / w["loop_s"] for w in per[side])

    out = {
        "base": base,
        "head": head,
        "n": npart,
        "mode": mode,
        "threads": threads,
        "head_mode": head_mode,
        "head_threads": head_threads,
        "window_steps": window,
        "windows": windows,
        "warm_steps": warm,
        "ratio_median": median(ratios),
        "ratio_min": min(ratios),
        "ratio_max": max(ratios),
        "base_pstep_per_s": tput("base"),
        "head_pstep_per_s": tput("head"),
        "rebuilds_per_window": [w["rebuilds"] for w in per["head"]],
        "same_rebuilds_and_contacts": same,
        "base_ready_s": ready["base"]["ready_s"],
        "head_ready_s": ready["head"]["ready_s"],
        "load_before": load0,
        "load_after": os.getloadavg(),
        "command": (
            f"python -m bench.ab_dem --base {base} --head {head} --n {n} --window {window} "
            f"--windows {windows} --mode {mode} --threads {threads}"
            + (f" --head-mode {head_mode}" if head_mode != mode else "")
            + (f" --head-threads {head_threads}" if head_threads != threads else "")
        ),
    }
    return out


#: the commit before the DEM redesign that made the contact laws plug-ins and the state namedtuples: the
#: baseline of the "no slowdown beyond 5%" figure
REDESIGN_BASE = "e658bc0"


def run(quick: bool = False) -> list[dict]:
    """Records of the benchmark suite: the Hooke DEM now vs before the redesign (serial, 1e4 disks,
    interleaved steady-state windows). Skipped in quick mode (it compiles a second tree) and where
    the checkout has no history of the base commit."""
    rev = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", "--verify", "--quiet", f"{REDESIGN_BASE}^{{commit}}"], capture_output=True
    )
    if quick or rev.returncode != 0:
        why = "quick mode" if quick else f"commit {REDESIGN_BASE} not in this clone's history"
        return [
            {
                "name": "ab_dem.redesign_ratio",
                "value": None,
                "unit": "x",
                "target": ">= 0.95",
                "note": f"not measured ({why}); python -m bench.ab_dem --base {REDESIGN_BASE}",
            }
        ]
    res = compare(REDESIGN_BASE, "WORKTREE", n=10000, window=200, windows=14, log=lambda *_: None)
    return [
        {
            "name": "ab_dem.redesign_ratio",
            "value": res["ratio_median"],
            "unit": "x",
            "target": ">= 0.95",
            "note": (
                f"native DEM (Hooke, LIGGGHTS flavour, serial, {res['n']} disks) now / before the plug-in "
                f"redesign ({REDESIGN_BASE}): median of {res['windows']} interleaved {res['window_steps']}-step "
                f"windows, range {res['ratio_min']:.3f}-{res['ratio_max']:.3f}; rebuilds per window "
                f"{res['rebuilds_per_window']}; same rebuilds and contacts on both sides: "
                f"{res['same_rebuilds_and_contacts']}; load {res['load_before'][0]:.2f} -> "
                f"{res['load_after'][0]:.2f}; rerun: {res['command']}"
            ),
        }
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.ab_dem", description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", required=True, help="git revision of the baseline")
    ap.add_argument("--head", default="WORKTREE", help="git revision to compare (default: this checkout)")
    ap.add_argument("--n", type=int, default=10000, help="disks (default 10000)")
    ap.add_argument("--window", type=int, default=200, help="steps per timed window (default 200)")
    ap.add_argument("--windows", type=int, default=12, help="timed windows per side (default 12)")
    ap.add_argument("--warm", type=int, default=300, help="warm-up steps before timing (default 300)")
    ap.add_argument("--mode", choices=MODES, default="serial")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--head-mode", choices=MODES, default=None, help="the head side's mode (default: --mode)")
    ap.add_argument("--head-threads", type=int, default=None, help="the head side's threads (default: --threads)")
    ap.add_argument("--json", type=Path, default=None, help="also write the figures here")
    a = ap.parse_args(argv)
    if shutil.which("git") is None:
        raise SystemExit("ab_dem: git is needed to check out the base revision")
    res = compare(
        a.base, a.head, a.n, a.window, a.windows, a.warm, a.mode, a.threads, print, a.head_mode, a.head_threads
    )
    print(json.dumps(res, indent=1))
    if not math.isfinite(res["ratio_median"]):  # a NaN window (a zero or NaN loop time): no figure
        print(f"[ab] head/base throughput ratio: {show(res['ratio_median'])}: a window's ratio is not a finite number")
        return 1
    print(
        f"[ab] head/base throughput: median {res['ratio_median']:.3f} (min {res['ratio_min']:.3f}, max "
        f"{res['ratio_max']:.3f}) over {a.windows} interleaved windows; load {res['load_before'][0]:.2f} -> "
        f"{res['load_after'][0]:.2f}; same rebuilds and contacts: {res['same_rebuilds_and_contacts']}"
    )
    if a.json:
        a.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
