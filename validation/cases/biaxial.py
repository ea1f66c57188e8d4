"""Cases ``biaxial-short`` and ``biaxial-full``: the native DEM engine against LIGGGHTS 3.8.0.

Both codes run the same deck (``reference_runs.decks.biaxial.write_biaxial_deck``: hooke/stiffness
with tangential history, the same time step, skin, rebuild rule, servo and rate loading).

* ``biaxial-short``: step for step over thousands of steps. The engine repeats LIGGGHTS'
  floating-point operations in LIGGGHTS' order, so positions, velocities, spins, per-particle
  forces and torques, the stress and the box are expected to agree bit for bit.
* ``biaxial-full``: the compression of the Kuhn assembly. Round-off differences (another CPU,
  another summation order) grow exponentially in a granular assembly, so the native-vs-LIGGGHTS
  difference is judged against LIGGGHTS' own sensitivity: the same deck with one coordinate moved
  by 1e-15 relative, and the same deck on 2 MPI processes.
"""

from __future__ import annotations

import csv
import dataclasses
import datetime
import functools
import hashlib
import html
import json
from concurrent.futures import ThreadPoolExecutor, wait
from dataclasses import dataclass

import numpy as np

from gransim import generation
from gransim.dem import AxisControl, DEMEngine, Loading
from gransim.dem import default_settings as dem_defaults
from gransim.geometry import Packing
from gransim.io import atomic_path, load_packing
from reference_runs.decks.biaxial import SHORT_CASE_DUMP_EVERY, short_case
from reference_runs.native_schema import trajectory_to_run_file
from reference_runs.yade.dem import biaxial_job, short_biaxial, undamped

from .. import yade_runs
from ..codes import CODES, NATIVE, code_label, pair_key, why_they_differ
from ..core import (
    CaseResult,
    Context,
    case,
    stored_dir,
)
from ..dem_compare import (
    Trajectory,
    read_reference,
    run_native,
    run_reference_job,
)
from ..judges import BITWISE_RULE, CurveCheck, Ensemble, StepBounds, step_for_step
from ..matrix import Comparison, Run, evaluate, stored_job

POS_TOL = 1e-10  # of D50
POS_REASON = (
    "the engine does LIGGGHTS' floating-point operations in LIGGGHTS' order (neighbour list, "
    "ghosts, step order), so the doubles are equal; 1e-10 D50 (the step-for-step bound) leaves room for another "
    "CPU/compiler, whose round-off grows ~10x per 1000 steps (docs/liggghts.md), yet is 7 decades below the "
    "8e-4 D50 that 1% stiffer contacts give within 1000 steps (measured, tests/validation)"
)
REL_TOL = 1e-8
STRESS_REASON = (
    "virial stress = sum over the same contacts in the same order: equal doubles expected; 1e-8 "
    "relative (of the largest component, sigma_xy passes through 0) allows round-off growth on "
    "another machine while a 1% stiffness change gives ~1e-2"
)
VEL_REASON = (
    "velocities/spins relative to the largest value: same bound as the stress, as they come from the "
    "same forces by the same kicks"
)
FORCE_REASON = (
    "per-particle force/torque applied in the step (dump fx fy tqz) relative to the largest: sums of "
    "the contact forces in the same order. Per-contact rows are not compared: LIGGGHTS' "
    "pair/gran/local re-evaluates contacts at output time (remapped positions, full-step "
    "velocities, stale ghosts: up to 3.9% off the applied force, docs/liggghts.md)"
)
BOX_REASON = "box lengths after fix deform (servo/rate) in D50: the servo uses the stress, same bound as positions"

SHORT_KUHN_STEPS = 5000
SHORT_DUMP_EVERY = 500
LIVE_SHORT_STEPS = 1000


def _kuhn(ctx: Context):
    paths = generation.standard_packings(ctx.results / "packings", names=["kuhn-1002"])
    return load_packing(paths["kuhn-1002"])


def _servo(bi):
    return AxisControl("servo", target=bi.confining, gain=bi.servo_gain)


#: display names of the reference codes
CODE = {code: code_label(code) for code in CODES}

#: the step-for-step bounds of the biaxial decks (every code, native in that code's arithmetic)
SHORT_BOUNDS = StepBounds(
    position=POS_TOL,
    relative=REL_TOL,
    position_reason=POS_REASON,
    velocity_reason=VEL_REASON,
    force_reason=FORCE_REASON,
    stress_reason=STRESS_REASON,
    box_reason=BOX_REASON,
)


def step_records(
    label: str, nat, lig, d50: float, nsteps: int, dump_every: int, thermo_every: int = 1, code: str = "LIGGGHTS"
) -> tuple[list, list]:
    """:func:`validation.judges.step_for_step` at the biaxial bounds: records and a table row
    (run, last step, frames, positions, velocities, forces, stress)."""
    recs, s = step_for_step(
        label,
        nat,
        lig,
        d50=d50,
        nsteps=nsteps,
        dump_every=dump_every,
        thermo_every=thermo_every,
        bounds=SHORT_BOUNDS,
        sides=("native", code),
    )
    return recs, short_row(s)


def short_row(s: dict) -> list:
    """A row of the step-for-step table from a judge's summary."""
    return [s["label"], s["last_step"], s["frames"], s["x"], s["v"], s["f"], s["stress"]]


def _flavour(settings, engine: str):
    """The native settings that mirror ``engine``'s arithmetic (``DEMSettings.flavour``)."""
    return dataclasses.replace(settings, flavour=engine)


def _stored_log(d):
    """The log of a stored job directory (``log.liggghts`` or ``log.lammps``)."""
    for name in ("log.liggghts", "log.lammps"):
        if (d / name).exists():
            return d / name
    return d / "log.lammps"


CROSS_SHORT_REASON = (
    "the two codes' Hooke history laws differ in their arithmetic and in two physical details "
    "(LAMMPS resets a spring when its pair stops touching and caps spring plus damping; "
    "docs/lammps.md); each native flavour reproduces its code bit for bit, so LIGGGHTS minus LAMMPS "
    "must equal native(liggghts) minus native(lammps) to the bitwise bounds: the cross-code "
    "difference is explained, term by term, by the documented differences"
)
NATIVE_LAMMPS_REASON = (
    "native flavour lammps does LAMMPS' floating-point operations in LAMMPS' order (docs/lammps.md): "
    "positions 1e-10 D50 and stress 1e-8 as for LIGGGHTS"
)


@dataclass(frozen=True)
class ShortCode:
    """Where a code's runs of biaxial-short come from: its stored job (the 120-disk deck, 3000
    steps) under reference_runs/stored, its live job directories under
    results/reference/biaxial-short, and the reason of its native column. A code is one more
    entry of :data:`SHORT_CODES`; its comparisons follow from :func:`short_plan`."""

    stored: str
    live_job: str
    kuhn_job: str
    reason: str


