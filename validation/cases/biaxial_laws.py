"""The biaxial test on the Kuhn assembly with each contact law, native vs its code (case
``biaxial-laws``, full suite only).

For every law of :func:`gransim.contacts.laws.law_names` the compression phase of biaxial-full is
run by the native engine with that law (in its code's arithmetic, ``law_code``) and by the code
that has the law (``reference_runs.decks.biaxial.write_biaxial_deck(..., law=...)``), plus that
code's envelope members (a coordinate moved by 1e-15 relative, twice: the round-off band of the
code itself). Judged as biaxial-full is (:func:`validation.judges.envelope` with biaxial-full's
rule, :data:`validation.cases.biaxial.FULL_RULE`): the native run's divergence from the code's
serial reference, positions per dump and stress per thermo row, must stay within 10 times the
code's own envelope.

Common start: the native engine consolidates the Kuhn assembly with the default Hooke law (both
axes servo-controlled to p, as biaxial-full); every law compresses from that state (positions,
velocities, spins; zero contact history, as a data file carries none). A law other than Hooke
re-equilibrates in the first steps under the servo; that is part of the compared run.

Parameters (:func:`law_table`): the protocol's Hooke settings (kn, kt = kn, zeta 0.3, mu 0.5) and,
for the other laws, the same scales: Hertz with E such that 2 Y* sqrt(R* delta) = kn at
R* = D50/4, delta = 2e-4 D50 (:func:`gransim.dem.biaxial.hertz_equivalent_stiffness`),
restitution exp(-pi zeta/sqrt(1 - zeta^2)) of zeta 0.3 (LIGGGHTS hertz, LAMMPS tsuji DAMP),
``gran/hertz/history`` GAMMAN = gamma_n/a_ref (the Hooke damping at that contact radius);
rolling resistance mu_r = 0.1 (epsd eta_r = 0.3; sds KR = kt, no rolling damping).

Kept out of the default suite for time: 9 laws x (native + 3 code runs) of the 1002-disk
compression. No stored outputs: without the code the law's cell is reported not applicable.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from gransim.contacts.laws import law_code, law_names, make_law
from gransim.contacts.material import effective_shear
from gransim.dem import AxisControl, DEMEngine, Loading
from gransim.dem import default_settings as dem_defaults
from gransim.dem.biaxial import PAPER_INDENTATION
from gransim.geometry import Packing
from reference_runs.decks.biaxial import write_biaxial_deck
from reference_runs.errors import ReferenceRunError
from reference_runs.runner import run_job

from ..codes import NATIVE
from ..core import CaseResult, Context, case
from ..dem_compare import Trajectory, _frame, read_reference
from ..matrix import Comparison, Failed, Run, evaluate
from .biaxial import (
    FULL_CONSOLIDATION_STEPS,
    FULL_DUMP_EVERY,
    FULL_RULE,
    FULL_THERMO_EVERY,
    PERTURB_REL,
    _kuhn,
    _servo,
)

#: envelope members of each law's code: (label, disk index from n, axis, sign)
PERTURB = (
    ("x of disk 1 moved by +1e-15 rel", 0, 0, 1.0),
    ("y of disk n/2+1 moved by -1e-15 rel", None, 1, -1.0),
)
STRAIN = 0.005
ROLLING_MU = 0.1
ROLLING_ETA = 0.3
POISSON = 0.3


def law_table(packing, dem) -> dict:
    """{law name: make_law parameters} for the Kuhn assembly and the protocol's settings ``dem``
    (module docstring). Every name of :func:`gransim.contacts.laws.law_names` appears."""
    d50 = packing.d50
    a_ref = math.sqrt(0.25 * d50 * PAPER_INDENTATION * d50)
    ystar = dem.kn / (2.0 * a_ref)
    E = 2.0 * (1.0 - POISSON**2) * ystar
    G = effective_shear(E, POISSON, E, POISSON)
    z = dem.gamma_n / (2.0 * math.sqrt(dem.kn / (0.5 * float(np.median(packing.masses)))))
    e = math.exp(-math.pi * z / math.sqrt(1.0 - z * z))
    hooke = {
        "kn": dem.kn,
        "kt": dem.kt,
        "gamma_n": dem.gamma_n,
        "gamma_t": dem.gamma_t,
        "mu": dem.mu,
    }
    table = {
        "hooke-liggghts": {**hooke},
        "hooke-lammps": {**hooke},
        "hertz-liggghts": {
            "youngs_modulus": E,
            "poisson_ratio": POISSON,
            "restitution": e,
            "friction": dem.mu,
        },
        "hertz-lammps": {
            "kn": 4.0 / 3.0 * ystar,
            "kt": 8.0 * G,
            "gamma_n": dem.gamma_n / a_ref,
            "gamma_t": dem.gamma_t / a_ref,
            "mu": dem.mu,
        },
        "hertz-granular-lammps": {
            "youngs_modulus": E,
            "poisson_ratio": POISSON,
            "damp": e,
            "friction": dem.mu,
        },
        "hooke-epsd2-liggghts": {**hooke, "mu_r": ROLLING_MU},
        "hooke-epsd-liggghts": {**hooke, "mu_r": ROLLING_MU, "eta_r": ROLLING_ETA},
        "hooke-cdt-liggghts": {**hooke, "mu_r": ROLLING_MU},
        "hooke-sds-lammps": {
            "kn": dem.kn,
            "damp": dem.gamma_n,
            "kt": dem.kt,
            "xgammat": dem.gamma_t / dem.gamma_n if dem.gamma_n else 0.0,
            "mu": dem.mu,
            "kroll": dem.kt,
            "gammaroll": 0.0,
            "muroll": ROLLING_MU,
        },
    }
    missing = set(law_names()) - set(table)
    if missing:
        raise ValueError(f"law_table: no parameters for {', '.join(sorted(missing))}")
    return {k: table[k] for k in law_names()}


def build_law(name: str, params: dict):
    """The law object of ``name``: :func:`gransim.contacts.laws.make_law` (a law built by name
    keeps the constants its deck lines need)."""
    return make_law(name, **params)


def _perturbed(common, k: int, ax: int, sign: float):
    xp = np.array(common.positions)
    xp[k, ax] *= 1.0 + sign * PERTURB_REL
    return Packing(positions=xp, radii=common.radii, cell=common.cell, density=common.density, metadata={})


def law_jobs(ctx: Context, common, dem, table: dict | None = None) -> dict:
    """The code jobs of the case: {(law name, label): {"job_dir", "packing", "settings", "law",
    "engine"}} with label "reference" (the serial run) and the :data:`PERTURB` members, for every
    law whose code is available in ``ctx``. ``settings`` is ``dem`` in the law's flavour."""
    table = law_table(common, dem) if table is None else table
    jobs = {}
    for name, params in table.items():
        code = law_code(name)
        if not (ctx.liggghts if code == "liggghts" else ctx.lammps):
            continue
        law = build_law(name, params)
        settings = dataclasses.replace(dem, flavour=code, mode="serial")
        base = ctx.work("reference", "biaxial-laws", name, f"strain{STRAIN:g}")
        jobs[(name, "reference")] = {
            "job_dir": base / "reference",
            "packing": common,
            "settings": settings,
            "law": law,
            "engine": code,
        }
        for label, k, ax, sign in PERTURB:
            k = common.n // 2 if k is None else k
            jobs[(name, label)] = {
                "job_dir": base / f"perturbed-{k}-{ax}",
                "packing": _perturbed(common, k, ax, sign),
                "settings": settings,
                "law": law,
                "engine": code,
            }
    return jobs


