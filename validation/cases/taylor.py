"""Case ``taylor-rve``: Taylor RVE stresses and contact forces, native gransim vs LIGGGHTS.

Both codes evaluate the same closed-form sums (eqs 5, 10 of Meier et al.) on the same affinely
mapped particles; they differ only in summation order and in how the periodic images are
built (LIGGGHTS: periodic box for compression, explicit image copies for shear, because its
triclinic boxes are broken). So the expected difference is round-off.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

from gransim import generation
from gransim.io import load_packing
from gransim.rve import TaylorMaterial
from gransim.rve.study import run_study
from reference_runs import store
from reference_runs.store import RVE_CASE, TAYLOR_CASE, taylor_case
from reference_runs.taylor import read_taylor_job, run_taylor

from .. import yade_runs
from ..codes import CODES, NATIVE, code_label
from ..core import CaseResult, Context, case, stored_dir
from ..judges import TaylorStates
from ..matrix import Comparison, Run, evaluate
from ..taylor_compare import (  # noqa: F401 (compare_contact_forces, contact_records: used by the fault tests)
    CROSS_REASON,
    KN,
    STRESS_REASON,
    STRESS_TOL,
    compare_contact_forces,
    compare_contact_forces_by_pair,
    contact_records,
)

CASE = "taylor-rve"
#: display names of the reference codes
CODE = {code: code_label(code) for code in CODES}


def _suite_settings(suite: str) -> dict:
    if suite == "quick":
        return {"names": [f"rve-70-{k}" for k in (1, 2, 3)], "stride": 5, "study": False}
    return {"names": None, "stride": 1, "study": True}


def _taylor_work(packing, states_per_path: int) -> float:
    """Particle-steps equivalent of a Taylor job: 6 series of ``states_per_path`` ``run 0`` states of
    about 4 N atoms (central particles and their image copies), each costing a few set-up steps."""
    return 6 * states_per_path * 4 * packing.n * 20


@dataclass(frozen=True)
class TaylorCode:
    """How the taylor-rve case runs and reads one code: its live job directories (all states;
    the contact jobs), the route its contact rows come from and the matcher of their form. A code
    is one more entry of :data:`TAYLOR_CODES`; its comparisons follow from :func:`taylor_plan`."""

    jobs: str
    contact_jobs: str
    route: str
    match: object


TAYLOR_CODES = {
    # LIGGGHTS: the images route (its periodic boxes cannot shear), contacts matched by branch vector
    "liggghts": TaylorCode("taylor", "taylor-contacts", "images", compare_contact_forces),
    # LAMMPS: the periodic route (every path in a true periodic box), matched by pair and distance
    "lammps": TaylorCode("taylor-lammps", "taylor-contacts-lammps", "periodic", compare_contact_forces_by_pair),
}


def _live_states(ctx, packings, stride, engine) -> TaylorStates:
    jobs = ctx.work("reference", TAYLOR_CODES[engine].jobs)
    runs = {
        name: run_taylor(
            p,
            KN,
            jobs / name,
            name=name,
            stride=stride,
            progress=False,
            engine=engine,
            timeout=ctx.job_timeout(_taylor_work(p, 50 // stride + 1)),
        )
        for name, p in packings.items()
    }
    return TaylorStates(runs, False, f"live {CODE[engine]} jobs (one job per RVE, all states of the four paths)")


def _stored_states(engine) -> TaylorStates:
    runs = {}
    for base in (RVE_CASE, TAYLOR_CASE):
        stored = taylor_case(base, engine)
        d = Path(store.STORED) / stored
        runs[stored] = read_taylor_job(d, load_packing(d / "packing.h5"))
    return TaylorStates(
        runs, True, f"stored {CODE[engine]} outputs (reference_runs/stored/), {CODE[engine]} being absent"
    )


def _live_contacts(ctx, packings, engine) -> TaylorStates:
    tc = TAYLOR_CODES[engine]
    names = [n for n in packings if n.endswith("-1")]
    jobs = ctx.work("reference", tc.contact_jobs)
    runs = {
        n: run_taylor(
            packings[n],
            KN,
            jobs / n,
            name=n,
            routes=(tc.route,),
            stride=25,
            contacts=True,
            progress=False,
            timeout=ctx.job_timeout(_taylor_work(packings[n], 3)),
            engine=engine,
        )
        for n in names
    }
    return TaylorStates(runs, False, f"live {CODE[engine]} contact jobs ({tc.route} route)")


def _stored_contacts(engine) -> TaylorStates:
    d = Path(store.STORED) / taylor_case(TAYLOR_CASE, engine)
    runs = {taylor_case(TAYLOR_CASE, engine): read_taylor_job(d, load_packing(d / "packing.h5"))}
    return TaylorStates(runs, True, f"stored {CODE[engine]} contact rows")


def _material(packing):
    return TaylorMaterial(packing, KN)


# ---------------------------------------------------------------- YADE's column
#: YADE's Taylor states per suite: the RVEs and the stride along the 50-step paths (quick settings in
#: the default suite, about 4 s; every state of the 15 RVEs of Meier, Steinmann & Kuhl's study in the
#: full suite, about 95 s of YADE)
YADE_SETTINGS = {
    "quick": {"names": [f"rve-70-{k}" for k in (1, 2, 3)], "stride": 5},
    "default": {"names": [f"rve-70-{k}" for k in (1, 2, 3)], "stride": 5},
    "full": {"names": None, "stride": 1},
}
YADE_STORED = "taylor-rve-yade"
YADE_N_STEPS = 50
YADE_REASON = (
    "YADE 2023.02a's getStress and getStressAndTangent against gransim's Taylor stress and the material part of "
    "its tangent, state by state: round-off only (stress 1e-10 of max|sigma|: the branch vectors formed from "
    "centres in other orders, bound 3.2e-11; tangent 1e-12; zero entries exactly 0; no unmatched contact), "
    "docs/yade.md 'The 15 study RVEs'"
)


def yade_plan(ctx: Context, packings: dict, suite: str) -> tuple[list, list]:
    """YADE's Taylor column: its jobs of the suite's RVEs (:data:`YADE_SETTINGS`), run now (one job per
    RVE, results/reference/taylor-yade/<RVE>) or, with YADE absent, its stored outputs
    (reference_runs/stored/taylor-rve-yade, the quick settings only: a suite asking for more has
    incomplete evidence), against gransim by :func:`validation.judges.taylor_yade`: YADE's
    ``getStress`` and ``getStressAndTangent`` against gransim's Cauchy stress (eq 10 of Meier et al.)
    and the material part of its tangent (eq 12, its eps/d terms removed, pushed forward), the zero
    entries of YADE's tangent and the contacts of the two codes, state by state, every RVE and every
    state of each path present (docs/yade.md, "The 15 study RVEs")."""
    st = YADE_SETTINGS.get(suite, YADE_SETTINGS["default"])
    names = st["names"] or sorted(n for n in packings if n.startswith("rve-"))
    mine = {n: packings[n] for n in names if n in packings}
    ks = list(range(0, YADE_N_STEPS + 1, st["stride"]))
    ks = ks if ks[-1] == YADE_N_STEPS else [*ks, YADE_N_STEPS]

    def timeout(packing):
        return ctx.job_timeout(len(ks) * 4 * packing.n * 20)

    runs = [
        Run(
            "live/yade",
            "yade",
            "yade",
            f"one YADE job per RVE run now ({len(mine)} RVEs, every {st['stride']} states)",
            lambda: yade_runs.taylor_live(
                mine, KN, ctx.work("reference", "taylor-yade"), YADE_N_STEPS, st["stride"], timeout
            ),
            live=True,
            fallback="stored/yade",
        ),
        Run(
            "stored/yade",
            "yade",
            "yade",
            f"stored {YADE_STORED}",
            lambda: yade_runs.taylor_stored(mine, KN, stored_dir(YADE_STORED), YADE_N_STEPS, st["stride"]),
        ),
    ]
    comps = [
        Comparison(
            "taylor_yade",
            f"{CASE}/yade",
            ("native", "live/yade"),
            YADE_REASON,
            {"expected_rves": sorted(mine), "expected_ks": ks},
        )
    ]
    return runs, comps


def taylor_plan(ctx: Context, packings: dict, stride: int, suite: str = "quick") -> tuple[list, list]:
    """The runs and comparisons of taylor-rve: per code of :data:`TAYLOR_CODES`, its Taylor jobs
    (live, or the stored outputs when the code is absent) against gransim's Taylor stress of every
    state, its contact jobs against gransim's contacts (two-sided), and every two codes' stresses
    against each other on the states both ran."""
    here = [c for c in CODES if c in TAYLOR_CODES]
    runs = [Run("native", NATIVE, "", "gransim's Taylor material (numba kernel)", lambda: _material)]
    comps = []
    for code in here:
        runs += [
            Run(f"stored/{code}", code, code, "stored outputs", functools.partial(_stored_states, code)),
            Run(
                f"live/{code}",
                code,
                code,
                "one job per RVE run now",
                functools.partial(_live_states, ctx, packings, stride, code),
                live=True,
                fallback=f"stored/{code}",
            ),
            Run(
                f"stored-contacts/{code}", code, code, "stored contact rows", functools.partial(_stored_contacts, code)
            ),
            Run(
                f"live-contacts/{code}",
                code,
                code,
                "contact jobs run now",
                functools.partial(_live_contacts, ctx, packings, code),
                live=True,
                fallback=f"stored-contacts/{code}",
            ),
        ]
        comps.append(
            Comparison(
                "taylor_stress",
                f"{CASE}/{code}",
                ("native", f"live/{code}"),
                STRESS_REASON,
                {"expected_rves": sorted(packings), "tolerance": STRESS_TOL, "reason": STRESS_REASON},
            )
        )
        comps.append(
            Comparison(
                "taylor_contacts",
                f"{CASE}/{code}/contacts",
                ("native", f"live-contacts/{code}"),
                STRESS_REASON,
                {"route": TAYLOR_CODES[code].route, "match": TAYLOR_CODES[code].match},
            )
        )
    if "yade" in CODES:
        y_runs, y_comps = yade_plan(ctx, packings, suite)
        runs += y_runs
        comps += y_comps
    for i, a in enumerate(here):
        for b in here[i + 1 :]:
            comps.append(
                Comparison(
                    "taylor_cross",
                    f"{CASE}/{a}-{b}",
                    (f"live/{a}", f"live/{b}"),
                    CROSS_REASON,
                    {"engines": (a, b), "tolerance": STRESS_TOL, "reason": CROSS_REASON},
                )
            )
    return runs, comps


@case("taylor-rve", "Taylor RVE stresses: 15 RVEs, compression 11/22 and simple shear 12/21", order=10)
def taylor_rve(ctx: Context) -> CaseResult:
    s = _suite_settings(ctx.suite)
    res = CaseResult(
        CASE,
        "Taylor RVE stresses: 15 RVEs, compression 11/22 and simple shear 12/21",
        "Every RVE is mapped affinely (x = F X) along F11, F22: 1 -> 0.9 and F12, F21: 0 -> 0.1 (50 steps). "
        "gransim's Cauchy stress (numba Taylor kernel, tension positive) is compared state by state with "
        "the virial stress of LIGGGHTS and of LAMMPS for the same configuration (elastic normal contact, "
        f"kn = E_n = {KN:.3g} N/m, <code>run 0</code>), per RVE, path and route: <i>periodic</i> = true "
        "periodic box "
        "(LIGGGHTS: compression only, its triclinic boxes lose their ghosts in 3.8.0; LAMMPS: every path, "
        "shear in a triclinic box), <i>images</i> = explicit periodic image copies in an open box. Metric: max "
        "over states of max|sigma_a - sigma_b| / max|sigma_b|. Contact forces: LIGGGHTS images route (matched by "
        "branch vector), LAMMPS periodic route (matched by pair and distance), both two-sided; and LIGGGHTS "
        "against LAMMPS on every state both ran.",
    )
    names = s["names"]
    paths = generation.standard_packings(ctx.results / "packings", names=names)
    packings = {n: load_packing(p) for n, p in paths.items()}
    runs, comps = taylor_plan(ctx, packings, s["stride"], ctx.suite)
    out = evaluate(res, ctx, runs, comps)
    res.skip_code(
        "yade",
        "not declared: YADE and each code are judged against gransim's Taylor stress on the same states at 1e-10 "
        "(native vs YADE, native vs the code), so they agree to 2e-10 by the triangle inequality; YADE's jobs are "
        "the quick settings' RVEs in the default suite",
    )
    for r in runs:
        if r.code == "yade" and r.key in out.runs:  # {RVE: YADE's Taylor run, or why it failed}
            versions = [
                v for c in comps if c.kind == "taylor_yade" for v in out.summaries.get(c.label, {}).get("versions", [])
            ]
            res.notes.append(f"YADE reference: {r.source} ({', '.join(versions) or 'no job completed'}).")
        elif r.key in out.runs and r.code != NATIVE and not r.key.startswith(("live-contacts", "stored-contacts")):
            res.notes.append(f"{CODE[r.code]} reference: {out.runs[r.key].source}.")
    rows = [row for c in comps if c.kind == "taylor_stress" for row in out.summaries.get(c.label, {}).get("rows", [])]
    for c in comps:
        if c.kind == "taylor_cross" and c.label in out.summaries:
            a, b = c.params["engines"]
            res.notes.append(f"{CODE[a]} vs {CODE[b]}: {out.summaries[c.label]['states']} states compared directly.")
    yade_rows = [
        row for c in comps if c.kind == "taylor_yade" for row in out.summaries.get(c.label, {}).get("rows", [])
    ]
    if yade_rows:
        res.tables.append(
            (
                "gransim against YADE per RVE (largest relative difference over all states and paths)",
                ["RVE", "N", "states", "contacts", "getStress", "stress of getStressAndTangent", "tangent", "YADE s"],
                yade_rows,
            )
        )
    res.tables.append(
        (
            "Stress agreement per code, RVE, path and route",
            ["code", "packing", "path", "route", "states", "max rel diff"],
            rows,
        )
    )
    if s["study"]:
        _, _, pngs = run_study(packings, ctx.work("rve_study"), normal_stiffness=KN)
        for png in pngs:
            dest = ctx.copy_figure(png, f"rve_study_{Path(png).name}")
            res.figures.append(
                (
                    dest,
                    (
                        f"RVE study (Figs 3-5 of Meier et al.): {Path(png).stem}; mean and "
                        "standard deviation over the 5 RVEs of each size"
                    ),
                )
            )
    return res