SHORT_CODES = {
    "liggghts": ShortCode("biaxial-short", "live-120", "kuhn-1002", POS_REASON),
    "lammps": ShortCode("biaxial-short-lammps", "live-120-lammps", "kuhn-1002-lammps", NATIVE_LAMMPS_REASON),
}


def short_plan(ctx: Context, manifests: dict | None = None) -> tuple[list, list]:
    """The runs and comparisons of biaxial-short.

    Scenarios: ``stored-120`` (the stored 120-disk runs, 3000 steps, every suite), ``live-120``
    (the same deck run now, 1000 steps, codes installed), ``kuhn-1002`` (default and full suites,
    codes installed: the Kuhn assembly consolidated under the servo on both axes, 5000 steps).
    In each: every code of :data:`SHORT_CODES` against native in its arithmetic, step for step
    (:func:`validation.judges.step_for_step`), and every two codes against each other, their
    difference explained by the two native flavours (:func:`validation.judges.explained_difference`).
    ``manifests`` collects the live jobs' manifests (key: run key)."""
    manifests = {} if manifests is None else manifests
    p, s, ld, n = short_case()
    scen = {
        "stored-120": (lambda: p, ld, n, SHORT_CASE_DUMP_EVERY),
        "live-120": (lambda: p, ld, LIVE_SHORT_STEPS, 250),
    }
    if ctx.suite != "quick":
        kuhn = functools.cache(lambda: _kuhn(ctx))
        dem = functools.cache(lambda: dem_defaults(kuhn()))

        def kuhn_loading():
            bi = dem()[1]
            return Loading(x=_servo(bi), y=_servo(bi))

        scen["kuhn-1002"] = (kuhn, None, SHORT_KUHN_STEPS, SHORT_DUMP_EVERY)

    def settings_of(name, code):
        return _flavour(dem()[0] if name == "kuhn-1002" else s, code)

    def loading_of(name):
        return kuhn_loading() if name == "kuhn-1002" else ld

    def native(name, code):
        pk, _, steps, every = scen[name]
        return lambda: run_native(pk(), settings_of(name, code), loading_of(name), steps, every)

    def stored(code):
        d = stored_dir(SHORT_CODES[code].stored)
        return lambda: read_reference(_stored_log(d), d / "dump.atoms")

    def live(name, code):
        pk, _, steps, every = scen[name]
        job = SHORT_CODES[code].live_job if name == "live-120" else SHORT_CODES[code].kuhn_job

        def make():
            tr, man = run_reference_job(
                ctx.work("reference", "biaxial-short", job),
                pk(),
                settings_of(name, code),
                loading_of(name),
                steps,
                every,
                timeout=ctx.job_timeout(pk().n * steps),
                engine=code,
            )
            manifests[f"{name}/{code}"] = man
            return tr

        return make

    runs, comps = [], []
    for name, (pk, _, steps, every) in scen.items():
        here = [c for c in CODES if c in SHORT_CODES]
        for code in here:
            if name == "stored-120":
                d = stored_dir(SHORT_CODES[code].stored)
                ref = Run(
                    f"{name}/{code}",
                    code,
                    code,
                    f"stored {d.name}",
                    stored(code),
                    verify=stored_job(d),
                )
            else:
                ref = Run(f"{name}/{code}", code, code, f"{name} deck run now", live(name, code), live=True)
            runs += [Run(f"native/{name}/{code}", NATIVE, code, f"native, {code} arithmetic", native(name, code)), ref]

        def params(pk=pk, steps=steps, every=every, **fixed):
            return {"d50": pk().d50, "nsteps": steps, "dump_every": every, **fixed}

        for code in here:
            comps.append(
                Comparison(
                    "step",
                    f"biaxial-short/{name}/{code}",
                    (f"native/{name}/{code}", f"{name}/{code}"),
                    SHORT_CODES[code].reason,
                    functools.partial(params, bounds=SHORT_BOUNDS),
                )
            )
        for i, a in enumerate(here):
            for b in here[i + 1 :]:
                comps.append(
                    Comparison(
                        "explained",
                        f"biaxial-short/{name}/{a}-{b}",
                        (f"{name}/{a}", f"{name}/{b}", f"native/{name}/{a}", f"native/{name}/{b}"),
                        CROSS_SHORT_REASON,
                        functools.partial(
                            params, position_tol=POS_TOL, relative_tol=REL_TOL, reason=CROSS_SHORT_REASON
                        ),
                    )
                )
    return runs, comps


# ---------------------------------------------------------------- YADE's columns
#: YADE's run of the short case: the deck's case undamped (reference_runs.yade.dem.short_biaxial), its
#: stored output (the stand-in when YADE is absent) and its sampling (the stored output's)
YADE_STORED = "biaxial-short-yade"
YADE_SCEN = "yade-120"
YADE_THERMO_EVERY = 10
YADE_DUMP_EVERY = 500
YADE_BIT_REASON = (
    "native in YADE's arithmetic (gransim.dem.yade_arithmetic.yade_run) mirrors every floating-point operation "
    "of YADE 2023.02a on this case in YADE's order (container order fixed by the collider, libstdc++'s std::sort, "
    "tan(atan(mu)), no FMA: docs/yade.md); measured equal to the bit at every step, so the tolerance is 0"
)
YADE_BOUNDS = StepBounds(
    0.0,
    0.0,
    YADE_BIT_REASON,
    "velocities v_(k-1/2) with the mean field and spins as YADE holds them: " + YADE_BIT_REASON,
    "per-particle forces and torques summed in YADE's container order: " + YADE_BIT_REASON,
    "z getStress() (not symmetrised): " + YADE_BIT_REASON,
    "the cell after YADE's velGrad update: " + YADE_BIT_REASON,
)
YADE_CROSS_REASON = (
    "YADE's run is undamped (its 2023.02a damped law takes a periodic image's velocity with the wrong sign, "
    "docs/yade.md), so the code runs the same deck undamped; the codes' laws and kinematics differ physically "
    "(raw difference shown, with why), and a 1e-15 perturbation's envelope (1e-12 of the stress in 3000 steps, "
    "measured) is ten decades below that difference, so no envelope can hold it; the check is that the codes' "
    "difference equals the difference of the native runs in their two arithmetics, each equal to its code to the "
    "bit on this deck (measured 0.0), so the tolerance is 0"
)


