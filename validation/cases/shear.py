"""Case ``simple-shear``: true periodic simple shear (a sheared, Lees-Edwards cell), native vs LAMMPS.

The native side is :class:`gransim.dem.sheared.ShearEngine` in LAMMPS' arithmetic (``flavour="lammps"``,
docs/shear.md); the LAMMPS side runs the mirror deck :mod:`reference_runs.decks.shear`
(``change_box all triclinic``, ``fix deform 1 xy erate RATE [y variable v_dy v_ry] remap v``).

* Short horizon, step for step: the stored LAMMPS runs ``reference_runs/stored/shear-short-lammps``
  (120 disks, constant volume and y servo, 3000 steps) and, with ``lmp`` installed, a live rerun of
  1000 steps; positions, velocities, spins, forces, torques, stress and box at the bitwise bounds.
* Long horizon, by envelope (default and full suites): the Kuhn 1002-disk assembly, consolidated
  natively (as ``biaxial-full``), sheared under the y servo at the biaxial confining pressure to
  :data:`LONG_STRAIN`; native vs LAMMPS judged against LAMMPS' own divergence under a 1e-15
  perturbation (one member in the default suite, two in the full suite); the shear stress-strain
  and dilatancy curves within the LAMMPS band. Without ``lmp``, the stored series
  ``reference_runs/stored/shear-full-lammps`` (:func:`store_long_reference`).
* Kuhn's void cells on simple shear (:mod:`gransim.voidcell`), from snapshots built identically for
  both codes by :func:`sheared_snapshot` (sheared cell, contacts from positions, lab velocities).

Trajectories here are :class:`validation.dem_compare.Trajectory` with ``lengths`` (T, 3) = the box
(lx, ly, xy) in m, not the (T, 2) side lengths of the orthogonal cases.
"""

from __future__ import annotations

import dataclasses
import datetime
import functools
import hashlib
import json
import math
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gransim.contacts import find_neighbours
from gransim.dem import DEMEngine, Loading
from gransim.dem import default_settings as dem_defaults
from gransim.dem.sheared import ShearEngine, ShearLoading
from gransim.errors import InputError
from gransim.geometry import Packing
from gransim.voidcell import Snapshot
from reference_runs.decks.shear import (
    DATA,
    DUMP,
    SHORT_CASES,
    SHORT_DUMP_EVERY,
    read_thermo,
    short_case,
    wrapped_packing,
    write_shear_deck,
)
from reference_runs.judge import defined_diff
from reference_runs.parsers import parse_dump_custom
from reference_runs.runner import run_job
from reference_runs.yade.dem import shear_job, short_shear

from .. import dem_compare, yade_runs
from ..codes import CODES, NATIVE, code_label, pair_key
from ..core import (
    CaseResult,
    Context,
    case,
    default_job_timeout,
    stored_dir,
)
from ..dem_compare import (
    Trajectory,
    expected_frames,
    reduce_sheared,  # noqa: F401 (the sheared-cell geometry of this case, tested here)
    sheared_cell,
    stress_differences,
)
from ..judges import (
    ENVELOPE_FACTOR,
    LIST_REASON,
    Bound,
    CurveCheck,
    Ensemble,
    EnvelopeRule,
    StepBounds,
    step_for_step,
    void_cells,
)
from ..matrix import Comparison, Run, evaluate, stored_job
from .biaxial import (
    FULL_CONSOLIDATION_STEPS,
    PERTURB_REL,
    YADE_BIT_REASON,
    YADE_BOUNDS,
    _kuhn,
    _servo,
)

CASE = "simple-shear"
TITLE = "Simple shear in a sheared periodic cell (Lees-Edwards): native vs LAMMPS, and void cells"

POS_TOL = 1e-10  # of D50
REL_TOL = 1e-8
POS_REASON = (
    "the sheared-cell engine does LAMMPS' floating-point operations (fix nve/sphere, triclinic neighbour "
    "check, lamda wrap with the remap v velocity jumps, gran/hooke/history, fix deform; docs/shear.md); only "
    "the summation order of the neighbour list differs (measured 2.5e-13 D50 over 3000 steps), so 1e-10 "
    "D50 (the step-for-step bound) is 3 decades above round-off and 7 below what 1% stiffer contacts give"
)
VEL_REASON = (
    "velocities (lab frame on both sides: remap v keeps the streaming velocity in v), spins: relative to "
    "the largest value, the stress bound, as they come from the same forces by the same kicks"
)
FORCE_REASON = (
    "per-particle force/torque of the step (dump fx fy tqz) relative to the largest: the same contact "
    "sums in another order"
)
STRESS_REASON = (
    "virial stress every thermo step (compute pressure NULL virial, over the area of the box after "
    "the step): the same contacts summed in another order; 1e-8 relative to the largest component"
)
BOX_REASON = (
    "box lx, ly, xy after fix deform, in D50: the tilt is LAMMPS' linear ramp with its tilt wrap, the "
    "servo moves ly from the stress, so the position bound applies"
)
LIGGGHTS_NA = (
    "LIGGGHTS 3.8.0's triclinic box has no periodic ghost atoms (Domain sets prd_lamda to 0, "
    "domain.cpp:144-145, docs/liggghts.md): contacts across the boundary are lost and simple shear loses "
    "atoms, so LIGGGHTS cannot run this case; its sheared states are checked through explicit image "
    "copies in taylor-rve"
)
MATRIX_REASON = (
    "native flavour lammps repeats LAMMPS' arithmetic in the sheared cell: step for step at 1e-10 D50 "
    "and 1e-8 stress on the short horizon, within 10x LAMMPS' own round-off envelope on the long one"
)

LIVE_STEPS = 1000
LIVE_DUMP_EVERY = 250

#: long horizon: inertial number I = gamma_dot D50 sqrt(rho / p). 1e-3 is the usual quasi-static
#: bound (I < 1e-3: rate-independent response) and keeps the LAMMPS job short: 2% strain of the
#: 1002 disks is ~7.2e4 steps, ~7e7 particle-steps, ~20 s of serial LAMMPS at ~4e6 particle-steps/s
LONG_INERTIAL = 1e-3
LONG_STRAIN = 0.02
LONG_DUMP_EVERY = 3000
LONG_THERMO_EVERY = 10
STORED_EVERY = 100
STORED_LONG = "shear-full-lammps"


def perturb_labels(n: int, suite: str) -> list[str]:
    """Labels of the perturbed LAMMPS runs of the long horizon: one member in the default suite,
    two in the full suite."""
    out = ["x of disk 1 moved by +1e-15 rel", f"y of disk {n // 2 + 1} moved by -1e-15 rel"]
    return out if suite == "full" else out[:1]


