"""Start-up: what a user waits for before gransim computes (docs/startup.md).

Records, every figure a whole process (interpreter start to exit) and every comparison interleaved
within each repeat, with the 1-minute load average beside it:

* ``gransim --help`` wall time (heavy imports must stay lazy);
* the first neighbour search, import included, from a warm numba cache;
* the first ``gransim biaxial`` of a fresh install, three ways, interleaved: **cold** (an empty
  numba cache: what a fresh install paid before ``make`` warmed it), **after the warm-up** (a
  copy of the cache ``gransim warmup`` filled, never used by a biaxial run on this assembly: the
  first run after ``make``) and **warm** (the same cache after a run). Target: after the warm-up
  <= 2 x warm. The CPU time of each process (user + system) is recorded beside the wall time: it
  is the compile work itself, which the load does not stretch;
* whole-process overhead for 1e5 disks at 60 steps, native against LIGGGHTS on the ``bench.dem``
  deck (same assembly, law and steps; bench/dem.py's job helpers): overhead = whole process -
  loop time. Target: native overhead below LIGGGHTS';
* the floor numba sets to any whole-process overhead: a fresh interpreter that imports numpy and
  numba and calls one trivial ``cache=True`` kernel already in the disk cache (numba's one-time
  set-up of its typing and target registries happens at that first call, loaded or compiled),
  against the same interpreter importing numpy only;
* where ``import`` time goes (``python -X importtime``, self time summed per top-level package)
  for ``import gransim`` and for the imports of ``gransim biaxial``.

Run: ``python -m bench --only startup [--quick]`` (quick, a smoke test: the warm biaxial figure
only, on 110 disks, nothing compiled, 1 repeat at 1e3 disks for the overhead; full: 3 repeats,
1e5 disks).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench import median

ROOT = Path(__file__).resolve().parents[1]
GRANSIM = [sys.executable, "-m", "gransim"]
#: the biaxial run that is timed: ~1e3 disks, a short compression (about 2 s warm on this machine)
BIAXIAL = (
    "--strain",
    "2e-4",
    "--inertial-number",
    "1e-2",
    "--consolidation-steps",
    "2000",
    "--allow-unsettled",
    "--snapshot-every",
    "200",
    "--checkpoint-every",
    "0",
)
#: what ``gransim biaxial`` imports before it computes (gransim/cli/cmd_biaxial.py's handlers)
BIAXIAL_IMPORTS = (
    "import gransim.cli, gransim.cli.cmd_biaxial, gransim.dem.biaxial, gransim.dem.output, "
    "gransim.io, gransim.contacts.laws"
)
OVERHEAD = (100_000, 60)
QUICK_OVERHEAD = (1_000, 60)


def _wall(cmd, repeat=5):
    ts = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, capture_output=True)
        ts.append(time.perf_counter() - t0)
    ts.sort()
    return ts[len(ts) // 2], ts[0], ts[-1]


def _timed(cmd, env=None, cwd=None) -> tuple[float, float]:
    """Wall and CPU (user + system) seconds of one process, which must succeed."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    p.returncode = os.waitstatus_to_exitcode(status)
    err = p.stderr.read().decode(errors="replace")
    p.stderr.close()
    if p.returncode != 0:
        raise RuntimeError(f"{' '.join(map(str, cmd))} failed ({p.returncode}):\n{err[-2000:]}")
    return wall, usage.ru_utime + usage.ru_stime


def _env(cache: Path | None) -> dict:
    env = dict(os.environ, MPLBACKEND="Agg")
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    return env


def _spread(xs) -> str:
    return f"median of {len(xs)}, min..max {min(xs):.3g}..{max(xs):.3g}" if len(xs) > 1 else "1 run"


def _load() -> float:
    return os.getloadavg()[0]


