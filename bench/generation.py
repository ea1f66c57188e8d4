"""Packing generation: the advancing-front start against Feng, Han & Owen's figure, and whole packings.

Records (each with the 1-minute load average of the machine beside it, ``load``):

* **front start** (algorithm time): :func:`gransim.generation.front.front_packing` for 1e4, 1e5
  and (not quick) 1e6 quartz-sand disks, against the published 1e6 disks in 3.8 s (Feng, Han &
  Owen, "An advancing front packing of polygons, ellipses and spheres", 2003, on a 2003 PC);
* **700 disks**, the default request (max residual <= 1e-3), median of seeds 1-3 (target < 10 s);
* **whole process** ``gransim pack --n 10000`` with the default tolerance, ``--method random``
  and ``--method front`` interleaved (subprocess wall time: import, numba cache load, packing,
  file write);
* **Newton at a FIRE minimum** (1000 disks, default request): the exact Newton step of the
  enthalpy on the current contact network (:mod:`gransim.generation.stiffness`): its median
  displacement against the mean overlap, the contacts it closes at 1 % of its length and the lowest
  non-zero eigenvalue of the backbone stiffness; why Newton does not replace the last FIRE pass;
* (not quick) **100,000 disks**, ``residual="rms"`` 1e-3, both methods interleaved, with the split
  of FIRE steps and time per kind of stage;
* (not quick) **the packing targets**: ``gransim pack --n 100000`` (default tolerance: largest
  residual <= 1e-3 of the mean contact force; target < 10 s) and ``gransim pack --n 1000000
  --method front`` (target < 2 min), each a whole process (``bench/_pack_job.py``) with a time
  budget (:data:`BUDGET_1E5`, :data:`BUDGET_1E6`); the record holds the stage split as far as the
  run got, so a run stopped by its budget still says where the time went.

Run alone: ``python -m bench --only generation``.
"""

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from bench import median
from gransim.generation import get_distribution, make_packing
from gransim.generation.front import FRONT_PHI, front_packing
from gransim.generation.stiffness import backbone, contact_pairs, enthalpy_derivatives, newton_step

#: Feng, Han & Owen (2003): 1e6 disks packed by the advancing front in 3.8 s (2003 PC)
FENG_1E6_SECONDS = 3.8
#: wall-time budgets (s) of the whole-process runs at 1e5 and 1e6 disks (stopped beyond: not measured)
BUDGET_1E5 = 3600
BUDGET_1E6 = 3600
ROOT = Path(__file__).resolve().parents[1]


def _load() -> float:
    return round(os.getloadavg()[0], 2)


def _time(n, seed, **kw):
    t0 = time.perf_counter()
    p = make_packing("quartz-sand", n, seed, **kw)
    return time.perf_counter() - t0, p.metadata


def _split(meta) -> str:
    """Where the time goes: steps and seconds per kind of stage."""
    parts = {}
    for s in meta["stages"]:
        kind = s["stage"].split(" ")[0]
        st, sec = parts.get(kind, (0, 0.0))
        parts[kind] = (st + s["steps"], sec + s["seconds"])
    return "; ".join(f"{k} {st} steps {sec:.1f} s" for k, (st, sec) in parts.items())


def _front_time(n: int) -> tuple[float, int]:
    rng = np.random.default_rng(1)
    d = get_distribution("quartz-sand").sample(n, rng)
    r = d / (2 * d.mean())
    L = float(np.sqrt(np.pi * np.sum(r**2) / FRONT_PHI))
    t0 = time.perf_counter()
    _, placed = front_packing(r, L, rng)
    return time.perf_counter() - t0, placed


def _process(n: int, method: str) -> float:
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        subprocess.run(
            [
                sys.executable,
                "-m",
                "gransim",
                "pack",
                "--n",
                str(n),
                "--seed",
                "1",
                "--method",
                method,
                "-o",
                str(Path(tmp) / "p.h5"),
            ],
            check=True,
            capture_output=True,
            cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )
        return time.perf_counter() - t0