def write_job_deck(tmp, job: dict, loading, nsteps: int, velocities, spins, dump_every: int, thermo_every: int):
    """Deck of one job of :func:`law_jobs` in ``tmp``: (deck path, {file name: bytes})."""
    deck = write_biaxial_deck(
        tmp,
        job["packing"],
        job["settings"],
        loading,
        nsteps,
        thermo_every=thermo_every,
        dump_every=dump_every,
        velocities=velocities,
        spins=spins,
        engine=job["engine"],
        law=job["law"],
    )
    files = {q.name: q.read_bytes() for q in Path(tmp).iterdir() if q.is_file() and q != deck}
    return deck, files


def run_code_job(
    job: dict,
    loading,
    nsteps: int,
    dump_every: int,
    velocities,
    spins,
    thermo_every: int,
    timeout: float,
):
    """Run one job (reused when complete); (Trajectory, manifest)."""
    with tempfile.TemporaryDirectory() as tmp:
        deck, files = write_job_deck(tmp, job, loading, nsteps, velocities, spins, dump_every, thermo_every)
        res = run_job(
            job["job_dir"],
            deck.read_text(),
            files=files,
            outputs=("dump.atoms",),
            expected_runs=1,
            progress=False,
            timeout=timeout,
            engine=job["engine"],
        )
    tr = read_reference(res.log_path, res.path("dump.atoms"))
    el = 0.0 if res.skipped else float(res.manifest.get("elapsed_s", 0.0))
    return Trajectory(tr.steps, tr.stress, tr.lengths, tr.frames, el), res.manifest