def import_breakdown(code: str, top: int = 8) -> list[tuple[str, float]]:
    """``[(top-level package, self seconds)]`` of ``python -X importtime -c code``, largest first."""
    r = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", code],
        capture_output=True,
        text=True,
        env=_env(None),
        check=True,
    )
    per: dict[str, float] = {}
    for line in r.stderr.splitlines():
        if not line.startswith("import time:") or "|" not in line:
            continue
        try:
            self_us, _cum, name = (x.strip() for x in line[len("import time:") :].split("|"))
            per[name.split(".")[0]] = per.get(name.split(".")[0], 0.0) + int(self_us) * 1e-6
        except ValueError:  # the header line
            continue
    return sorted(per.items(), key=lambda kv: -kv[1])[:top]


def _biaxial_records(tmp: Path, repeats: int, log, quick: bool = False) -> list[dict]:
    sys.path.insert(0, str(ROOT))
    from bench.dem import assembly
    from gransim.io import save_packing

    packing = tmp / "bench-1e3.h5"
    save_packing(packing, assembly(100 if quick else 1_000))
    run = [*GRANSIM, "biaxial", "--packing", str(packing), "-o", str(tmp / "b.h5"), *BIAXIAL]
    if quick:  # the warm figure only, from the cache in use, 110 disks: a smoke test compiles nothing
        run[run.index("--consolidation-steps") + 1] = "200"
        _timed(run, env=_env(None), cwd=tmp)
        wall, cpu = _timed(run, env=_env(None), cwd=tmp)
        return [
            {
                "name": "gransim biaxial, warm numba cache (wall)",
                "value": wall,
                "unit": "s",
                "note": f"1 run, 110 disks, 200 consolidation steps (quick: no cold or after-warm-up "
                f"figure); cpu {cpu:.2f} s; load {_load():.2f}",
            }
        ]
    # the warm-up, once, from an empty cache, on a 60-disk packing of its own (no pack step)
    tiny = tmp / "tiny.h5"
    save_packing(tiny, assembly(60))
    warmed = tmp / "cache-warmup"
    wall_w, cpu_w = _timed(
        [
            *GRANSIM,
            "warmup",
            "--laws",
            "default",
            "--packing",
            str(tiny),
            "--only",
            "biaxial",
            "--only",
            "biaxial --mode parallel",
        ],
        env=_env(warmed),
        cwd=tmp,
    )
    log(f"gransim warmup --only biaxial: {wall_w:.1f} s wall, {cpu_w:.1f} s cpu, load {_load():.2f}")
    warm_cache = tmp / "cache-warm"
    shutil.copytree(warmed, warm_cache)
    _timed(run, env=_env(warm_cache), cwd=tmp)  # the warm cache has seen this run once
    res: dict[str, list] = {"cold": [], "after warm-up": [], "warm": []}
    for k in range(repeats):
        order = list(res)[k % 3 :] + list(res)[: k % 3]
        for kind in order:
            cache = tmp / f"cache-{kind.replace(' ', '-')}-{k}"
            if kind == "after warm-up":
                shutil.copytree(warmed, cache)
            elif kind == "warm":
                cache = warm_cache
            load = _load()
            wall, cpu = _timed(run, env=_env(cache), cwd=tmp)
            res[kind].append((wall, cpu, load))
            log(f"first gransim biaxial, {kind}: {wall:.2f} s wall, {cpu:.2f} s cpu, load {load:.2f}")
    med = {k: (median(w for w, _, _ in v), median(c for _, c, _ in v)) for k, v in res.items()}
    loads = [ld for v in res.values() for _, _, ld in v]
    note = f"1,020-disk lattice, gransim biaxial {' '.join(BIAXIAL)}; load {min(loads):.1f}..{max(loads):.1f}"
    out = [
        {
            "name": f"first gransim biaxial, {k} numba cache (wall)",
            "value": med[k][0],
            "unit": "s",
            "note": f"{_spread([w for w, _, _ in res[k]])}; cpu {med[k][1]:.2f} s; {note}",
        }
        for k in res
    ]
    ratio = med["after warm-up"][0] / med["warm"][0]
    out.append(
        {
            "name": "first gransim biaxial after the warm-up / warm (wall)",
            "value": ratio,
            "unit": "x",
            "target": "<= 2",
            "meets": ratio <= 2.0,
            "note": f"cold / warm {med['cold'][0] / med['warm'][0]:.2f}x; cpu ratios: after warm-up "
            f"{med['after warm-up'][1] / med['warm'][1]:.2f}x, cold {med['cold'][1] / med['warm'][1]:.2f}x; "
            f"{note}",
        }
    )
    out.append(
        {
            "name": "gransim warmup --only biaxial (2 steps, from an empty cache)",
            "value": wall_w,
            "unit": "s",
            "note": f"cpu {cpu_w:.1f} s",
        }
    )
    return out