def yade_plan(ctx: Context, manifests: dict, codes=("liggghts", "lammps")) -> tuple[list, list]:
    """YADE's runs and comparisons of biaxial-short (``yade-120``: the 120-disk case undamped, 3000
    steps): native in YADE's arithmetic against YADE step for step at zero tolerance (the live job,
    or with YADE absent its stored output, reference_runs/stored/biaxial-short-yade); each code of
    ``codes`` running the same undamped deck against YADE, the difference explained by the native
    runs in the two arithmetics."""
    if "yade" not in CODES:
        return [], []
    p, s, ld, n = short_biaxial()
    every = {"thermo_every": YADE_THERMO_EVERY, "dump_every": YADE_DUMP_EVERY}
    job = biaxial_job(p, s, ld, n, **every)
    d = stored_dir(YADE_STORED)
    sc = YADE_SCEN

    def live_yade():
        job_dir = ctx.work("reference", "biaxial-short", sc)
        return yade_runs.live(job_dir, job, ctx.job_timeout(p.n * n), False, manifests, f"{sc}/yade")

    runs = [
        Run(
            f"{sc}/yade",
            "yade",
            "yade",
            f"{sc}: YADE 2023.02a run now (reference_runs/yade/dem.py, undamped)",
            lambda: yade_runs.live(
                ctx.work("reference", "biaxial-short", sc),
                job,
                ctx.job_timeout(p.n * n),
                False,
                manifests,
                f"{sc}/yade",
            ),
            live=True,
            fallback=f"{sc}/yade-stored",
        ),
        Run(
            f"{sc}/yade-stored",
            "yade",
            "yade",
            f"stored {YADE_STORED}",
            yade_runs.stored(d, False),
            verify=yade_runs.stored_verify(d, job, False),
        ),
        Run(
            f"native/{sc}/yade",
            NATIVE,
            "yade",
            "native, yade arithmetic (yade_run)",
            lambda: yade_runs.native(p, s, ld, n, YADE_THERMO_EVERY, YADE_DUMP_EVERY, False),
        ),
    ]
    params = {"d50": p.d50, "nsteps": n, **every}
    comps = [Comparison("step", f"biaxial-short/{sc}/yade", (f"native/{sc}/yade", f"{sc}/yade"), YADE_BIT_REASON,
                        {**params, "bounds": YADE_BOUNDS})]  # fmt: skip
    for code in (c for c in CODES if c in codes):
        su = undamped(_flavour(s, code))

        def make(code=code, su=su):
            tr, man = run_reference_job(
                ctx.work("reference", "biaxial-short", f"{sc}-{code}"),
                p,
                su,
                ld,
                n,
                YADE_DUMP_EVERY,
                thermo_every=YADE_THERMO_EVERY,
                timeout=ctx.job_timeout(p.n * n),
                engine=code,
            )
            manifests[f"{sc}/{code}"] = man
            return tr

        runs += [
            Run(f"{sc}/{code}", code, code, f"{sc}: the deck undamped, run now", make, live=True),
            Run(
                f"native/{sc}/{code}",
                NATIVE,
                code,
                f"native, {code} arithmetic, undamped",
                functools.partial(run_native, p, su, ld, n, YADE_DUMP_EVERY, thermo_every=YADE_THERMO_EVERY),
            ),
        ]
        comps.append(
            Comparison(
                "explained",
                f"biaxial-short/{sc}/{code}-yade",
                (f"{sc}/{code}", f"{sc}/yade", f"native/{sc}/{code}", f"native/{sc}/yade"),
                YADE_CROSS_REASON,
                {**params, "position_tol": 0.0, "relative_tol": 0.0, "reason": YADE_CROSS_REASON},
            )
        )
    return runs, comps


@case("biaxial-short", "Biaxial test, short horizon: step for step, native vs LIGGGHTS vs LAMMPS", order=20)
def biaxial_short(ctx: Context) -> CaseResult:
    res = CaseResult(
        "biaxial-short",
        "Biaxial test, short horizon: step for step, native vs LIGGGHTS vs LAMMPS",
        "The same deck in each code (LIGGGHTS 3.8.0 and LAMMPS, each in its own syntax), compared at every step "
        "(stress, box) and at every dump (positions, velocities, spins, per-particle forces and torques) with "
        "the native engine in that code's arithmetic (<code>DEMSettings.flavour</code>). <i>stored-120</i>: the "
        "stored runs <code>reference_runs/stored/biaxial-short</code> (LIGGGHTS) and "
        "<code>biaxial-short-lammps</code> (120 disks on a jittered lattice, servo on x, rate on y, ~60 sliding "
        "contacts, 3000 steps). <i>live-120</i>: the same deck run now. <i>kuhn-1002</i>: the Kuhn 1002-disk "
        "assembly with the biaxial default settings (gransim.dem.default_settings), consolidation with the servo "
        f"on both axes, {SHORT_KUHN_STEPS} steps. Two codes are set against each other by the difference of "
        "the native flavours (their laws differ; why, in words, beside the raw difference).",
    )
    manifests = {}
    runs, comps = short_plan(ctx, manifests)
    y_runs, y_comps = yade_plan(ctx, manifests)
    runs, comps = runs + y_runs, comps + y_comps
    out = evaluate(res, ctx, runs, comps)
    header = ["run", "steps", "frames", "max|dx|/D50", "max|dv|/max|v|", "max|df|/max|f|", "max rel stress"]
    rows = [short_row(s) for c in comps if c.kind == "step" and (s := out.summaries.get(c.label))]
    cols = ("label", "last_step", "frames", "raw_x", "raw_stress", "unexplained_x", "unexplained_stress")
    cross_rows = [[s[k] for k in cols] for c in comps if c.kind == "explained" and (s := out.summaries.get(c.label))]
    res.tables.append(("Largest differences per run and code (0 = bitwise equal)", header, rows))
    res.tables.append(
        (
            "Two codes against each other: raw differences and what the native flavours leave unexplained",
            [
                "run",
                "steps",
                "frames",
                "raw max|dx|/D50",
                "raw max rel stress",
                "unexplained |dx|/D50",
                "unexplained rel stress",
            ],
            cross_rows,
        )
    )
    for i, a in enumerate(CODES):
        for b in CODES[i + 1 :]:
            why = why_they_differ(pair_key(a, b))
            if why and cross_rows:
                res.notes.append(f"Why {CODE[a]} and {CODE[b]} differ beyond round-off: {html.escape(why)}")
    for key, man in manifests.items():
        if key.startswith("kuhn-1002/"):
            code = key.split("/")[1]
            res.notes.append(
                f"kuhn-1002 ({CODE[code]}): native {out.runs[f'native/{key}'].elapsed:.2f} s, {CODE[code]} job "
                f"{man.get('elapsed_s', 0):.2f} s (<code>{' '.join(man.get('command', []))}</code>)."
            )
    res.notes.append(
        "Per-contact forces: the native snapshot's contact forces are not set against LIGGGHTS' "
        "<code>compute pair/gran/local</code>, whose rows are a re-evaluation at output time "
        "(remapped positions, full-step velocities, stale ghost state), not the applied forces "
        "(docs/liggghts.md). Per-particle forces are the sums of the applied contact forces "
        "and are compared instead; with equal positions the contact lists are equal (voidcell case)."
    )
    return res