def run_native_law(
    packing,
    settings,
    law,
    loading,
    nsteps: int,
    dump_every: int,
    velocities,
    spins,
    thermo_every: int,
):
    """:func:`validation.dem_compare.run_native` with a contact law (``DEMEngine(..., law=law)``)."""
    t0 = time.perf_counter()
    eng = DEMEngine(packing, settings, velocities=velocities, spins=spins, law=law)
    box0 = (eng.lo.copy(), eng.hi.copy())
    st = [np.array([eng.stress[0, 0], eng.stress[1, 1], eng.stress[0, 1]])[None]]
    L = [eng.box_lengths.copy()[None]]
    frames = {0: _frame(eng)}
    done = 0
    while done < nsteps:
        stop = min(nsteps, (done // dump_every + 1) * dump_every)
        out = eng.advance(loading, stop - done, phase_step0=0, phase_box0=box0)
        done = stop
        s = out["stress"]
        st.append(np.stack([s[:, 0, 0], s[:, 1, 1], s[:, 0, 1]], axis=1))
        L.append(out["lengths"])
        frames[done] = _frame(eng)
    keep = slice(None, None, int(thermo_every))
    return Trajectory(
        np.arange(nsteps + 1)[keep],
        np.concatenate(st)[keep],
        np.concatenate(L)[keep],
        frames,
        time.perf_counter() - t0,
    )


def common_start(ctx: Context) -> dict:
    """The consolidated Kuhn assembly every law starts from (module docstring) and the protocol:
    {"packing", "settings", "biaxial", "loading", "nsteps", "velocities", "spins"}."""
    pk = _kuhn(ctx)
    dem, bi = dem_defaults(pk, strain=STRAIN)
    servo = _servo(bi)
    eng = DEMEngine(pk, dem)
    eng.advance(
        Loading(x=servo, y=servo),
        FULL_CONSOLIDATION_STEPS,
        phase_step0=0,
        phase_box0=(eng.lo.copy(), eng.hi.copy()),
    )
    common = Packing(
        positions=eng.x - eng.lo,
        radii=pk.radii,
        cell=np.diag(eng.box_lengths),
        density=pk.density,
        metadata={},
    )
    loading = Loading(x=servo, y=AxisControl("rate", rate=-bi.strain_rate))
    nsteps = int(np.ceil(bi.strain / (bi.strain_rate * dem.dt) / FULL_DUMP_EVERY)) * FULL_DUMP_EVERY
    return {
        "packing": common,
        "settings": dem,
        "biaxial": bi,
        "loading": loading,
        "nsteps": nsteps,
        "velocities": eng.v.copy(),
        "spins": eng.w.copy(),
    }


def plan(ctx: Context, c: dict, pool, manifests: dict) -> tuple[list, list]:
    """The runs of the case and their comparisons, from the common start ``c``
    (:func:`common_start`): per law, the native run in its code's arithmetic, the code's serial
    reference and its :data:`PERTURB` members (live runs: the jobs of the codes installed are
    submitted to ``pool`` at once, so they run beside the native runs; ``manifests`` collects their
    manifests); the native run judged against the code's own envelope (``envelope``)."""
    pk, dem = c["packing"], c["settings"]
    table = law_table(pk, dem)
    every = dataclasses.replace(ctx, liggghts=True, lammps=True)  # every law's jobs, made only where installed
    jobs = law_jobs(every, pk, dem, table)
    te, de, n = FULL_THERMO_EVERY, FULL_DUMP_EVERY, c["nsteps"]
    to = ctx.job_timeout(pk.n * n)
    fut = {
        k: pool.submit(run_code_job, j, c["loading"], n, de, c["velocities"], c["spins"], te, to)
        for k, j in jobs.items()
        if ctx.has(j["engine"])
    }

    def code_run(key):
        def make():
            try:
                tr, man = fut[key].result()
            except ReferenceRunError as exc:
                return Failed(f"{key[1]} job failed: {str(exc).splitlines()[0]}")
            manifests[key] = man
            return tr

        return make

    runs, comps = [], []
    members = [m[0] for m in PERTURB]
    for name in table:
        code = law_code(name)
        ref = jobs[(name, "reference")]
        runs.append(Run(f"{name}/native", NATIVE, code, f"{name}, native in {code}'s arithmetic",
                        lambda ref=ref: run_native_law(pk, ref["settings"], ref["law"], c["loading"], n, de,
                                                       c["velocities"], c["spins"], te)))  # fmt: skip
        for label in ("reference", *members):
            runs.append(Run(f"{name}/{label}", code, code, f"{name}, {code} {label}", code_run((name, label)),
                            live=True))  # fmt: skip
        comps.append(
            Comparison(
                "envelope", f"biaxial-laws/{name}", (f"{name}/native", f"{name}/reference",
                                                     *(f"{name}/{m}" for m in members)),
                f"each {code} law: native within 10x the code's envelope",
                {"member_names": members, "nsteps": n, "dump_every": de, "thermo_every": te, "d50": pk.d50,
                 "rule": FULL_RULE, "run_name": f"native ({code})", "reference_name": f"{code} reference"},
            )
        )  # fmt: skip
    return runs, comps


@case(
    "biaxial-laws",
    "Biaxial test on the Kuhn assembly with each contact law: native vs its code's envelope",
    suites=("full",),
    order=31,
)
def biaxial_laws(ctx: Context) -> CaseResult:
    res = CaseResult(
        "biaxial-laws",
        "Biaxial test on the Kuhn assembly with each contact law: native vs its code's envelope",
        "The compression of biaxial-full (axial strain 0.005, sigma_11 = p by the servo) from one "
        "consolidated state with each contact law of gransim.contacts.laws (Hooke, Hertz-Mindlin, "
        "rolling resistance), run by the native engine in the law's code's arithmetic and by that "
        "code; the native run's divergence from the code's serial reference must stay within 10 "
        "times the code's own round-off envelope (two runs with one coordinate moved by 1e-15), "
        "positions at every dump and stress at every thermo row.",
    )
    res.skip_pair(
        "liggghts-lammps",
        "each law is one code's: no cross-code pair (Hooke is compared in biaxial-full)",
    )
    res.skip_code("yade", "no YADE run: the laws are LIGGGHTS' and LAMMPS' (Hooke against YADE: biaxial-short)")
    c = common_start(ctx)
    table = law_table(c["packing"], c["settings"])
    manifests: dict = {}
    with ThreadPoolExecutor(max_workers=max(int(ctx.jobs), 1)) as pool:
        runs, comps = plan(ctx, c, pool, manifests)
        try:
            out = evaluate(res, ctx, runs, comps)
        finally:  # a case that stops early leaves no job queued (the running ones end with the pool)
            pool.shutdown(wait=False, cancel_futures=True)
    rows = []
    for name in table:
        code = law_code(name)
        sm = out.summaries.get(f"biaxial-laws/{name}")
        if sm is None:
            continue
        man = manifests.get((name, "reference"), {})
        res.notes.append(f"{name}: {table[name]} ({man.get('engine_version')}; parameters of law_table)")
        if not sm["complete"]:
            res.notes.append(f"<b>Incomplete evidence</b> ({name}): no envelope verdict on what remains.")
        env = [r for r in res.records if r.case == f"biaxial-laws/{name}" and r.tolerance == FULL_RULE.factor]
        rows.append(
            [name, code, f"{out.runs[f'{name}/native'].elapsed:.1f}", f"{float(man.get('elapsed_s', 0.0)):.1f}"]
            + ([f"{r.value:.3g}" for r in env] or ["incomplete", "incomplete"])
        )  # fmt: skip
    res.tables.append(
        (
            "Each law: run times (s) and the native divergence over the code's envelope",
            ["law", "code", "native s", "code s", "position ratio", "stress ratio"],
            rows,
        )
    )
    return res