def _overhead_records(tmp: Path, size, repeats: int, log) -> list[dict]:
    import numpy as np

    sys.path.insert(0, str(ROOT))
    from bench import dem

    p = dem.assembly(size[0])
    d = tmp / f"n{p.n}"
    d.mkdir()
    npz = d / "packing.npz"
    np.savez(npz, positions=p.positions, radii=p.radii, cell=p.cell, density=p.density)
    steps = size[1]
    have_lig = shutil.which("liggghts") is not None
    if have_lig:
        dem.write_bench_deck(d / "liggghts", p, steps, engine="liggghts")
    dem._job(dem.NATIVE_1, npz, d, steps, 0)  # kernels into the cache (a DEM source may have changed)
    res: dict[str, list] = {"native": [], "LIGGGHTS": []}
    for k in range(repeats):
        kinds = ["native", "LIGGGHTS"] if k % 2 == 0 else ["LIGGGHTS", "native"]
        for kind in kinds:
            if kind == "LIGGGHTS" and not have_lig:
                continue
            job = dem._job(dem.NATIVE_1 if kind == "native" else dem.LIG_1, npz, d, steps, 0)
            res[kind].append((job["whole_s"], job["loop_s"], job["load"]))
            log(
                f"{kind}, {p.n} disks, {steps} steps: whole {job['whole_s']:.2f} s, "
                f"loop {job['loop_s']:.2f} s, "
                f"overhead {job['whole_s'] - job['loop_s']:.2f} s, load {job['load']:.2f}"
            )
    out = []
    med = {}
    for kind, v in res.items():
        if not v:
            continue
        over = [w - lp for w, lp, _ in v]
        med[kind] = median(over)
        out.append(
            {
                "name": f"whole-process overhead (whole - loop), {kind}, {p.n} disks, {steps} steps",
                "value": med[kind],
                "unit": "s",
                "note": f"{_spread(over)}; whole {median(w for w, _, _ in v):.2f} s, loop "
                f"{median(lp for _, lp, _ in v):.2f} s; load "
                f"{min(x[2] for x in v):.1f}..{max(x[2] for x in v):.1f}",
            }
        )
    if len(med) == 2:
        wn = median(w for w, _, _ in res["native"])
        wl = median(w for w, _, _ in res["LIGGGHTS"])
        out.append(
            {
                "name": f"whole-process overhead native / LIGGGHTS, {p.n} disks, {steps} steps",
                "value": med["native"] / med["LIGGGHTS"],
                "unit": "x",
                "target": "< 1",
                "meets": med["native"] < med["LIGGGHTS"],
                "note": f"whole process native / LIGGGHTS {wn / wl:.2f}x (interleaved, bench.dem deck "
                f"and job "
                "helpers; native: interpreter, imports, cached kernels, bench.dem's 110-disk warm-up "
                "job, set-up, loop)",
            }
        )
    return out