# ====================================================================== biaxial-full
FULL_CONSOLIDATION_STEPS = 6000
FULL_DUMP_EVERY = 2000  # steps: 2.8e-5 axial strain at the default rate
FULL_THERMO_EVERY = 10
PERTURB_REL = 1e-15
#: the codes biaxial-full runs (full_runs' reference jobs and stored series; another code's columns stay
#: empty here until its jobs are added to reference_jobs and full_runs)
FULL_CODES = ("liggghts", "lammps")
#: the envelope criterion of biaxial-full (validation.judges.EnvelopeRule): the native run repeats the
#: code's arithmetic bit for bit, so the pointwise rule (no window, no floor, the curves within the band)
FULL_RULE = BITWISE_RULE
CURVE_REASON = (
    "band = the largest deviation of the perturbed LIGGGHTS runs from the reference along the "
    "curve (their spread is the uncertainty of a curve under round-off), in units of the confining p"
)


def _settings_by_suite(suite: str) -> dict:
    if suite == "full":
        return {"strain": 0.01, "np2": True}
    return {"strain": 0.005, "np2": False}


_FULL_CACHE: dict = {}


#: the neighbour-setting member of the full suite's envelope: the same deck with twice the skin
#: (LIGGGHTS keeps a spring while its pair is in the list, LAMMPS rebuilds at other steps: a
#: change of a numerical setting, not of the physics asked for)
SKIN_LABEL = "neighbour skin x2"
SKIN_FACTOR = 2.0


def ensemble_labels(n: int, np2: bool) -> list[str]:
    """Labels of the perturbed LIGGGHTS runs of :func:`full_runs` for ``n`` disks."""
    out = ["x of disk 1 moved by +1e-15 rel", f"y of disk {n // 2 + 1} moved by -1e-15 rel"]
    return out + (["2 MPI processes", SKIN_LABEL] if np2 else [])


def lammps_ensemble_labels(n: int, suite: str) -> list[str]:
    """Labels of the perturbed LAMMPS runs: one in the default suite (its own envelope, beside
    LIGGGHTS' two), the LIGGGHTS set in the full suite."""
    labels = ensemble_labels(n, suite == "full")
    return labels if suite == "full" else labels[:1]


def _perturbed(common, k: int, ax: int, sign: float):
    xp = np.array(common.positions)
    xp[k, ax] *= 1.0 + sign * PERTURB_REL
    return Packing(positions=xp, radii=common.radii, cell=common.cell, density=common.density, metadata={})


