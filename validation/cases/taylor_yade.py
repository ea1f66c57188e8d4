"""taylor-rve-yade: Taylor stress and the material part of the Taylor tangent of the 15 study RVEs,
gransim against YADE's ``getStress`` and ``getStressAndTangent``.

Every RVE of Meier, Steinmann & Kuhl's study ("Towards completeness, a multiscale approach of
confined particulate systems" (2007), section 4: five each of 70, 350 and 700 disks) is mapped
affinely along compression 11/22 (F11, F22: 1 -> 0.9) and simple shear 12/21 (F12, F21: 0 -> 0.1),
50 steps each, and every state is built in YADE 2023.02a's periodic cell (one YADE job per RVE,
:mod:`reference_runs.yade.taylor`). gransim's Cauchy stress (eq 10) is compared with YADE's two
stresses, the material part of gransim's tangent (eq 12, its eps/d terms removed, pushed forward)
with YADE's contact-stiffness tangent, and the contacts of the two codes with each other,
state by state (:func:`reference_runs.yade.compare.compare_yade_taylor`; docs/yade.md). YADE shares
no code with gransim, LIGGGHTS or LAMMPS; round-off is expected.

Evidence: every RVE must have run and every state of every path be in YADE's output (a job whose
output is cut short, lacks a state or a contact is failed by its reader, and recorded here as
``incomplete``); YADE absent, there is no evidence and the case fails, saying so.
"""

from __future__ import annotations

import math

import numpy as np

from gransim import generation
from gransim.io import load_packing
from gransim.paper import KN_2D
from gransim.rve import TaylorMaterial
from reference_runs.decks.taylor import PATHS
from reference_runs.engines import YADE
from reference_runs.errors import ReferenceRunError
from reference_runs.judge import JudgeError
from reference_runs.yade.compare import (
    compare_yade_taylor,
)
from reference_runs.yade.taylor import run_yade_taylor

from ..core import CaseResult, Context, Record, case, evidence, in_pair
from ..judges import yade_taylor_records

CASE = "taylor-rve-yade"
TITLE = "Taylor stress and tangent (material part) of the 15 RVEs against YADE's getStressAndTangent"
N_STEPS = 50
#: what each suite runs: the RVEs and the stride along the paths (every state of the study in full)
SUITE_SETTINGS = {
    "quick": {"names": [f"rve-70-{k}" for k in (1, 2, 3)], "stride": 5},
    "default": {"names": None, "stride": 25},
    "full": {"names": None, "stride": 1},
}
PATH_NAMES = {
    "compression-11": "compression11",
    "compression-22": "compression22",
    "shear-12": "shear12",
    "shear-21": "shear21",
}


def _expected_k(stride: int) -> list:
    ks = list(range(0, N_STEPS + 1, stride))
    return ks if ks[-1] == N_STEPS else [*ks, N_STEPS]


def _yade_work(packing, n_states: int) -> float:
    """Particle-steps equivalent of a YADE Taylor job: per state a fresh scene (N bodies created
    from Python, about 50 us each) and one step, counted as 20 steps of N particles."""
    return n_states * packing.n * 20


#: the checks of one RVE and path: validation.judges.yade_taylor_records
_records = yade_taylor_records


@case(CASE, TITLE, suites=("full",), order=11)
def taylor_rve_yade(ctx: Context) -> CaseResult:
    """Every record of the case in the native vs YADE column."""
    res = _taylor_rve_yade(ctx)
    res.records = in_pair(res.records, "native-yade")
    return res


def _taylor_rve_yade(ctx: Context) -> CaseResult:
    s = SUITE_SETTINGS[ctx.suite]
    ks = _expected_k(s["stride"])
    res = CaseResult(CASE, TITLE, __doc__.split("\n\n", 1)[1].replace("\n", " "))
    res.declare("native-yade", "YADE's getStress, getStressAndTangent and interactions against gransim, state by state")
    for code in ("liggghts", "lammps"):
        res.skip_code(code, "gransim against YADE only (taylor-rve sets LIGGGHTS and LAMMPS against gransim)")
    res.notes.append(
        f"{ctx.suite} suite: {'all 15 RVEs' if s['names'] is None else ', '.join(s['names'])}, "
        f"states k = {ks[0]}, {ks[1]}, ..., {ks[-1]} of {N_STEPS} on each path; kn = {KN_2D:.4g} N/m."
    )
    paths = generation.standard_packings(
        ctx.results / "packings", names=s["names"] or [n for n in generation.STANDARD_PACKINGS if n.startswith("rve-")]
    )
    packings = {n: load_packing(p) for n, p in paths.items()}
    if not YADE.available():
        res.records.append(evidence(CASE, "RVEs run by YADE", sorted(packings), []))
        res.error = f"YADE is not installed: no evidence ({YADE.install_hint})"
        return res
    jobs = ctx.work("reference", "taylor-yade")
    ran, rows, versions = [], [], set()
    for name, packing in packings.items():
        short = name.replace("rve-", "")
        n_states = len(PATHS) * len(ks)
        try:
            run = run_yade_taylor(
                packing,
                KN_2D,
                jobs / name,
                n_steps=N_STEPS,
                stride=s["stride"],
                name=name,
                timeout=ctx.job_timeout(_yade_work(packing, n_states)),
            )
        except ReferenceRunError as exc:  # failed or incomplete job: missing evidence, named
            first = str(exc).splitlines()[0]
            res.records.append(
                Record(f"{CASE}/{short}", "evidence", f"incomplete: YADE job failed: {first}", 1.0, 0.0, False)
            )
            continue
        ran.append(name)
        versions.add(run.manifest.get("engine_version"))
        for path in PATHS:
            have = [st["k"] for st in run.states if st["path"] == path]
            res.records.append(evidence(f"{CASE}/{short}/{PATH_NAMES[path]}", "YADE states", ks, have))
        try:
            cmp = compare_yade_taylor(run, TaylorMaterial(packing, KN_2D))
        except JudgeError as exc:  # NaN or inf on a side, no state: a failure, named
            res.records.append(Record(f"{CASE}/{short}", "evidence", f"cannot be judged: {exc}", math.nan, 0.0, False))
            continue
        for path in PATHS:
            sel = np.array([st["path"] == path for st in run.states])
            res.records += _records(f"{CASE}/{short}/{PATH_NAMES[path]}", cmp, sel)
        rows.append(
            [
                name,
                packing.n,
                len(run.states),
                f"{int(cmp.n_gransim.min())}-{int(cmp.n_gransim.max())}",
                f"{float(cmp.stress.max()):.2e}",
                f"{float(cmp.stress_tangent_call.max()):.2e}",
                f"{float(cmp.tangent.max()):.2e}",
                f"{float(run.manifest.get('elapsed_s', 0.0)):.1f}",
            ]
        )
    res.records.insert(0, evidence(CASE, "RVEs run by YADE", sorted(packings), ran))
    res.notes.append(f"YADE: {', '.join(sorted(str(v) for v in versions)) or 'no job completed'}.")
    res.tables.append(
        (
            "gransim against YADE per RVE (largest relative difference over all states and paths)",
            ["RVE", "N", "states", "contacts", "getStress", "stress of getStressAndTangent", "tangent", "YADE s"],
            rows,
        )
    )
    return res