def run(quick: bool):
    def log(s):
        print(f"[startup] {s}", flush=True)

    med, lo, hi = _wall([*GRANSIM, "--help"], repeat=3 if quick else 7)
    out = [
        {
            "name": "gransim --help wall time",
            "value": med,
            "unit": "s",
            "target": "< 1 s",
            "meets": med < 1.0,
            "note": f"median, spread {lo:.2f}-{hi:.2f} s, load {_load():.2f}",
        }
    ]
    code = (
        "import time,numpy as np;t=time.perf_counter();"
        "from gransim.contacts import find_neighbours;"
        "find_neighbours(np.random.rand(50,2),np.full(50,0.05),np.eye(2));"
        "print(time.perf_counter()-t)"
    )
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)  # fill the cache
    vals = sorted(
        float(subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True).stdout)
        for _ in range(3)
    )
    out.append(
        {
            "name": "first neighbour search incl. import, warm numba cache",
            "value": vals[1],
            "unit": "s",
            "target": "< 2 s",
            "meets": vals[1] < 2.0,
            "note": f"median of 3 fresh processes, load {_load():.2f}",
        }
    )
    repeats = 1 if quick else 3
    with tempfile.TemporaryDirectory(prefix="bench-startup-") as tmp:
        out += _biaxial_records(Path(tmp), repeats, log, quick)
        out += _overhead_records(Path(tmp), QUICK_OVERHEAD if quick else OVERHEAD, repeats, log)
    out += _numba_floor_records(3 if not quick else 1)
    for label, code in (
        ("import gransim", "import gransim"),
        ("imports of gransim biaxial", BIAXIAL_IMPORTS),
    ):
        parts = import_breakdown(code)
        total = sum(s for _, s in parts)
        out.append(
            {
                "name": f"{label}: import self time, top packages",
                "value": total,
                "unit": "s",
                "note": ", ".join(f"{k} {s:.2f}" for k, s in parts) + f"; load {_load():.2f}",
            }
        )
    return out


#: a trivial kernel in the disk cache: its first call in a fresh process costs numba's one-time
#: initialisation of the typing and target contexts (about 250 builtin registries, and
#: numba.np.arraymath's BLAS probe, which imports scipy.linalg when SciPy is installed)
_TRIVIAL = "import numba\n\n\n@numba.njit(cache=True)\ndef f(x):\n    return x + 1.0\n"
_FLOOR = (
    "import time,sys;t0=time.perf_counter();import numpy;t1=time.perf_counter();import numba;"
    "t2=time.perf_counter();sys.path.insert(0,{d!r});import trivial_kernel as k;k.f(1.0);"
    "t3=time.perf_counter();print(t1-t0,t2-t1,t3-t2)"
)


def _numba_floor_records(repeats: int) -> list[dict]:
    """numba's own start-up, measured in fresh interpreters (whole process, the interpreter start
    included), interleaved with a numpy-only interpreter: the floor under the native overhead."""
    with tempfile.TemporaryDirectory(prefix="bench-numba-floor-") as d:
        Path(d, "trivial_kernel.py").write_text(_TRIVIAL)
        env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(d, "cache"))}
        code = _FLOOR.format(d=d)
        subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, env=env)  # compile, cache
        whole, parts, base = [], [], []
        for _ in range(repeats):
            t = time.perf_counter()
            r = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, env=env)
            whole.append(time.perf_counter() - t)
            parts.append([float(v) for v in r.stdout.split()])
            t = time.perf_counter()
            subprocess.run([sys.executable, "-c", "import numpy"], check=True, env=env)
            base.append(time.perf_counter() - t)
    k = sorted(range(repeats), key=whole.__getitem__)[repeats // 2]
    np_s, nb_s, first_s = parts[k]
    return [
        {
            "name": "numba floor: whole process importing numpy and numba, one cached trivial kernel called",
            "value": median(whole),
            "unit": "s",
            "note": (
                f"median of {repeats}; of the median run: numpy {np_s:.2f} s, import numba {nb_s:.2f} s, "
                f"first call of the cached kernel {first_s:.2f} s (numba's one-time registry set-up); "
                f"a numpy-only interpreter {median(base):.2f} s; load {_load():.2f}"
            ),
        }
    ]