def reference_jobs(ctx: Context, common, dem, tag: str, np2: bool) -> dict:
    """The reference jobs of the full loading: {(engine, label): keyword arguments of
    :func:`validation.dem_compare.run_reference_job`} for each available code, its serial
    reference (label "reference") and its envelope members (:func:`ensemble_labels`,
    :func:`lammps_ensemble_labels`): a coordinate moved by 1e-15, 2 MPI processes, twice the skin."""
    n = common.n
    perturb = {
        "x of disk 1 moved by +1e-15 rel": (0, 0, 1.0),
        f"y of disk {n // 2 + 1} moved by -1e-15 rel": (n // 2, 1, -1.0),
    }
    jobs = {}
    for engine, avail, labels in (
        ("liggghts", ctx.liggghts, ensemble_labels(n, np2)),
        ("lammps", ctx.lammps, lammps_ensemble_labels(n, ctx.suite)),
    ):
        if not avail:
            continue
        base = ctx.work("reference", "biaxial-full" if engine == "liggghts" else "biaxial-full-lammps", tag)
        settings = _flavour(dem, engine)
        jobs[(engine, "reference")] = dict(job_dir=base / "reference", packing=common, settings=settings)
        for label in labels:
            if label in perturb:
                k, ax, sign = perturb[label]
                jobs[(engine, label)] = dict(
                    job_dir=base / f"perturbed-{k}-{ax}", settings=settings, packing=_perturbed(common, k, ax, sign)
                )
            elif label == SKIN_LABEL:
                jobs[(engine, label)] = dict(
                    job_dir=base / "skin2",
                    packing=common,
                    settings=dataclasses.replace(settings, skin=SKIN_FACTOR * settings.skin),
                )
            elif label == "2 MPI processes":
                jobs[(engine, label)] = dict(job_dir=base / "np2", packing=common, settings=settings, np_procs=2)
            else:
                raise ValueError(f"unknown envelope member {label!r}")
    return jobs


def _full_key(ctx: Context) -> tuple:
    return (str(ctx.results.resolve()), ctx.suite, ctx.liggghts, ctx.lammps)


def _full_setup(ctx: Context) -> dict:
    """The consolidation of ``biaxial-full`` (native, bit for bit the short case's arithmetic) and
    the reference jobs of its compression: the run dict of :func:`full_runs` before any compression
    run, plus ``jobs`` (:func:`reference_jobs`) and the keyword arguments every job shares."""
    cfg = _settings_by_suite(ctx.suite)
    if not ctx.liggghts:  # only the stored series can be compared: run to its strain
        cfg["strain"] = _settings_by_suite("default")["strain"]
    pk = _kuhn(ctx)
    dem, bi = dem_defaults(pk, strain=cfg["strain"])
    servo = _servo(bi)
    eng = DEMEngine(pk, dem)
    out = eng.advance(
        Loading(x=servo, y=servo), FULL_CONSOLIDATION_STEPS, phase_step0=0, phase_box0=(eng.lo.copy(), eng.hi.copy())
    )
    cons_err = float(np.abs(out["stress"][-1000:, [0, 1], [0, 1]].mean(axis=0) / bi.confining - 1).max())
    x = eng.x - eng.lo
    L = eng.box_lengths
    common = Packing(positions=x, radii=pk.radii, cell=np.diag(L), density=pk.density, metadata={})
    v, w = eng.v.copy(), eng.w.copy()
    loading = Loading(x=servo, y=AxisControl("rate", rate=-bi.strain_rate))
    nsteps = int(np.ceil(bi.strain / (bi.strain_rate * dem.dt) / FULL_DUMP_EVERY)) * FULL_DUMP_EVERY
    r = {
        "packing": common,
        "settings": dem,
        "biaxial": bi,
        "loading": loading,
        "nsteps": nsteps,
        "consolidation_error": cons_err,
        "velocities": v,
        "spins": w,
    }
    r["jobs"] = reference_jobs(ctx, common, dem, f"strain{bi.strain:g}", cfg["np2"])
    r["np2"] = cfg["np2"]
    r["job_common"] = dict(
        loading=loading,
        nsteps=nsteps,
        dump_every=FULL_DUMP_EVERY,
        velocities=v,
        spins=w,
        thermo_every=FULL_THERMO_EVERY,
        timeout=ctx.job_timeout(common.n * nsteps),
    )
    return r


#: reference jobs of ``biaxial-full`` started ahead of the case (:func:`prefetch_full`): key of
#: :func:`_full_key` -> (run dict of :func:`_full_setup`, {job key: future}, executor)
_FULL_PENDING: dict = {}


def _native_flavours(ctx: Context) -> tuple[str, ...]:
    """The arithmetics :func:`full_runs` runs the compression in natively: LIGGGHTS', and LAMMPS'
    when LAMMPS is installed."""
    return ("liggghts", "lammps") if ctx.lammps else ("liggghts",)


def _native_full(r: dict, flavour: str):
    """The native compression of ``r`` (:func:`_full_setup`) in ``flavour``'s arithmetic."""
    return run_native(
        r["packing"],
        _flavour(r["settings"], flavour),
        r["loading"],
        r["nsteps"],
        FULL_DUMP_EVERY,
        velocities=r["velocities"],
        spins=r["spins"],
        thermo_every=FULL_THERMO_EVERY,
    )


def prefetch_full(ctx: Context) -> None:
    """Start the long runs of ``biaxial-full`` now, in the background: its reference jobs (each a
    code process), then its native compressions, so that they run while the cases before it use
    the other core(s).

    They go to the run's shared background pool (``ctx.background``, ``ctx.jobs - 1`` threads),
    else to a pool of ``ctx.jobs - 1`` threads of their own. The jobs are those :func:`full_runs`
    would start (same decks, same inputs, same directories) and the native runs the same calls;
    it collects them and runs the rest. Nothing starts with ``ctx.jobs`` < 2 (the user asked for
    one reference job at a time) or without a code installed (the stored series are compared then).
    """
    key = _full_key(ctx)
    if key in _FULL_CACHE or key in _FULL_PENDING or int(ctx.jobs) < 2 or not (ctx.liggghts or ctx.lammps):
        return
    r = _full_setup(ctx)
    own = ctx.background is None
    pool = (
        ThreadPoolExecutor(max_workers=int(ctx.jobs) - 1, thread_name_prefix="biaxial-full-prefetch")
        if own
        else ctx.background
    )
    futures = {k: pool.submit(run_reference_job, engine=k[0], **r["job_common"], **kw) for k, kw in r["jobs"].items()}
    for flavour in _native_flavours(ctx):
        futures[(NATIVE, flavour)] = pool.submit(_native_full, r, flavour)
    _FULL_PENDING[key] = (r, futures, pool if own else None)


def _drop(futures, pool) -> None:
    """Cancel ``futures`` not yet started and wait for the running ones (and shut ``pool`` down,
    when it is a pool of their own)."""
    for f in futures:
        f.cancel()
    if pool is not None:
        pool.shutdown(wait=True, cancel_futures=True)
    else:
        wait([f for f in futures if not f.cancelled()])


def cancel_prefetch() -> None:
    """Cancel the prefetched runs not yet started and wait for the running ones (a validation
    run that ends early: an error, a signal)."""
    while _FULL_PENDING:
        _, (_, futures, pool) = _FULL_PENDING.popitem()
        _drop(futures.values(), pool)


def full_runs(ctx: Context) -> dict:
    """The compression runs of ``biaxial-full`` (cached per results dir and suite): native,
    reference and perturbed runs of each available code, from one common consolidated state.

    Design: the native engine consolidates the Kuhn assembly (both axes servo-controlled to p,
    ``FULL_CONSOLIDATION_STEPS``: the short case shows this phase bit for bit); its final state
    (positions shifted to a box at the origin, velocities, spins) is the packing every code
    starts the compression from (each reads it as a data file, which carries no contact
    history, and the native engine starts with zero springs too). Compression: y at the default
    rate, sigma_11 = p held by the servo, up to the suite's strain.

    The reference jobs run in a pool of ``max(ctx.jobs, 1)`` worker threads (each a code process)
    while the native runs (flavour liggghts, and flavour lammps when LAMMPS is there) proceed in
    this thread and one beside it; the jobs and native runs that :func:`prefetch_full` started
    earlier are collected (the jobs it had not started yet move to this pool, the native runs to
    this thread and the one beside it). Keys: ``native``, ``liggghts``, ``manifest``, ``ensemble``,
    ``expected_ensemble`` (LIGGGHTS) and ``lammps`` = {``native``, ``reference``, ``manifest``,
    ``ensemble``, ``expected_ensemble``} when LAMMPS is installed.
    """
    key = _full_key(ctx)
    if key in _FULL_CACHE:
        return _FULL_CACHE[key]
    pending = _FULL_PENDING.pop(key, None)
    if pending is None:
        r, early, early_pool = _full_setup(ctx), {}, None
    else:
        r, early, early_pool = pending
    jobs, common = r.pop("jobs"), r.pop("job_common")
    cfg = {"np2": r.pop("np2")}
    common_pk, dem, n = r["packing"], r["settings"], r["packing"].n
    pool = ThreadPoolExecutor(max_workers=max(int(ctx.jobs), 1))
    try:
        futures, natives = {}, {}
        for k, kw in jobs.items():
            f = early.get(k)
            futures[k] = (
                f if f is not None and not f.cancel() else pool.submit(run_reference_job, engine=k[0], **common, **kw)
            )
        for flavour in _native_flavours(ctx):
            f = early.get((NATIVE, flavour))
            if f is not None and not f.cancel():  # running or finished in the background
                natives[flavour] = f
        try:
            # the native runs not made in the background: the first in this thread, the others each
            # in a thread of its own beside it (the kernels release the GIL)
            todo = [fl for fl in _native_flavours(ctx) if fl not in natives]
            with ThreadPoolExecutor(max_workers=max(len(todo) - 1, 1)) as beside:
                natives.update({fl: beside.submit(_native_full, r, fl) for fl in todo[1:]})
                mine = {fl: _native_full(r, fl) for fl in todo[:1]}
                made = {**{fl: f.result() for fl, f in natives.items()}, **mine}
            r["native"] = made["liggghts"]
            nat_m = made.get("lammps")
            done = {k: f.result() for k, f in futures.items()}
        except BaseException:
            for f in (*futures.values(), *natives.values()):
                f.cancel()
            raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        if early_pool is not None:
            early_pool.shutdown(wait=True, cancel_futures=True)
    if ctx.liggghts:
        lig, man = done[("liggghts", "reference")]
        ens = {lab: done[("liggghts", lab)][0] for (e, lab) in jobs if e == "liggghts" and lab != "reference"}
        r.update(liggghts=lig, manifest=man, ensemble=ens, expected_ensemble=ensemble_labels(n, cfg["np2"]))
        # the reference job in the native run-file schema (read by gransim.dem / gransim voidcells)
        ref_dir = jobs[("liggghts", "reference")]["job_dir"]
        r["liggghts_run_file"] = trajectory_to_run_file(
            ref_dir / "liggghts-run.h5",
            common_pk,
            lig.steps,
            lig.stress,
            lig.lengths,
            lig.frames,
            dem.dt,
            settings=dem.to_dict(),
            source=str(ref_dir),
        )
    if ctx.lammps:
        lmp, man = done[("lammps", "reference")]
        ens = {lab: done[("lammps", lab)][0] for (e, lab) in jobs if e == "lammps" and lab != "reference"}
        r["lammps"] = {
            "native": nat_m,
            "reference": lmp,
            "manifest": man,
            "ensemble": ens,
            "expected_ensemble": lammps_ensemble_labels(n, ctx.suite),
        }
    _FULL_CACHE[key] = r
    return r


def curves(tr, p: float):
    """Axial strain -ln(Ly/Ly0), deviator (sigma_22 - sigma_11, compression positive, / p) and volumetric
    strain ln(A/A0) (dilation positive) of a trajectory."""
    L = tr.lengths
    ea = -np.log(L[:, 1] / L[0, 1])
    q = (tr.stress[:, 1] - tr.stress[:, 0]) / p
    ev = np.log(L[:, 0] * L[:, 1] / (L[0, 0] * L[0, 1]))
    return ea, q, ev


def _plots(ctx, div, sdiv, cur) -> list:
    # lazy: pyplot costs ~1.5 s of import (measured, load 9); only the figures need it
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    figs = []
    floor = 1e-18
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, (steps, d) in div.items():
        zero = " (exactly 0 at every dump)" if len(d) and not np.any(d) else ""
        axes[0].semilogy(steps, np.maximum(d, floor), "o-" if "native vs" in name else "-", ms=3, label=name + zero)
    axes[0].set_xlabel("step of the compression phase")
    axes[0].set_ylabel("max |x_a - x_b| / D50  (0 drawn at 1e-18)")
    if div:
        axes[0].legend(fontsize=8)
    else:  # stored series: stress and box only
        axes[0].text(0.5, 0.5, "positions not stored (codes absent)", ha="center", transform=axes[0].transAxes)
    for name, (steps, d) in sdiv.items():
        zero = " (exactly 0 at every step)" if len(d) and not np.any(d) else ""
        axes[1].semilogy(steps, np.maximum(d, floor), lw=0.8, label=name + zero)
    axes[1].set_xlabel("step of the compression phase")
    axes[1].set_ylabel("max |sigma_a - sigma_b| / max |sigma_b|  (0 drawn at 1e-18)")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    path = ctx.figure_path("biaxial_full_divergence.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    data = _long_csv(
        path.with_suffix(".csv"),
        ["run", "series", "step", "value"],
        [(n, "position max|dx|/D50", st, v) for n, (sts, d) in div.items() for st, v in zip(sts, d)]
        + [(n, "stress rel diff", st, v) for n, (sts, d) in sdiv.items() for st, v in zip(sts, d)],
    )
    figs.append(
        (
            path,
            data,
            False,
            "Divergence against each code's serial reference run over time: native in that code's "
            "arithmetic, and the code itself under a round-off perturbation (the envelope). Left: positions "
            "at every dump; right: "
            f"stress every {FULL_THERMO_EVERY} steps.",
        )
    )
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, (ea, q, ev) in cur.items():
        ls = "--" if name.startswith("native") else "-"
        axes[0].plot(100 * ea, q, ls, lw=1, label=name)
        axes[1].plot(100 * ea, 100 * ev, ls, lw=1, label=name)
    axes[0].set_xlabel("axial strain -ln(Ly/Ly0) (%)")
    axes[0].set_ylabel("(sigma_22 - sigma_11) / p  (compression positive)")
    axes[1].set_xlabel("axial strain -ln(Ly/Ly0) (%)")
    axes[1].set_ylabel("volumetric strain ln(A/A0) (%), dilation positive")
    for ax in axes:
        ax.legend(fontsize=8)
    fig.tight_layout()
    path = ctx.figure_path("biaxial_full_curves.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    data = _long_csv(
        path.with_suffix(".csv"),
        ["run", "axial_strain", "q_over_p", "volumetric_strain"],
        [(n, a, b, c) for n, (ea, q, ev) in cur.items() for a, b, c in zip(ea, q, ev)],
    )
    figs.append(
        (
            path,
            data,
            True,
            "Stress-strain and volumetric curves of the Kuhn assembly: native (dashed), "
            "LIGGGHTS and LAMMPS runs (the perturbed runs lie on top: their spread is the band).",
        )
    )
    return figs


def _long_csv(path, header, rows):
    """Write the data a figure was drawn from as CSV (one row per point; atomic) and return its path."""
    with atomic_path(path, suffix=".csv.tmp") as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            for row in rows:
                w.writerow([f"{v:.17g}" if isinstance(v, (float, np.floating)) else v for v in row])
    return path


CROSS_CURVE_REASON = (
    "the two codes run the same deck with slightly different laws (docs/lammps.md); over the full "
    "loading each code's reference lies within its own band of the curve (the largest deviation of "
    "its perturbed runs from it), so if both codes follow the same curve their references differ "
    "by at most the sum of the two bands"
)


def _full_curves(p: float):
    def of(tr):
        return curves(tr, p)

    return of


def full_plan(ctx: Context, r: dict) -> tuple[list, list]:
    """The runs and comparisons of biaxial-full, from :func:`full_runs`' result ``r``: per code of
    :data:`FULL_CODES`, native in its arithmetic against the code's ensemble (its serial reference
    and envelope members run now, or with the code absent its stored series in their place) by
    :func:`validation.judges.ensemble_envelope` with :data:`FULL_RULE` (divergence and curves),
    and every two codes' references against the sum of their bands
    (:func:`validation.judges.ensemble_cross`)."""
    pk, bi, n = r["packing"], r["biaxial"], r["nsteps"]
    here = [c for c in CODES if c in FULL_CODES]
    of = _full_curves(bi.confining)
    checks = (
        CurveCheck(1, "deviator", "max|dq|/p along the curve", ""),
        CurveCheck(2, "volumetric_strain", "max|d eps_v| along the curve", ""),
    )

    def native(code):
        if code == "liggghts":
            return r["native"]
        if "lammps" in r:
            return r["lammps"]["native"]
        return run_native(
            pk,
            _flavour(r["settings"], code),
            r["loading"],
            n,
            FULL_DUMP_EVERY,
            velocities=r["velocities"],
            spins=r["spins"],
            thermo_every=FULL_THERMO_EVERY,
        )

    def live(code):
        side = (
            {"reference": r["liggghts"], "ensemble": r["ensemble"], "manifest": r["manifest"]}
            if code == "liggghts"
            else r["lammps"]
        )
        expected = r["expected_ensemble"] if code == "liggghts" else r["lammps"]["expected_ensemble"]
        return Ensemble(
            side["reference"],
            side["ensemble"],
            tuple(expected),
            FULL_THERMO_EVERY,
            False,
            f"{CODE[code]} jobs run now",
            side["manifest"],
        )

    def stored(code):
        want = ensemble_labels(pk.n, False) if code == "liggghts" else lammps_ensemble_labels(pk.n, "default")
        z = load_stored_full(bi.strain, code)
        name = f"{STORED_FULL}/{_stored_name(bi.strain, code)}"
        if z is None:
            empty = Trajectory(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 2)), {})
            return Ensemble(empty, {}, tuple(want), STORED_EVERY, True, name, refused=f"no stored series {name}")
        refused = ""
        if z["input_sha256"] != input_fingerprint(ctx):
            refused = (
                "made from another Kuhn assembly than the one generated here (input fingerprint differs: the "
                "packing generator changed); regenerate it with validation.cases.biaxial.store_full_reference "
                "where the code is installed"
            )
        return Ensemble(z["liggghts"], z["ensemble"], tuple(want), STORED_EVERY, True, name, refused=refused)

    runs, comps = [], []
    for code in here:
        runs += [
            Run(
                f"native/{code}",
                NATIVE,
                code,
                f"native compression, {code} arithmetic",
                functools.partial(native, code),
            ),
            Run(f"stored/{code}", code, code, "stored series", functools.partial(stored, code)),
            Run(
                f"ensemble/{code}",
                code,
                code,
                "serial reference and envelope members run now",
                functools.partial(live, code),
                live=True,
                fallback=f"stored/{code}",
            ),
        ]
        comps.append(
            Comparison(
                "ensemble",
                f"biaxial-full/{code}",
                (f"native/{code}", f"ensemble/{code}"),
                FULL_RULE.reason.replace("CODE", CODE[code]),
                {
                    "nsteps": n,
                    "native_every": FULL_THERMO_EVERY,
                    "dump_every": FULL_DUMP_EVERY,
                    "d50": pk.d50,
                    "rule": FULL_RULE,
                    "curves_of": of,
                    "checks": tuple(
                        dataclasses.replace(
                            c,
                            reason=CURVE_REASON.replace("LIGGGHTS", CODE[code])
                            if c.col == 1
                            else CURVE_REASON.replace("LIGGGHTS", CODE[code]).replace(
                                ", in units of the confining p", ""
                            ),
                        )
                        for c in checks
                    ),
                    "native_name": f"native ({code})",
                },
            )
        )
    for i, a in enumerate(here):
        for b in here[i + 1 :]:
            na, nb = CODE[a], CODE[b]
            comps.append(
                Comparison(
                    "ensemble_cross",
                    f"biaxial-full/{a}-{b}",
                    (f"ensemble/{a}", f"ensemble/{b}"),
                    CROSS_CURVE_REASON,
                    {
                        "nsteps": n,
                        "curves_of": of,
                        "checks": (
                            CurveCheck(1, "deviator", f"max|q_{na} - q_{nb}|/p along the curve", ""),
                            CurveCheck(2, "volumetric_strain", f"max|eps_v {na} - eps_v {nb}| along the curve", ""),
                        ),
                        "reason": CROSS_CURVE_REASON,
                    },
                )
            )
    return runs, comps