def _perturbation(label: str, n: int) -> tuple[int, int, float]:
    return {
        "x of disk 1 moved by +1e-15 rel": (0, 0, 1.0),
        f"y of disk {n // 2 + 1} moved by -1e-15 rel": (n // 2, 1, -1.0),
    }[label]


def _frame(eng) -> dict:
    return {
        "x": eng.x.copy(),
        "v": eng.v.copy(),
        "w": eng.w.copy(),
        "f": eng.f.copy(),
        "t": eng.t.copy(),
    }


def run_native_shear(
    packing,
    settings,
    loading,
    nsteps: int,
    dump_every: int,
    thermo_every: int = 1,
    velocities=None,
    spins=None,
):
    """The sheared-cell engine (flavour lammps) as a Trajectory: stress (compression positive,
    N/m) and box (lx, ly, xy) every ``thermo_every`` steps from the set-up (step 0), frames every
    ``dump_every`` steps. The settings pass through :func:`validation.dem_compare.native_setup`
    (the hook the validation tests perturb)."""
    settings, loading = dem_compare.native_setup(dataclasses.replace(settings, flavour="lammps"), loading)
    t0 = time.perf_counter()
    eng = ShearEngine(packing, settings, velocities=velocities, spins=spins, flavour="lammps")
    b = eng.box
    box = [np.array([[b[2] - b[0], b[3] - b[1], b[4]]])]
    s0 = eng.start_run(loading, nsteps)
    st = [np.array([[s0[0, 0], s0[1, 1], s0[0, 1]]])]
    frames = {0: _frame(eng)}
    while eng.step < nsteps:
        stop = min(nsteps, (eng.step // dump_every + 1) * dump_every)
        out = eng.advance(stop - eng.step)
        s = out["stress"]
        st.append(np.stack([s[:, 0, 0], s[:, 1, 1], s[:, 0, 1]], axis=1))
        box.append(out["box"][:, :3])
        if eng.step % dump_every == 0:
            frames[eng.step] = _frame(eng)
    keep = slice(None, None, int(thermo_every))
    return Trajectory(
        np.arange(nsteps + 1)[keep],
        np.concatenate(st)[keep],
        np.concatenate(box)[keep],
        frames,
        time.perf_counter() - t0,
    )


def read_lammps_shear(log_path, dump_path):
    """A Trajectory of a LAMMPS run of the shear deck (log: thermo; dump: frames sorted by id).
    A dump the parser refuses (e.g. a frame cut short) gives no frames: the evidence records then
    name every frame as missing."""
    th = read_thermo(log_path)
    frames = {}
    try:
        for fr in parse_dump_custom(dump_path):
            c = dict(fr.columns)
            frames[int(fr.step)] = {
                "x": np.stack([c["x"], c["y"]], 1),
                "v": np.stack([c["vx"], c["vy"]], 1),
                "w": np.asarray(c["omegaz"], float),
                "f": np.stack([c["fx"], c["fy"]], 1),
                "t": np.asarray(c["tqz"], float),
            }
    except (OSError, ValueError, KeyError, IndexError):
        pass
    return Trajectory(
        th["step"],
        np.stack([th["sxx"], th["syy"], th["sxy"]], 1),
        np.stack([th["lx"], th["ly"], th["xy"]], 1),
        frames,
    )


def run_shear_job(
    job_dir,
    packing,
    settings,
    loading,
    nsteps: int,
    dump_every: int,
    thermo_every: int = 1,
    velocities=None,
    spins=None,
    timeout=None,
):
    """The shear deck run by LAMMPS in ``job_dir`` (:func:`reference_runs.runner.run_job`, reused
    when complete with the same inputs). Returns (Trajectory, manifest)."""
    if timeout is None:
        timeout = default_job_timeout(packing.n * nsteps)
    with tempfile.TemporaryDirectory() as tmp:
        deck = write_shear_deck(
            tmp,
            packing,
            settings,
            loading,
            nsteps,
            thermo_every=thermo_every,
            dump_every=dump_every,
            velocities=velocities,
            spins=spins,
        )
        data = (Path(tmp) / DATA).read_bytes()
        res = run_job(
            job_dir,
            deck.read_text(),
            files={DATA: data},
            np=1,
            outputs=(DUMP,),
            expected_runs=1,
            progress=False,
            timeout=timeout,
            engine="lammps",
        )
    tr = read_lammps_shear(res.log_path, res.path(DUMP))
    el = 0.0 if res.skipped else float(res.manifest.get("elapsed_s", 0.0))
    return dataclasses.replace(tr, elapsed=el), res.manifest


# ------------------------------------------------------------------ step for step
SHEAR_BOUNDS = StepBounds(
    position=POS_TOL,
    relative=REL_TOL,
    position_reason=POS_REASON,
    velocity_reason=VEL_REASON,
    force_reason=FORCE_REASON,
    stress_reason=STRESS_REASON,
    box_reason=BOX_REASON,
    cell="sheared",
)


def step_records(label: str, nat, ref, d50: float, nsteps: int, dump_every: int) -> tuple[list, list]:
    """:func:`validation.judges.step_for_step` in the sheared cell at this case's bounds; returns
    (records, table row)."""
    recs, s = step_for_step(
        label, nat, ref, d50=d50, nsteps=nsteps, dump_every=dump_every, bounds=SHEAR_BOUNDS, sides=("native", "LAMMPS")
    )
    return recs, short_row(s)


def short_row(s: dict) -> list:
    """A row of the step-for-step table from a judge's summary."""
    return [s["label"], s["last_step"], s["frames"], s["x"], s["v"], s["f"], s["stress"], s["box"]]


# ------------------------------------------------------------------ void cells on the sheared cell
def box_rate(tr, step: int, dt: float) -> np.ndarray:
    """dh/dt (2, 2) = [[d lx/dt, d xy/dt], [0, d ly/dt]] at ``step`` by central differences of the
    box series (one-sided at the ends)."""
    k = int(tr.at([step])[0])
    a, b = max(k - 1, 0), min(k + 1, len(tr.steps) - 1)
    r = (tr.lengths[b] - tr.lengths[a]) / ((tr.steps[b] - tr.steps[a]) * dt)
    return np.array([[r[0], r[2]], [0.0, r[1]]])


def sheared_snapshot(tr, step: int, radii: np.ndarray, dt: float):
    """A :class:`gransim.voidcell.Snapshot` of a frame of a sheared run, the same way for both codes.

    Cell h = [[lx, xy], [0, ly]] of the box after the step; contacts = the overlapping pairs of
    the positions (``find_neighbours(x, r, h, skin=0)``); velocities = the frame's v as they are:
    with ``remap v`` they are lab velocities (the streaming part included; LAMMPS' fix deform
    documentation: the atoms "acquire a velocity that matches the box change", only a crossing of
    a periodic boundary changes v, by the boundary velocity difference), so nothing is added,
    unlike the ``remap x`` snapshot of :func:`validation.dem_compare.snapshot`; the image
    x_j + h n moves with v_j + (dh/dt) n, dh/dt from the box series (:func:`box_rate`).
    """
    fr = tr.frames[step]
    h = sheared_cell(tr.lengths[tr.at([step])[0]])
    nl = find_neighbours(fr["x"], radii, h, skin=0.0)
    return Snapshot(
        positions=fr["x"],
        cell=h,
        contacts_i=nl.i,
        contacts_j=nl.j,
        contacts_shift=nl.shift,
        velocities=fr["v"],
        cell_velocity=box_rate(tr, step, dt),
        radii=radii,
    )


def cell_stats(tr, steps, radii, dt) -> np.ndarray:
    """(len(steps), 2): mean alpha and fraction alpha <= 0 of every frame (NaN without a tessellation)."""
    rows = []
    for s in steps:
        try:
            vc = void_cells(sheared_snapshot(tr, s, radii, dt))
            rows.append([vc.mean_alpha, vc.fraction_nonpositive_alpha])
        except InputError:
            rows.append([np.nan, np.nan])
    return np.array(rows, float).reshape(-1, 2)


# ------------------------------------------------------------------ long horizon
_CONS_CACHE: dict = {}
_LONG_CACHE: dict = {}


def consolidated(ctx: Context) -> dict:
    """The Kuhn 1002-disk assembly consolidated natively exactly as ``biaxial-full`` does (both
    axes servo-controlled to the default confining pressure, FULL_CONSOLIDATION_STEPS steps),
    wrapped into [0, Lx) x [0, Ly) (the positions the data file carries). Keys: packing, settings
    (DEMSettings, flavour lammps), biaxial, velocities, spins, consolidation_error."""
    key = str(ctx.results.resolve())
    if key in _CONS_CACHE:
        return _CONS_CACHE[key]
    pk = _kuhn(ctx)
    dem, bi = dem_defaults(pk)
    servo = _servo(bi)
    eng = DEMEngine(pk, dem)
    out = eng.advance(
        Loading(x=servo, y=servo),
        FULL_CONSOLIDATION_STEPS,
        phase_step0=0,
        phase_box0=(eng.lo.copy(), eng.hi.copy()),
    )
    err = float(np.abs(out["stress"][-1000:, [0, 1], [0, 1]].mean(axis=0) / bi.confining - 1).max())
    common = wrapped_packing(
        Packing(
            positions=eng.x - eng.lo,
            radii=pk.radii,
            cell=np.diag(eng.box_lengths),
            density=pk.density,
            metadata={},
        )
    )
    r = {
        "packing": common,
        "settings": dataclasses.replace(dem, flavour="lammps"),
        "biaxial": bi,
        "velocities": eng.v.copy(),
        "spins": eng.w.copy(),
        "consolidation_error": err,
    }
    _CONS_CACHE[key] = r
    return r


def long_setup(ctx: Context) -> dict:
    """Loading and start state of the long horizon: simple shear at inertial number
    :data:`LONG_INERTIAL` (erate = I / (D50 sqrt(rho/p))), y servo to the biaxial confining p with
    the biaxial servo gain, initial velocities = consolidation velocities + the homogeneous shear
    flow erate * y (so the cell starts in the flow its boundaries impose), up to :data:`LONG_STRAIN`."""
    c = consolidated(ctx)
    pk, dem, bi = c["packing"], c["settings"], c["biaxial"]
    erate = LONG_INERTIAL / (pk.d50 * np.sqrt(pk.density / bi.confining))
    loading = ShearLoading(erate=erate, y="servo", target=bi.confining, gain=bi.servo_gain)
    nsteps = int(np.ceil(LONG_STRAIN / (erate * dem.dt) / LONG_DUMP_EVERY)) * LONG_DUMP_EVERY
    v = c["velocities"].copy()
    v[:, 0] += erate * pk.positions[:, 1]
    return {**c, "loading": loading, "nsteps": nsteps, "v0": v, "erate": erate}


def _perturbed(packing, k: int, ax: int, sign: float):
    x = np.array(packing.positions)
    x[k, ax] *= 1.0 + sign * PERTURB_REL
    return packing.replace(positions=x)


def input_fingerprint(ctx: Context) -> str:
    """SHA-256 of the LAMMPS inputs of the long-horizon reference run (deck text and data file:
    the consolidated state, velocities, spins, law, loading, run length)."""
    s = long_setup(ctx)
    with tempfile.TemporaryDirectory() as tmp:
        deck = write_shear_deck(
            tmp,
            s["packing"],
            s["settings"],
            s["loading"],
            s["nsteps"],
            thermo_every=LONG_THERMO_EVERY,
            dump_every=LONG_DUMP_EVERY,
            velocities=s["v0"],
            spins=s["spins"],
        )
        h = hashlib.sha256(deck.read_bytes())
        h.update((Path(tmp) / DATA).read_bytes())
    return h.hexdigest()


#: long-horizon runs started ahead of the case (:func:`prefetch_long`): key of :func:`_long_key` ->
#: (the plan of :func:`_long_plan`, {job label or "native": future})
_LONG_PENDING: dict = {}


def _long_key(ctx: Context) -> tuple:
    return (str(ctx.results.resolve()), ctx.suite, ctx.lammps)


def _long_plan(ctx: Context) -> tuple[dict, dict, dict]:
    """The run dict of :func:`long_setup`, the LAMMPS jobs {label: job arguments} (none without
    LAMMPS) and the keyword arguments every job shares."""
    s = long_setup(ctx)
    pk, n = s["packing"], s["nsteps"]
    jobs = {}
    if ctx.lammps:
        base = ctx.work("reference", CASE, f"kuhn-1002-strain{LONG_STRAIN:g}")
        jobs["reference"] = {"job_dir": base / "reference", "packing": pk}
        for label in perturb_labels(pk.n, ctx.suite):
            k, ax, sign = _perturbation(label, pk.n)
            jobs[label] = {
                "job_dir": base / f"perturbed-{k}-{ax}",
                "packing": _perturbed(pk, k, ax, sign),
            }
    kw = {
        "settings": s["settings"],
        "loading": s["loading"],
        "nsteps": n,
        "dump_every": LONG_DUMP_EVERY,
        "thermo_every": LONG_THERMO_EVERY,
        "velocities": s["v0"],
        "spins": s["spins"],
        "timeout": ctx.job_timeout(pk.n * n),
    }
    return s, jobs, kw


def _long_native(s: dict):
    """The native long-horizon run of :func:`long_setup`'s ``s`` (sheared cell, LAMMPS' arithmetic)."""
    return run_native_shear(
        s["packing"],
        s["settings"],
        s["loading"],
        s["nsteps"],
        LONG_DUMP_EVERY,
        LONG_THERMO_EVERY,
        velocities=s["v0"],
        spins=s["spins"],
    )


def prefetch_long(ctx: Context) -> None:
    """Queue the long horizon's LAMMPS jobs and its native run on the run's shared background pool
    (``ctx.background``: behind the work of the cases before this one), so that they run while
    earlier cases leave a core idle; :func:`long_runs` collects them and makes what has not
    started. Nothing is queued without that pool (one job at a time, or a case run on its own)."""
    key = _long_key(ctx)
    if ctx.background is None or key in _LONG_CACHE or key in _LONG_PENDING:
        return
    s, jobs, kw = _long_plan(ctx)
    futures = {k: ctx.background.submit(run_shear_job, **j, **kw) for k, j in jobs.items()}
    futures[NATIVE] = ctx.background.submit(_long_native, s)
    _LONG_PENDING[key] = ((s, jobs, kw), futures)


def cancel_long() -> None:
    """Cancel the queued long-horizon runs not yet started and wait for the running ones (a
    validation run that ends early)."""
    while _LONG_PENDING:
        _, (_, futures) = _LONG_PENDING.popitem()
        for f in futures.values():
            f.cancel()
        wait([f for f in futures.values() if not f.cancelled()])


def long_runs(ctx: Context) -> dict:
    """The long-horizon runs (cached per results dir, suite and availability): ``native`` always;
    with ``lmp``: ``reference``, ``ensemble`` {label: Trajectory}, ``manifest``. LAMMPS jobs run in
    ``max(ctx.jobs, 1)`` threads while the native run proceeds; job dirs under
    ``reference/simple-shear/kuhn-1002``. What :func:`prefetch_long` queued is collected: the runs
    already running or finished as they are, the others made here."""
    key = _long_key(ctx)
    if key in _LONG_CACHE:
        return _LONG_CACHE[key]
    pending = _LONG_PENDING.pop(key, None)
    (s, jobs, kw), early = pending if pending is not None else (_long_plan(ctx), {})
    r = dict(s)
    with ThreadPoolExecutor(max_workers=max(int(ctx.jobs), 1)) as pool:
        futures = {}
        for k, j in jobs.items():
            f = early.get(k)
            futures[k] = f if f is not None and not f.cancel() else pool.submit(run_shear_job, **j, **kw)
        try:
            f = early.get(NATIVE)
            r["native"] = f.result() if f is not None and not f.cancel() else _long_native(s)
            done = {k: f.result() for k, f in futures.items()}
        except BaseException:
            for f in (*futures.values(), *early.values()):
                f.cancel()
            raise
    if ctx.lammps:
        r["reference"], r["manifest"] = done.pop("reference")
        r["ensemble"] = {k: v[0] for k, v in done.items()}
    _LONG_CACHE[key] = r
    return r


def _stored_path():
    return stored_dir(STORED_LONG) / f"strain{LONG_STRAIN:g}.npz"


def store_long_reference(ctx: Context) -> None:
    """Store the stress and box series (every STORED_EVERY steps) of the LAMMPS reference and
    perturbed runs of the long horizon, with a README (provenance, input fingerprint), for
    machines without LAMMPS. Needs ``ctx.lammps``; run with suite "full" to store both members:
    ``python -c "from pathlib import Path; from validation.core import Context;
    from validation.cases.shear import store_long_reference;
    store_long_reference(Context('full', Path('results'), lammps=True))"``."""
    if not ctx.lammps:
        raise InputError("store_long_reference: needs LAMMPS (lmp) installed (Context.lammps)")
    r = long_runs(ctx)
    ref, man = r["reference"], r["manifest"]
    steps = ref.steps[ref.steps % STORED_EVERY == 0]
    arrays = {
        "steps": steps,
        "reference/stress": ref.stress[ref.at(steps)],
        "reference/box": ref.lengths[ref.at(steps)],
    }
    names = list(r["ensemble"])
    for k, name in enumerate(names):
        tr = r["ensemble"][name]
        arrays[f"ensemble{k}/stress"] = tr.stress[tr.at(steps)]
        arrays[f"ensemble{k}/box"] = tr.lengths[tr.at(steps)]
    path = _stored_path()
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(
        path,
        names=np.array(json.dumps(names)),
        input_sha256=np.array(input_fingerprint(ctx)),
        **arrays,
    )
    ld = r["loading"]
    (path.parent / "README.md").write_text(
        f"# {STORED_LONG}: LAMMPS series of the long horizon of validation case `simple-shear`\n\n"
        f"- Written by `validation.cases.shear.store_long_reference(ctx)` on "
        f"{datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')}.\n"
        f"- LAMMPS: `{' '.join(man.get('command', []))}` ({man.get('engine_version', '')}; Debian package "
        f"{man.get('engine_package', '')}), serial; deck sha256 {man.get('deck_sha256', '')}; the deck is "
        "`reference_runs.decks.shear.write_shear_deck` of `validation.cases.shear.long_setup`.\n"
        f"- Run: the Kuhn 1002-disk assembly consolidated natively as biaxial-full (servo on both axes to "
        f"p = {ld.target:g} N/m), then {r['nsteps']} steps of `fix deform 1 xy "
        f"erate {ld.erate:.17g} y variable "
        f"v_dy v_ry remap v` (y servo to {ld.target:g} N/m, gain {ld.gain:.6g} 1/(Pa s)): shear strain "
        f"{LONG_STRAIN:g} at inertial number {LONG_INERTIAL:g}; initial "
        "velocities = consolidation + erate*y.\n"
        f"- Runs: reference and {', '.join(names)}.\n"
        f"- `{path.name}` arrays: `steps` (every {STORED_EVERY} steps), "
        "`<run>/stress` (T, 3) xx yy xy of `compute "
        "pressure NULL virial` (compression positive, N/m), `<run>/box` (T, 3) lx ly xy (m) with <run> = "
        "`reference`, `ensemble0`, ...; `names` = JSON list of the ensemble runs; `input_sha256` = "
        "`validation.cases.shear.input_fingerprint` (SHA-256 of deck text + data file): the case refuses the "
        "series when its inputs differ.\n"
    )


def load_stored_long():
    """The stored series as {reference, ensemble, input_sha256} Trajectories without frames, or None."""
    path = _stored_path()
    if not path.exists():
        return None
    z = np.load(path)
    steps = z["steps"]
    names = json.loads(str(z["names"]))
    return {
        "reference": Trajectory(steps, z["reference/stress"], z["reference/box"], {}),
        "ensemble": {
            n: Trajectory(steps, z[f"ensemble{k}/stress"], z[f"ensemble{k}/box"], {}) for k, n in enumerate(names)
        },
        "input_sha256": str(z["input_sha256"]),
    }


ENVELOPE_REASON = (
    "chaos: LAMMPS' own divergence under a round-off perturbation (one coordinate moved by 1e-15 "
    "relative; one run in the default suite, two in the full suite) is the envelope E(t), taken as its "
    "largest value within +/- one dump interval (3000 steps, about the time of one decade of its mean "
    "growth, shown as info): a slip event makes a divergence jump by decades within ~100 steps, and the "
    "native run, seeded by summation-order round-off at every step rather than one 1e-15 kick, meets it up "
    "to ~1000 steps earlier. Native vs LAMMPS must stay within 10 times that (one decade: the magnitude "
    "of the seed is uncertain to that), or within the short-horizon bound (1e-10 D50 positions, 1e-8 "
    "stress) while the envelope is below it (validation.judges.EnvelopeRule)"
)
ENVELOPE_WINDOW = LONG_DUMP_EVERY  # steps
#: the native run and the LAMMPS reference are two members of the same round-off ensemble: if each
#: stays within R of the ensemble's mean curve they differ by up to 2R, while the band (a perturbed
#: run's deviation from the reference) estimates R to 2R; so the tolerance is twice the band
CURVE_FACTOR = 2.0
CURVE_REASON = (
    "band = the largest deviation of the perturbed LAMMPS runs from the LAMMPS reference along the "
    "curve (the curve's own uncertainty under round-off); tolerance 2 x band: native and reference are two "
    "samples of that ensemble, so they may be apart by twice what one perturbed run is from the reference"
)
STATS_REASON = (
    "void-cell statistics of every dump: band = the largest deviation of the perturbed LAMMPS runs from "
    "the reference (instantaneous velocity fields decorrelate once positions differ by ~1e-4 D50); "
    "tolerance 2 x band, as for the curves"
)
#: the codes the long horizon runs (long_runs' jobs and the stored series)
LONG_CODES = ("lammps",)
#: the envelope criterion of the long horizon (validation.judges.EnvelopeRule): the sheared-cell native
#: run differs from LAMMPS by summation-order round-off, hence the window and the step-for-step floors
LONG_RULE = EnvelopeRule(
    factor=ENVELOPE_FACTOR,
    window=ENVELOPE_WINDOW,
    position_floor=POS_TOL,
    stress_floor=REL_TOL,
    curve_factor=CURVE_FACTOR,
    reason=ENVELOPE_REASON,
)


def shear_curves(tr, p: float):
    """Shear strain (xy - xy0)/ly0, shear stress tau/p (tension positive: -sigma_xy of the
    compression-positive virial) and normal strain ln(ly/ly0) (dilation positive)."""
    b = tr.lengths
    return (b[:, 2] - b[0, 2]) / b[0, 1], -tr.stress[:, 2] / p, np.log(b[:, 1] / b[0, 1])


# ------------------------------------------------------------------ the short horizon as a declaration
@dataclass(frozen=True)
class ShearCode:
    """Where a code's runs of the short horizon come from: its stored jobs (one directory per
    loading of SHORT_CASES under reference_runs/stored/<stored>), the prefix of its live job
    directories, how a job of it is run and how its output is read, and the suffix of its record
    labels. A code is one more entry of :data:`SHEAR_CODES`; its comparisons follow from
    :func:`short_plan`."""

    stored: str
    live_job: str
    run_job: object
    read: object
    suffix: str = ""


SHEAR_CODES = {"lammps": ShearCode("shear-short-lammps", "live-120", run_shear_job, read_lammps_shear)}
#: why a code has no column here
SHEAR_NA = {"liggghts": LIGGGHTS_NA}


def short_plan(ctx: Context, manifests: dict | None = None) -> tuple[list, list]:
    """The runs and comparisons of the short horizon: for every loading of SHORT_CASES and every
    code of :data:`SHEAR_CODES`, native (the sheared-cell engine in that code's arithmetic)
    against the code's stored run (3000 steps) and, with the code installed, against the same
    deck run now (:data:`LIVE_STEPS`), step for step in the sheared cell. ``manifests`` collects
    the live jobs' manifests and directories (key: the comparison label)."""
    manifests = {} if manifests is None else manifests
    runs, comps = [], []
    for name in SHORT_CASES:
        p, s, ld, n = short_case(name)
        for code in CODES:
            sc = SHEAR_CODES.get(code)
            if sc is None:
                continue
            d = stored_dir(sc.stored) / name

            def live(name=name, sc=sc, p=p, s=s, ld=ld):
                job = ctx.work("reference", CASE, f"{sc.live_job}-{name}")
                tr, man = sc.run_job(
                    job, p, s, ld, LIVE_STEPS, LIVE_DUMP_EVERY, timeout=ctx.job_timeout(p.n * LIVE_STEPS)
                )
                manifests[f"live-120/{name}{sc.suffix}"] = (man, job)
                return tr

            for scen, steps, every in (("stored-120", n, SHORT_DUMP_EVERY), ("live-120", LIVE_STEPS, LIVE_DUMP_EVERY)):
                key = f"{scen}/{name}/{code}"
                if scen == "stored-120":
                    ref = Run(
                        key,
                        code,
                        code,
                        f"stored {sc.stored}/{name}",
                        functools.partial(sc.read, d / "log.lammps", d / "dump.atoms"),
                        verify=stored_job(d),
                    )
                else:
                    ref = Run(key, code, code, f"{scen} deck run now", live, live=True)
                nat = Run(
                    f"native/{key}",
                    NATIVE,
                    code,
                    f"native sheared cell, {code} arithmetic",
                    functools.partial(run_native_shear, p, s, ld, steps, every),
                )
                runs += [nat, ref]
                comps.append(
                    Comparison(
                        "step",
                        f"{CASE}/{scen}/{name}{sc.suffix}",
                        (nat.key, ref.key),
                        MATRIX_REASON,
                        {"d50": p.d50, "nsteps": steps, "dump_every": every, "bounds": SHEAR_BOUNDS},
                    )
                )
                if scen == "stored-120":  # Kuhn's void cells of every dump, on the sheared cell
                    comps.append(
                        Comparison(
                            "cells",
                            f"{CASE}/voidcells-120/{name}{sc.suffix}",
                            (nat.key, ref.key),
                            LIST_REASON,
                            {
                                "frames": [int(k) for k in expected_frames(n, SHORT_DUMP_EVERY)],
                                "radii": p.radii,
                                "dt": s.dt,
                                "snapshot": sheared_snapshot,
                            },
                        )
                    )
    return runs, comps


# ------------------------------------------------------------------ YADE's columns
#: YADE's runs of the short horizon: each loading of SHORT_CASES undamped
#: (reference_runs.yade.dem.short_shear), stored under reference_runs/stored/simple-shear-yade/<name>
YADE_STORED = "simple-shear-yade"
YADE_THERMO_EVERY = 10
YADE_DUMP_EVERY = 500
YADE_SHEAR_CROSS_REASON = (
    "YADE's run is undamped (its 2023.02a damped law takes a periodic image's velocity with the wrong sign, "
    "docs/yade.md), so LAMMPS runs the same deck undamped; the codes' laws and kinematics differ physically (raw "
    "difference shown, with why), ten decades above a 1e-15 envelope, so the check is that the codes' difference "
    "equals the difference of the native runs in their two arithmetics: YADE's side is equal to the bit, the "
    "sheared-cell native run differs from LAMMPS by the summation order only (measured 8e-14 to 1.5e-13 of the "
    "stress and 2.6e-14 to 4.7e-14 D50 here, docs/shear.md), so the step-for-step bounds 1e-10 D50 and 1e-8"
)


def yade_plan(ctx: Context, manifests: dict) -> tuple[list, list]:
    """YADE's runs and comparisons of the short horizon (``yade-120/<loading>``: 120 disks, 3000
    steps, undamped): native in YADE's arithmetic against YADE's sheared cell step for step at zero
    tolerance (the live job, or with YADE absent its stored output); LAMMPS running the same deck
    undamped against YADE, their difference explained by the native runs in the two arithmetics
    (LIGGGHTS has no sheared periodic box: not applicable)."""
    if "yade" not in CODES:
        return [], []
    runs, comps = [], []
    for name in SHORT_CASES:
        p, s, ld, n = short_shear(name)
        every = {"thermo_every": YADE_THERMO_EVERY, "dump_every": YADE_DUMP_EVERY}
        job = shear_job(p, s, ld, n, **every)
        d = stored_dir(YADE_STORED) / name
        sc = f"yade-120/{name}"

        def live_yade(name=name, job=job, p=p, n=n, sc=sc):
            job_dir = ctx.work("reference", CASE, f"yade-120-{name}")
            return yade_runs.live(job_dir, job, ctx.job_timeout(p.n * n), True, manifests, f"{sc}/yade")

        runs += [
            Run(f"{sc}/yade", "yade", "yade", f"{sc}: YADE 2023.02a run now (undamped)", live_yade, live=True,
                fallback=f"{sc}/yade-stored"),
            Run(f"{sc}/yade-stored", "yade", "yade", f"stored {YADE_STORED}/{name}", yade_runs.stored(d, True),
                verify=yade_runs.stored_verify(d, job, True)),
            Run(f"native/{sc}/yade", NATIVE, "yade", "native, yade arithmetic (yade_run)",
                functools.partial(yade_runs.native, p, s, ld, n, YADE_THERMO_EVERY, YADE_DUMP_EVERY, True)),
        ]  # fmt: skip
        params = {"d50": p.d50, "nsteps": n, **every}
        comps.append(
            Comparison(
                "step",
                f"{CASE}/{sc}",
                (f"native/{sc}/yade", f"{sc}/yade"),
                YADE_BIT_REASON,
                {**params, "bounds": dataclasses.replace(YADE_BOUNDS, cell="sheared")},
            )
        )
        if "lammps" not in CODES:
            continue

        def live_lammps(name=name, p=p, s=s, ld=ld, n=n, sc=sc):
            job_dir = ctx.work("reference", CASE, f"yade-120-{name}-lammps")
            tr, man = run_shear_job(
                job_dir, p, s, ld, n, YADE_DUMP_EVERY, thermo_every=YADE_THERMO_EVERY, timeout=ctx.job_timeout(p.n * n)
            )
            manifests[f"{sc}/lammps"] = (man, job_dir)
            return tr

        runs += [
            Run(f"{sc}/lammps", "lammps", "lammps", f"{sc}: the LAMMPS deck undamped, run now", live_lammps, live=True),
            Run(f"native/{sc}/lammps", NATIVE, "lammps", "native sheared cell, lammps arithmetic, undamped",
                functools.partial(run_native_shear, p, s, ld, n, YADE_DUMP_EVERY, thermo_every=YADE_THERMO_EVERY)),
        ]  # fmt: skip
        comps.append(
            Comparison(
                "explained",
                f"{CASE}/{sc}/lammps-yade",
                (f"{sc}/lammps", f"{sc}/yade", f"native/{sc}/lammps", f"native/{sc}/yade"),
                YADE_SHEAR_CROSS_REASON,
                {
                    **params,
                    "position_tol": POS_TOL,
                    "relative_tol": REL_TOL,
                    "reason": YADE_SHEAR_CROSS_REASON,
                    "cell": "sheared",
                },
            )
        )
    return runs, comps


# ------------------------------------------------------------------ the case
@case(CASE, TITLE, order=35, prefetch=prefetch_long, cancel=cancel_long)
def simple_shear_case(ctx: Context) -> CaseResult:
    res = CaseResult(
        CASE,
        TITLE,
        "True periodic simple shear: a sheared (triclinic) periodic cell with "
        "LAMMPS' <code>fix deform 1 xy erate R "
        "remap v</code> (Lees-Edwards: positions are not mapped, images across "
        "y move with the box rate, a disk "
        "crossing y has its velocity changed by it), constant volume or under a "
        "y normal-stress servo. Native: "
        "<code>gransim.dem.sheared.ShearEngine</code> in LAMMPS' arithmetic "
        "(docs/shear.md); LAMMPS: the mirror deck "
        "<code>reference_runs/decks/shear.py</code>. <i>stored-120</i>: the stored LAMMPS runs "
        "<code>reference_runs/stored/shear-short-lammps</code> (120 disks, 3000 "
        "steps, xy erate 2.5 1/s, 1.5% strain), "
        "compared at every step and dump. <i>live-120</i>: the same decks, 1000 "
        "steps, run now. <i>kuhn-1002</i> "
        "(default/full suites): the Kuhn 1002-disk assembly consolidated "
        "natively as in biaxial-full, sheared to "
        f"{100 * LONG_STRAIN:g}% under the y servo at the biaxial confining pressure, at inertial number "
        f"{LONG_INERTIAL:g} (quasi-static, and a LAMMPS job of about 20 s), "
        "judged against LAMMPS' own round-off "
        "envelope. Void cells (Kuhn, eqs 18-20) from snapshots of both codes "
        "built identically on the sheared cell.",
    )
    res.notes.append(
        "Velocities: with <code>remap v</code> the dumped v are lab velocities (streaming part included): "
        "LAMMPS' fix deform documentation says the atoms 'acquire a velocity that matches the box change' "
        "and only a periodic crossing changes v (Domain::pbc with deform_vremap); dump custom vx is atom->v. "
        "The native engine's v are lab velocities (ShearEngine.peculiar_velocities subtracts the flow) and "
        "agree with the dumped ones step for step below, so the snapshots take v as it is and dh/dt "
        "from the box series."
    )
    header = [
        "run",
        "steps",
        "frames",
        "max|dx|/D50",
        "max|dv|/max|v|",
        "max|df|/max|f|",
        "max rel stress",
        "max|dbox|/D50",
    ]
    for code in CODES:
        if code not in SHEAR_CODES and code != "yade":  # YADE's runs: yade_plan
            why = SHEAR_NA.get(code, f"no sheared-cell run of {code_label(code)} is declared (SHEAR_CODES)")
            res.skip_pair(pair_key(NATIVE, code), why)
            for other in CODES:
                if other != code:
                    res.skip_pair(pair_key(code, other), why)
    manifests = {}
    runs, comps = short_plan(ctx, manifests)
    y_runs, y_comps = yade_plan(ctx, {})  # YADE's manifests: in its job directories
    out = evaluate(res, ctx, runs + y_runs, comps + y_comps)
    rows = [short_row(out.summaries[c.label]) for c in comps + y_comps if c.kind == "step" and c.label in out.summaries]
    short_div = {}
    vc_fig = None
    for c in comps:
        nat_key, ref_key = c.runs
        if not ref_key.startswith("stored-120/") or c.label not in out.summaries:
            continue
        name = ref_key.split("/")[1]
        if c.kind == "step":
            nat, ref = out.runs[nat_key], out.runs[ref_key]
            short_div[name] = stress_differences(nat, ref, steps=np.intersect1d(nat.steps, ref.steps))[:2]
            continue
        cmp = out.summaries[c.label]
        if cmp["no_tessellation"]:
            res.notes.append(
                f"stored-120/{name}: steps {cmp['no_tessellation']} have no framework spanning the cell on "
                "either side (identical outcome, no cells to compare there)."
            )
        if name == "servo" and cmp["vc"] and cmp["vc"][-1][0] is not None:
            vc_fig = (cmp["steps"][-1], *cmp["vc"][-1])
    for key, (man, job) in manifests.items():
        res.notes.append(
            f"{key}: <code>{' '.join(man.get('command', []))}</code> "
            f"({man.get('engine_version', '')}) in <code>{job}</code>."
        )
    res.tables.append(("Step for step, native vs LAMMPS: largest differences per run", header, rows))
    if vc_fig is not None:
        res.figures.append(
            (
                _cell_maps(ctx, vc_fig),
                (
                    f"Void cells on the sheared cell (stored-120/servo, step "
                    f"{vc_fig[0]}, 1.5% shear strain), shaded by alignment alpha (eq "
                    "18 of Kuhn; white <= 0): "
                    "native left, LAMMPS right (gransim.voidcell.plots.plot_alignment draws the cell "
                    "parallelogram and the faces across its tilted boundary)."
                ),
            )
        )
    res.figures.append(
        (
            _short_plot(ctx, short_div),
            (
                "Short horizon: relative stress difference native vs LAMMPS "
                "at every step of the stored runs (round-off of the summation order)."
            ),
        )
    )
    if ctx.suite == "quick":
        return res
    _long(ctx, res)
    return res


def long_plan(ctx: Context) -> tuple[list, list]:
    """The long horizon as a declaration: per code of :data:`LONG_CODES`, the native sheared-cell run
    against the code's ensemble (its reference and perturbed runs now, or with the code absent the
    stored series in their place) by :func:`validation.judges.ensemble_envelope` with
    :data:`LONG_RULE` (divergence in the sheared cell, the shear stress and dilatancy curves)."""
    s = long_setup(ctx)
    pk, n, p = s["packing"], s["nsteps"], s["loading"].target
    want = tuple(perturb_labels(pk.n, ctx.suite))
    used: dict = {}  # "stored": the stored series stood in (no frames)

    def native():
        return long_runs(ctx)["native"]

    def live():
        r = long_runs(ctx)
        return Ensemble(
            r["reference"], r["ensemble"], want, LONG_THERMO_EVERY, False, "LAMMPS jobs run now", r["manifest"]
        )

    def stored():
        used["stored"] = True
        z = load_stored_long()
        name = f"reference_runs/stored/{STORED_LONG}/{_stored_path().name}"
        if z is None:
            empty = Trajectory(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)), {})
            return Ensemble(empty, {}, want, STORED_EVERY, True, name, refused=f"no stored series {name}")
        refused = ""
        if z["input_sha256"] != input_fingerprint(ctx):
            refused = (
                "made from other inputs than this run's (input fingerprint differs: the consolidation, the packing "
                "or the loading changed); regenerate it with validation.cases.shear.store_long_reference where "
                "LAMMPS is installed"
            )
        members = {k: v for k, v in z["ensemble"].items() if k in want}
        return Ensemble(z["reference"], members, want, STORED_EVERY, True, name, refused=refused)

    def curves_of(tr):
        return shear_curves(tr, p)

    runs, comps = [], []
    for code in CODES:
        if code not in LONG_CODES:
            continue
        runs += [
            Run(f"native/kuhn-1002/{code}", NATIVE, code, f"native sheared cell, {code} arithmetic", native),
            Run(f"stored/kuhn-1002/{code}", code, code, "stored series", stored),
            Run(
                f"kuhn-1002/{code}",
                code,
                code,
                "reference and perturbed runs now",
                live,
                live=True,
                fallback=f"stored/kuhn-1002/{code}",
            ),
        ]
        comps.append(
            Comparison(
                "ensemble",
                f"{CASE}/kuhn-1002/{code}",
                (f"native/kuhn-1002/{code}", f"kuhn-1002/{code}"),
                MATRIX_REASON,
                {
                    "nsteps": n,
                    "native_every": LONG_THERMO_EVERY,
                    "dump_every": LONG_DUMP_EVERY,
                    "d50": pk.d50,
                    "rule": LONG_RULE,
                    "curves_of": curves_of,
                    "checks": (
                        CurveCheck(1, "shear_stress", "max|d tau/p| along the curve", CURVE_REASON),
                        CurveCheck(2, "normal_strain", "max|d ln(ly/ly0)| along the curve", CURVE_REASON),
                    ),
                    "cell": "sheared",
                },
            )
        )

        def frames():
            return [] if used.get("stored") else [int(k) for k in expected_frames(n, LONG_DUMP_EVERY)]

        def statistics(tr):
            return cell_stats(tr, frames(), pk.radii, s["settings"].dt)

        def profile(ens):
            # remap v keeps the streaming velocity in the dumped v: its x profile has the slope of the flow
            fr = ens.reference.frames[frames()[-1]]
            return {("", "velocity_profile"): np.polyfit(fr["x"][:, 1], fr["v"][:, 0], 1)[0] / s["erate"]}

        comps.append(
            Comparison(
                "statistics", f"{CASE}/kuhn-1002/voidcells", (f"native/kuhn-1002/{code}", f"kuhn-1002/{code}"),
                MATRIX_REASON,
                lambda: {"frames": frames(), "statistics": statistics, "factor": LONG_RULE.curve_factor,
                         "checks": ((0, "mean_alpha"), (1, "fraction_alpha_le_0")), "reason": STATS_REASON,
                         "diff": defined_diff, "without_frames": NO_FRAMES},
            )
        )  # fmt: skip
        comps.append(
            Comparison(
                "analytic", f"{CASE}/kuhn-1002/voidcells", (f"kuhn-1002/{code}",), MATRIX_REASON,
                lambda: {"expected": [("", "velocity_profile")] if frames() else [], "values": profile,
                         "bound": {"velocity_profile": Bound(math.nan, PROFILE_REASON, "info")},
                         "metric": lambda item, quantity, vals: "slope d v_x/d y of LAMMPS' last dump / erate"},
                pair=f"native-{code}",
            )
        )  # fmt: skip
    return runs, comps


NO_FRAMES = "the stored series keeps no positions: the long horizon's void cells are not made"
PROFILE_REASON = "lab velocities (remap v): about 1 (the homogeneous shear flow); peculiar ones would give ~0"


def _long(ctx: Context, res: CaseResult) -> None:
    s = long_setup(ctx)
    n, ld = s["nsteps"], s["loading"]
    p = ld.target
    res.notes.append(
        f"kuhn-1002: consolidation (native, biaxial-full's) within {100 * s['consolidation_error']:.2f}% "
        f"of p = {p:g} N/m; shear at erate {s['erate']:.4g} 1/s (inertial number {LONG_INERTIAL:g}), "
        f"dt {s['settings'].dt:.4g} s, {n} steps to {100 * LONG_STRAIN:g}% shear strain, dumps every "
        f"{LONG_DUMP_EVERY} steps, stress every {LONG_THERMO_EVERY} steps."
    )
    runs, comps = long_plan(ctx)
    out = evaluate(res, ctx, runs, comps)
    c = next(c for c in comps if c.kind == "ensemble")
    ens, nat = out.run(c.runs[1]), out.run(c.runs[0])
    if ens.stored:
        res.notes.append(
            f"<b>LAMMPS is absent</b>: the long horizon is compared with the stored series <code>{ens.source}</code> "
            f"(stress and box every {STORED_EVERY} steps of the reference and perturbed LAMMPS runs, README there); "
            "positions are not stored, so the position envelope and the void cells of the long horizon are not made."
            + (f" It cannot be used here: {ens.refused}." if ens.refused else "")
        )
    else:
        man = ens.manifest or {}
        res.notes.append(
            f"kuhn-1002 LAMMPS: <code>{' '.join(man.get('command', []))}</code> "
            f"({man.get('engine_version', '')}), reference job {ens.reference.elapsed:.1f} s (0: reused), native "
            f"{nat.elapsed:.1f} s."
        )
    sm = out.summaries[c.label]
    if not sm["complete"]:
        res.notes.append(
            "<b>Incomplete evidence</b> (kuhn-1002): a run is missing steps, frames or ensemble members "
            "(records above); no envelope verdict is made on what remains."
        )
        return
    ref, div, sdiv, cur = ens.reference, sm["div"], sm["sdiv"], sm["curves"]
    frames = [] if ens.stored else [int(k) for k in expected_frames(n, LONG_DUMP_EVERY)]
    res.tables.append(
        (
            "kuhn-1002: end of the shear",
            ["run", "shear strain %", "tau/p", "peak tau/p", "ln(ly/ly0) %"],
            [
                [
                    k,
                    float(100 * c[0][-1]),
                    float(c[1][-1]),
                    float(c[1].max()),
                    float(100 * c[2][-1]),
                ]
                for k, c in cur.items()
            ],
        )
    )
    vc = out.by_kind.get((f"{CASE}/kuhn-1002/voidcells", "statistics"), {})
    if frames and vc.get("complete"):
        st = dict(vc["stats"])
        strains = (ref.lengths[ref.at(frames), 2] - ref.lengths[0, 2]) / ref.lengths[0, 1]
        res.figures.append(
            (
                _stats_plot(ctx, strains, st),
                (
                    "kuhn-1002: mean alignment alpha and fraction alpha <= 0 of "
                    "the void cells over the shear (native dashed, LAMMPS and its perturbed runs)."
                ),
            )
        )
    res.figures += _long_plots(ctx, div, sdiv, cur)


# ------------------------------------------------------------------ figures
def _plt():
    # lazy: pyplot costs ~1.5 s of import (measured, load 9); only the figures need it
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _cell_maps(ctx, fig_data):
    # lazy: imports matplotlib (~1.5 s); only the figures need it
    from gransim.voidcell.plots import plot_alignment

    plt = _plt()
    step, a, b = fig_data
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.6))
    for ax, vc, who in ((axes[0], a, "native"), (axes[1], b, "LAMMPS")):
        plot_alignment(vc, ax=ax)
        ax.set_title(
            f"{who}, step {step}: mean alpha {vc.mean_alpha:.3f}, {100 * vc.fraction_nonpositive_alpha:.1f}% <= 0",
            fontsize=9,
        )
    fig.tight_layout()
    path = ctx.figure_path("simple_shear_voidcells.png")
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _short_plot(ctx, short_div):
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6.5, 3.8))
    for name, (steps, rel) in short_div.items():
        ax.semilogy(steps, np.maximum(rel, 1e-18), lw=0.8, label=name)
    ax.axhline(REL_TOL, color="r", lw=0.8, ls=":", label="tolerance 1e-8")
    ax.set_xlabel("step")
    ax.set_ylabel("max|dsigma|/max|sigma| (0 drawn at 1e-18)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = ctx.figure_path("simple_shear_short.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _stats_plot(ctx, strains, st):
    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    for name, a in st.items():
        ls = "--" if name == "native" else "-"
        axes[0].plot(100 * strains, a[:, 0], ls, lw=1, label=name)
        axes[1].plot(100 * strains, 100 * a[:, 1], ls, lw=1, label=name)
    axes[0].set_ylabel("mean alpha")
    axes[1].set_ylabel("alpha <= 0 (%)")
    for ax in axes:
        ax.set_xlabel("shear strain (%)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    path = ctx.figure_path("simple_shear_voidcell_stats.png")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _long_plots(ctx, div, sdiv, cur) -> list:
    plt = _plt()
    figs = []
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, (steps, d) in div.items():
        axes[0].semilogy(
            steps,
            np.maximum(d, 1e-18),
            "o-" if name.startswith("native") else "-",
            ms=3,
            label=name,
        )
    axes[0].set_xlabel("step of the shear")
    axes[0].set_ylabel("max |x_a - x_b| / D50 (mod the sheared cell)")
    if not div:
        axes[0].text(
            0.5,
            0.5,
            "positions not stored (LAMMPS absent)",
            ha="center",
            transform=axes[0].transAxes,
        )
    for name, (steps, d) in sdiv.items():
        axes[1].semilogy(steps, np.maximum(d, 1e-18), lw=0.8, label=name)
    axes[1].set_xlabel("step of the shear")
    axes[1].set_ylabel("max|sigma_a - sigma_b| / max|sigma_b| (0 drawn at 1e-18)")
    for ax in axes:
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8)
    fig.tight_layout()
    path = ctx.figure_path("simple_shear_divergence.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    figs.append(
        (
            path,
            (
                "kuhn-1002: divergence from the LAMMPS reference run over time, of the native run and of "
                "LAMMPS under a 1e-15 perturbation (the envelope); left positions "
                "at every dump, right stress."
            ),
        )
    )
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, (g, tau, en) in cur.items():
        ls = "--" if name == "native" else "-"
        axes[0].plot(100 * g, tau, ls, lw=1, label=name)
        axes[1].plot(100 * g, 100 * en, ls, lw=1, label=name)
    axes[0].set_ylabel("shear stress tau / p (tension positive)")
    axes[1].set_ylabel("normal strain ln(ly/ly0) (%), dilation positive")
    for ax in axes:
        ax.set_xlabel("shear strain (xy - xy0)/ly0 (%)")
        ax.legend(fontsize=8)
    fig.tight_layout()
    path = ctx.figure_path("simple_shear_curves.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    figs.append(
        (
            path,
            (
                "kuhn-1002: shear stress-strain and dilatancy under the y servo, "
                "native (dashed) and LAMMPS runs "
                "(the perturbed runs' spread is the band)."
            ),
        )
    )
    return figs
