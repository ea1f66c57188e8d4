"""Named reference cases for ``gransim reference run CASE`` and ``gransim reference list``.

A case is a callable ``run(out_dir, np_procs, timeout, force, progress, engine) -> int`` (exit
status) with a one-line description. The cases are the two Taylor sets defined here
(:data:`CASES`): the demo on built-in packings and the 15 study RVEs. The other reference jobs
(biaxial, shear, impacts, laws) are run by their validation cases (``gransim validate``) and by
``reference_runs.decks.*`` directly; they are not named cases.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from gransim.errors import InputError
from gransim.paper import KN_2D

#: tolerance of the Taylor comparison (relative to the largest stress component of the state):
#: both sides sum the same float64 contact forces in different orders, ~1e-15 is expected
TAYLOR_RTOL = 1e-10


@dataclass(frozen=True)
class Case:
    name: str
    description: str
    run: Callable


def compare_taylor(run, rtol: float = TAYLOR_RTOL) -> dict:
    """Largest relative difference between a LIGGGHTS/LAMMPS TaylorRun and the numpy Taylor stress.

    For every state: max |sigma_code - sigma_numpy| / max |sigma_numpy| (componentwise; the
    difference itself when the numpy stress is zero), and the same for the periodic route's
    pressure column. Returns ``{(path, route): max}``.

    Raises :class:`reference_runs.judge.JudgeError` naming the state and the side when a stress
    or a deformation gradient is NaN or inf on either side (``stress of state 3 of shear-12,
    periodic route of lattice-8x8-seed1 (liggghts) is NaN``), and when the run holds no state at
    all: such a run fails, it is never compared on what remains.
    """
    # lazy: `gransim reference list` imports this module; numba, h5py (~1.8 s) wait for a run
    import numpy as np

    from .judge import NoEvidenceError, max_rel_diff, require_finite
    from .taylor_numpy import candidate_pairs, taylor_stress_numpy

    code = getattr(run, "engine", "liggghts")
    states = [(key, i) for key, s in sorted(run.series.items()) for i in range(len(s.k))]
    if not states:
        raise NoEvidenceError(f"Taylor states of {run.name}: none in the job, nothing to compare")

    def what(key, k):
        return f"of state {int(k)} of {key[0]}, {key[1]} route of {run.name}"

    for key, s in sorted(run.series.items()):
        for k, F in zip(s.k, s.F):
            require_finite(F, f"deformation gradient {what(key, k)}")
    s_min = min(float(np.linalg.svd(F, compute_uv=False).min()) for s in run.series.values() for F in s.F)
    cand = candidate_pairs(run.packing, min(1.0, s_min))
    out = {}
    for key, s in sorted(run.series.items()):
        if len(s.k) == 0:
            raise NoEvidenceError(f"Taylor states of {key[0]}, {key[1]} route of {run.name}: none in the job")
        rel = []
        for k, F, sig, sp in zip(s.k, s.F, s.cauchy, s.cauchy_pressure):
            with np.errstate(invalid="ignore", divide="ignore"):  # a 0/0 is judged below, named, not warned
                ref = taylor_stress_numpy(run.packing, F, run.kn, cand).cauchy
            sides = (code, "numpy")
            rel.append(max_rel_diff(sig, ref, f"stress {what(key, k)}", sides))
            if key[1] == "periodic":
                rel.append(max_rel_diff(sp, ref, f"pressure stress {what(key, k)}", sides))
        out[key] = max(rel)  # every entry finite (max_rel_diff refuses NaN and inf)
    return out


def run_taylor_set(
    packings: dict,
    out_dir,
    kn: float = KN_2D,
    n_steps: int = 50,
    stride: int = 1,
    max_strain: float = 0.1,
    contacts: bool = False,
    np_procs: int = 1,
    timeout=3600.0,
    force: bool = False,
    progress: bool = True,
    h5_name: str = "taylor.h5",
    check: bool = True,
    echo=print,
    engine: str = "liggghts",
) -> tuple:
    """Run the Taylor states of several packings (one job of ``engine``, "liggghts" or "lammps",
    each) and compare with numpy.

    ``kn``: the 2D normal contact stiffness (N/m; default the paper's, :data:`gransim.paper.KN_2D`).
    Returns ``(runs, worst)``: the TaylorRun objects and the largest relative difference; NaN
    (which fails every ``worst <= tolerance``) when a packing could not be judged (a NaN or inf
    stress on either side, no states: the reason is echoed, naming the state and the side) or
    when ``check`` found nothing to compare (no packings).
    """
    # lazy: `gransim reference list` imports this module; numba, h5py (~1.8 s) wait for a run
    from gransim.progress import progress as _progress

    from .judge import JudgeError
    from .runner import MANIFEST_NAME
    from .taylor import run_taylor, write_taylor_h5

    out_dir = Path(out_dir)
    runs, worst = [], 0.0
    for name, packing in _progress(list(packings.items()), desc="packings"):
        job = out_dir / "jobs" / name
        if force:
            (job / MANIFEST_NAME).unlink(missing_ok=True)
        run = run_taylor(
            packing,
            kn,
            job,
            name=name,
            n_steps=n_steps,
            stride=stride,
            max_strain=max_strain,
            contacts=contacts,
            np_procs=np_procs,
            timeout=timeout,
            progress=progress,
            engine=engine,
        )
        runs.append(run)
        if check:
            head = (
                f"{name}: N = {packing.n}, {sum(len(s.k) for s in run.series.values())} states "
                f"({run.manifest.get('elapsed_s', 0):.2f} s)"
            )
            try:
                w = max(compare_taylor(run).values())
            except JudgeError as exc:  # NaN/inf on either side, or no state: a failure, named
                worst = math.nan
                echo(f"{head}: FAIL: {exc}")
                continue
            if not math.isnan(worst):
                worst = max(worst, w)
            echo(f"{head}, max rel. diff vs numpy Taylor = {w:.3e}")
    h5 = write_taylor_h5(
        out_dir / h5_name,
        runs,
        parameters={
            "kn": kn,
            "n_steps": n_steps,
            "stride": stride,
            "max_strain": max_strain,
            "packings": list(packings),
            "engine": engine,
        },
    )
    echo(f"wrote {h5}")
    if check and not runs:
        echo("no packings: nothing was compared (FAIL)")
        worst = math.nan
    return runs, worst


def _verdict(case: str, worst: float) -> int:
    """Print the verdict of a Taylor set; 0 when ``worst`` is within :data:`TAYLOR_RTOL`, else 1
    (NaN: a packing could not be judged, its reason printed above)."""
    # lazy: `gransim reference list` imports this module; the judge imports numpy
    from .judge import within

    ok = within(worst, TAYLOR_RTOL)
    print(f"{case}: largest relative difference {worst:.3e} ({'PASS' if ok else 'FAIL'}, tolerance {TAYLOR_RTOL:g})")
    return 0 if ok else 1


def _taylor_demo(out_dir, np_procs=1, timeout=600.0, force=False, progress=True, engine="liggghts") -> int:
    # lazy: `gransim reference list` imports this module; numba, h5py (~1.8 s) wait for a run
    from .demo_packings import perturbed_lattice

    packings = {f"lattice-8x8-seed{s}": perturbed_lattice(8, 8, seed=s) for s in (1, 2, 3)}
    _, worst = run_taylor_set(
        packings, out_dir, np_procs=np_procs, timeout=timeout, force=force, progress=progress, engine=engine
    )
    return _verdict("taylor-demo", worst)


def standard_rves(packings_dir="results/packings") -> dict:
    """The 15 RVEs of the study (rve-<N>-<seed>), generated or reused by gransim.generation."""
    # lazy: `gransim reference list` imports this module; numba, h5py (~1.8 s) wait for a run
    from gransim.generation import STANDARD_PACKINGS, standard_packings
    from gransim.io import load_packing

    names = [n for n in STANDARD_PACKINGS if n.startswith("rve-")]
    paths = standard_packings(packings_dir, names=names)
    return {name: load_packing(path) for name, path in paths.items()}


def _taylor_rves(out_dir, np_procs=1, timeout=3600.0, force=False, progress=True, engine="liggghts") -> int:
    _, worst = run_taylor_set(
        standard_rves(), out_dir, np_procs=np_procs, timeout=timeout, force=force, progress=progress, engine=engine
    )
    return _verdict("taylor-rves", worst)


#: every named case, by name
CASES = {
    c.name: c
    for c in (
        Case(
            "taylor-demo",
            "Taylor states of 3 built-in 64-disk packings along the 4 study paths, both routes, checked against numpy",
            _taylor_demo,
        ),
        Case(
            "taylor-rves",
            "Taylor states of the 15 study RVEs (results/packings, generated if "
            "missing) along the 4 study paths, 50 steps, both routes, checked against numpy",
            _taylor_rves,
        ),
    )
}


def all_cases() -> dict:
    """Every named case by name (:data:`CASES`)."""
    return dict(CASES)


def get_case(name: str) -> Case:
    """The case ``name``; InputError naming the known cases for any other name."""
    if name not in CASES:
        raise InputError(f"unknown reference case {name!r}; choose one of: {', '.join(sorted(CASES))}")
    return CASES[name]