@case(
    "biaxial-full",
    "Biaxial test, full loading: divergence envelopes and stress-strain curves",
    suites=("default", "full"),
    order=30,
    prefetch=prefetch_full,
    cancel=cancel_prefetch,
)
def biaxial_full(ctx: Context) -> CaseResult:
    r = full_runs(ctx)
    bi, dem = r["biaxial"], r["settings"]
    res = CaseResult(
        "biaxial-full",
        "Biaxial test, full loading: divergence envelopes and stress-strain curves",
        f"Kuhn 1002-disk assembly, default biaxial settings (kn = kt = {dem.kn:g} N/m, mu = {dem.mu:g}, "
        f"dt = {dem.dt:.3g} s, p = {bi.confining:g} N/m, strain rate {bi.strain_rate:.3g} 1/s: inertial "
        f"number 5e-5). Consolidation ({FULL_CONSOLIDATION_STEPS} steps, servo on both axes) in the native engine; "
        "from its final state (written as the data file with velocities and spins; no contact history "
        "on any side) LIGGGHTS, LAMMPS and the native engine in each code's arithmetic run the compression "
        f"(sigma_11 = p by the servo, y at constant rate) to {100 * bi.strain:g}% axial strain ({r['nsteps']} steps). "
        f"Divergence = max |x_a - x_b| / D50 at every dump ({FULL_DUMP_EVERY} steps) and the relative stress "
        f"difference every {FULL_THERMO_EVERY} steps (thermo), against each code's serial run, judged against that "
        "code's own envelope (its runs under a 1e-15 perturbation; full suite: also 2 MPI processes and twice the "
        "neighbour skin).",
    )
    res.skip_code(
        "yade",
        "no YADE run of the long compression: the decks' compression is damped (gamma_n = gamma_t), YADE 2023.02a's "
        "periodic damped law takes an image's velocity with the wrong sign (ViscoelasticPM.cpp:118, docs/yade.md) "
        "and an undamped 357,000-step compression is another loading; YADE's arithmetic is judged step for step "
        "on the short horizon (biaxial-short/yade-120)",
    )
    res.notes.append(
        f"Consolidation: mean sigma_11, sigma_22 over its last 1000 steps within "
        f"{100 * r['consolidation_error']:.2f}% of p. Native compression: {r['native'].elapsed:.1f} s."
    )
    if "liggghts_run_file" in r:
        res.notes.append(
            "The LIGGGHTS compression job, parsed into the native run-file schema (docs/schema_dem.md; "
            "readable by <code>gransim voidcells</code>, <code>gransim dem-export</code>): "
            f"<code>{r['liggghts_run_file']}</code>."
        )
    p = bi.confining
    runs, comps = full_plan(ctx, r)
    out = evaluate(res, ctx, runs, comps)
    cur, divs, sdivs, sides = {}, {}, {}, {}
    for c in comps:
        sm = out.summaries.get(c.label)
        if c.kind != "ensemble" or sm is None:
            continue
        engine = c.label.rsplit("/", 1)[1]
        ens = out.run(c.runs[1])
        sides[engine] = ens
        if ens.stored:
            res.notes.append(
                f"<b>{CODE[engine]} is absent</b>: compared with the stored series "
                f"<code>{STORED_FULL}/{_stored_name(bi.strain, engine)}</code> (stress and box every "
                f"{STORED_EVERY} steps of the reference and perturbed {CODE[engine]} runs); positions are not "
                "stored, so only the stress divergence and the curves are checked."
                + (f" It cannot be used here: {ens.refused}." if ens.refused else "")
            )
        if not sm["complete"]:
            res.notes.append(
                f"<b>Incomplete evidence</b> ({CODE[engine]}): a run the comparison needs is missing steps, frames "
                "or ensemble members (records above); no envelope verdict is made on what remains."
            )
            continue
        divs[engine], sdivs[engine] = sm["div"], sm["sdiv"]
        cur.update(sm["curves"])
    if not cur:
        res.error = "no code's reference (live or stored) is available for this suite"
        return res
    lig_code = "LIGGGHTS" if "LIGGGHTS" in cur else "LAMMPS"
    ea_ref = cur[lig_code][0]
    for engine in divs:
        div = divs[engine]
        code = CODE[engine]
        if f"native vs {code}" not in div:  # a stored series: no positions, no divergence table
            continue
        steps = div[f"native vs {code}"][0]
        rows = []
        ref = sides[engine].reference
        for k in range(0, len(steps), max(1, len(steps) // 12)):
            rows.append(
                [
                    int(steps[k]),
                    float(100 * curves(ref, p)[0][ref.at([steps[k]])[0]]),
                    *[float(div[n][1][k]) for n in div],
                ]
            )
        if rows:
            res.tables.append(
                (
                    f"Divergence max|dx|/D50 against the serial {code} run (selected dumps)",
                    ["step", "axial strain %", *div.keys()],
                    rows,
                )
            )
    k_end = len(ea_ref) - 1
    res.tables.append(
        (
            "End of compression",
            ["run", "axial strain %", "q/p", "eps_v %", "peak q/p"],
            [
                [
                    n,
                    float(100 * c[0][min(k_end, len(c[0]) - 1)]),
                    float(c[1][-1]),
                    float(100 * c[2][-1]),
                    float(c[1].max()),
                ]
                for n, c in cur.items()
            ],
        )
    )
    for path, data, head, cap in _plots(
        ctx,
        {f"{e}: {k}": v for e, d in divs.items() for k, v in d.items()},
        {f"{e}: {k}": v for e, d in sdivs.items() for k, v in d.items()},
        cur,
    ):
        res.add_figure(path, cap, data=data, headline=head)
    for engine, sd in sides.items():
        man = sd.manifest
        if not man:
            continue
        res.notes.append(
            f"{CODE[engine]} reference: <code>{' '.join(man.get('command', []))}</code> "
            f"({man.get('engine_version') or man.get('liggghts_version', '')}), job "
            f"<code>{man.get('job_dir', '')}</code>, {man.get('elapsed_s', 0):.1f} s."
        )
    for engine, div in divs.items():
        final = {n: float(d[1][-1]) for n, d in div.items() if len(d[1])}
        res.notes.append(
            f"Divergence at the last dump ({CODE[engine]}): "
            + ", ".join(f"{n} {v:.2e} D50" for n, v in final.items())
            + "."
        )
    return res


# -- stored reference of biaxial-full (for machines without LIGGGHTS) ------------------------
STORED_FULL = "reference_runs/stored/biaxial-full"
STORED_EVERY = 100


def _stored_dir():

    return stored_dir("biaxial-full")


def _stored_name(strain: float, engine: str = "liggghts") -> str:
    return f"strain{strain:g}.npz" if engine == "liggghts" else f"strain{strain:g}-{engine}.npz"


def store_full_reference(ctx: Context, engine: str = "liggghts") -> None:
    """Store the stress and box series (every STORED_EVERY steps) of ``engine``'s runs of
    biaxial-full (reference and perturbed) with a README: the comparison made without that code.

    Run: ``python -c "from pathlib import Path; from validation.core import Context;
    from validation.cases.biaxial import store_full_reference;
    store_full_reference(Context('default', Path('results'), liggghts=True, lammps=True), 'lammps')"``.
    """
    r = full_runs(ctx)
    d = _stored_dir()
    d.mkdir(parents=True, exist_ok=True)
    if engine == "liggghts":
        ref, ensemble, man = r["liggghts"], r["ensemble"], r["manifest"]
    else:
        ref, ensemble, man = r[engine]["reference"], r[engine]["ensemble"], r[engine]["manifest"]
    steps = ref.steps[ref.steps % STORED_EVERY == 0]
    arrays = {
        "steps": steps,
        "reference/stress": ref.stress[ref.at(steps)],
        "reference/lengths": ref.lengths[ref.at(steps)],
    }
    names = []
    for k, (name, tr) in enumerate(ensemble.items()):
        arrays[f"ensemble{k}/stress"] = tr.stress[tr.at(steps)]
        arrays[f"ensemble{k}/lengths"] = tr.lengths[tr.at(steps)]
        names.append(name)
    strain = r["biaxial"].strain
    arrays["input_sha256"] = np.array(input_fingerprint(ctx))
    name = _stored_name(strain, engine)
    np.savez_compressed(d / name, names=np.array(json.dumps(names)), **arrays)
    code = CODE[engine]
    version = man.get("engine_version") or man.get("liggghts_version", "")
    (d / name.replace(".npz", ".md")).write_text(
        f"# biaxial-full reference series of {code}, axial strain {strain:g}\n\n"
        f"- Written by `validation.cases.biaxial.store_full_reference(ctx, {engine!r})` on "
        f"{datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')}.\n"
        f"- {code}: `{' '.join(man.get('command', []))}` ({version}), serial; "
        f"deck sha256 {man.get('deck_sha256', '')}; the deck is `reference_runs.decks.biaxial.write_biaxial_deck` "
        f"(engine {engine!r}) of the compression phase of `validation.cases.biaxial.full_runs` (Kuhn 1002-disk "
        "assembly consolidated by the native engine, default biaxial settings).\n"
        f"- Runs: reference and {', '.join(names)}.\n"
        f"- Arrays (npz): `steps` (every {STORED_EVERY} steps), `<run>/stress` (T, 3) xx yy xy of `compute "
        "pressure ... virial` (compression positive, N/m), `<run>/lengths` (T, 2) box lengths (m); `names` = "
        "JSON list of the ensemble runs; `input_sha256` the fingerprint of the assembly "
        "(`validation.cases.biaxial.input_fingerprint`).\n"
    )


def input_fingerprint(ctx: Context) -> str:
    """SHA-256 of the assembly the full runs start from (positions, radii, cell, density).

    Stored with the reference series: a series made from another assembly (e.g. after a change
    of the packing generator) is refused with a clear message instead of failing numerically.
    """
    p = _kuhn(ctx)
    h = hashlib.sha256()
    for a in (p.positions, p.radii, p.cell, np.array([p.density])):
        h.update(np.ascontiguousarray(a, np.float64).tobytes())
    return h.hexdigest()


def load_stored_full(strain: float, engine: str = "liggghts"):
    """The stored series of ``engine`` as trajectories (no frames), or None."""
    path = _stored_dir() / _stored_name(strain, engine)
    if not path.exists():
        return None
    z = np.load(path)
    steps = z["steps"]
    lig = Trajectory(steps, z["reference/stress"], z["reference/lengths"], {})
    names = json.loads(str(z["names"]))
    ens = {n: Trajectory(steps, z[f"ensemble{k}/stress"], z[f"ensemble{k}/lengths"], {}) for k, n in enumerate(names)}
    return {"liggghts": lig, "ensemble": ens, "input_sha256": str(z["input_sha256"]) if "input_sha256" in z else None}