def _pack_job(n: int, method: str, budget: float) -> tuple[float | None, list, float]:
    """``gransim pack --n N --seed 1 --method METHOD`` as its own process (bench/_pack_job.py):
    (wall seconds or None when stopped at ``budget``, the stage records it printed, peak load)."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "bench._pack_job", str(n), "1", method, str(Path(tmp) / "p.h5")]
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            cmd, stdout=subprocess.PIPE, text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}
        )
        try:
            out, _ = proc.communicate(timeout=budget)
            wall = time.perf_counter() - t0
            if proc.returncode != 0:
                raise RuntimeError(f"{' '.join(cmd)} exited with {proc.returncode}")
        except subprocess.TimeoutExpired:
            proc.kill()
            out, _ = proc.communicate()
            wall = None
    stages = [json.loads(line) for line in out.splitlines() if line.startswith("{")]
    return wall, stages, max([s["load"] for s in stages], default=_load())


def _stage_note(stages) -> str:
    parts = {}
    for s in stages:
        kind = s["stage"].split(" ")[0]
        st, sec = parts.get(kind, (0, 0.0))
        parts[kind] = (st + s["steps"], sec + s["seconds"])
    last = stages[-1] if stages else None
    where = (
        f"; last stage ended: {last['stage']} at {last['elapsed']:.0f} s (residual {last['residual']:.2e} "
        f"{last['norm']})"
        if last
        else "; no stage ended"
    )
    return "; ".join(f"{k} {st} steps {sec:.1f} s" for k, (st, sec) in parts.items()) + where


def _newton_at_minimum(n: int = 1000) -> dict:
    """The exact Newton step of H on the contact network of a FIRE-converged packing."""
    p = make_packing("quartz-sand", n, 1)
    ell = 2 * p.radii.mean()
    x, r, L, P = p.positions / ell, p.radii / ell, p.cell[0, 0] / ell, p.metadata["pressure_reduced"]
    i, j, s = contact_pairs(x, r, L)
    bb = backbone(n, i, j)
    keep = bb[i] & bb[j]
    der = enthalpy_derivatives(x, r, L, P, pairs=(i[keep], j[keep], s[keep]))
    dx, lam = newton_step(der, free=bb)
    dx[bb] -= dx[bb].mean(axis=0)  # the translation gauge: no mean motion of the backbone
    disp = np.linalg.norm(dx[bb], axis=1)
    eps_mean = p.metadata["mean_overlap_dmean"]
    closed = len(contact_pairs(x + 0.01 * (dx + lam * x), r, L * (1 + 0.01 * lam))[0]) - len(i)
    dof = np.repeat(bb, 2)
    w = np.linalg.eigvalsh(der.K[dof][:, dof].toarray())
    return {
        "name": f"Newton step at a FIRE minimum, {n} disks: median displacement / mean overlap",
        "value": float(np.median(disp) / eps_mean),
        "unit": "",
        "n": n,
        "load": _load(),
        "target": "",
        "meets": None,
        "note": f"default request, seed 1 (largest residual {p.metadata['residual']:.2e} of the mean contact "
        f"force); largest displacement {disp.max():.2e} d_mean, mean overlap {eps_mean:.2e} d_mean; "
        f"{closed:+d} contacts at 1 % of the step; lowest non-zero eigenvalue of the backbone stiffness "
        f"{w[2]:.2e} k_n (largest {w[-1]:.2f})",
    }


def run(quick: bool):
    make_packing("quartz-sand", 50, 1)  # compile (serial build)
    make_packing("quartz-sand", 50, 1, residual="rms", method="front")
    out = []
    # -- the constructive start against the published figure --
    for n in (10_000, 100_000) if quick else (10_000, 100_000, 1_000_000):
        t, placed = _front_time(n)
        rec = {
            "name": f"advancing-front start, {n:,} disks (algorithm time)",
            "value": t,
            "unit": "s",
            "n": n,
            "load": _load(),
            "target": "",
            "meets": None,
            "note": f"{placed:,} placed by the front ({100 * placed / n:.2f} %), the rest at random; "
            f"Feng, Han & Owen 2003: 1e6 disks in {FENG_1E6_SECONDS} s (2003 PC)",
        }
        if n == 1_000_000:
            rec.update(target=f"published {FENG_1E6_SECONDS} s", meets=None, ratio=t / FENG_1E6_SECONDS)
        out.append(rec)
    # -- 700 disks, default request --
    times = []
    for seed in (1, 2, 3):
        t, meta = _time(700, seed)
        times.append(t)
    med = median(times)
    out.append(
        {
            "name": "packing 700 disks (quartz-sand)",
            "value": med,
            "unit": "s",
            "target": "< 10 s",
            "meets": med < 10.0,
            "n": 700,
            "load": _load(),
            "note": f"median of seeds 1-3, spread {min(times):.2f}-{max(times):.2f} s; max residual <= 1e-3; "
            f"phi {meta['solid_fraction']:.4f}, {meta['fire_steps']} FIRE steps (seed 3)",
        }
    )
    # -- whole process, 1e4, default tolerance, both methods interleaved --
    for method in ("random", "front"):
        t = _process(10_000, method)
        out.append(
            {
                "name": f"gransim pack --n 10000 --method {method} (whole process, max residual 1e-3)",
                "value": t,
                "unit": "s",
                "n": 10_000,
                "load": _load(),
                "target": "",
                "meets": None,
                "note": "subprocess wall time: import, numba cache load, packing, HDF5 write",
            }
        )
    out.append(_newton_at_minimum())
    if quick:
        return out
    # -- 1e5, rms residual 1e-3, both methods interleaved --
    for method in ("random", "front"):
        t, meta = _time(100_000, 1, force_tol=1e-3, residual="rms", method=method)
        out.append(
            {
                "name": f"packing 100,000 disks, rms residual <= 1e-3, method {method}",
                "value": t,
                "unit": "s",
                "n": 100_000,
                "load": _load(),
                "target": "< 10 s at the default max residual",
                "meets": False,
                "note": f"seed 1; phi {meta['solid_fraction']:.4f}, Z {meta['coordination']:.3f}, "
                f"{meta['fire_steps']} FIRE steps, {meta['neighbour_builds']} neighbour builds; "
                f"{_split(meta)}",
            }
        )
    # -- the packing targets: whole processes at the default tolerance, stage split as far as they got --
    for n, method, budget, target in (
        (100_000, "random", BUDGET_1E5, 10.0),
        (1_000_000, "front", BUDGET_1E6, 120.0),
    ):
        wall, stages, load = _pack_job(n, method, budget)
        out.append(
            {
                "name": f"gransim pack --n {n} --method {method} (whole process, default tolerance)",
                "value": wall,
                "unit": "s",
                "n": n,
                "load": load,
                "target": f"< {target:g} s",
                "meets": None if wall is None else wall < target,
                "note": ("" if wall is not None else f"stopped at the budget of {budget} s; ")
                + f"seed 1, max load {load}; {_stage_note(stages)}",
            }
        )
    return out
