"""Case ``taylor-rve``: Taylor RVE stresses and contact forces, native gransim vs LIGGGHTS.

Both codes evaluate the same closed-form sums (eqs 5, 10 of Meier et al.) on the same affinely
mapped particles; they differ only in summation order and in how the periodic images are
built (LIGGGHTS: periodic box for compression, explicit image copies for shear, because its
triclinic boxes are broken). So the expected difference is round-off.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core import CaseResult, Context, case, compare, stored_job_record

KN = 2.8e7  # N/m, Table 1 of Meier et al. (the RVE study stiffness)
STRESS_TOL = 1e-10
STRESS_REASON = ("same closed-form Love/Taylor sum in both codes; only summation order differs, so round-off "
                 "(~1e-13 measured) is all that may remain; 1e-10 leaves 1000x margin and still catches "
                 "any missed contact (~1e-3)")
FORCE_TOL = 1e-9
FORCE_REASON = ("per-contact force kn*eps*n from the same positions; eps = r_i + r_j - |l| loses digits by "
                "cancellation (|l|/eps ~ 4e3), so 1e-9 of the largest force is round-off with margin")

PATH_NAMES = {"compression-11": "compression11", "compression-22": "compression22", "shear-12": "shear12",
              "shear-21": "shear21"}


def _suite_settings(suite: str) -> dict:
    if suite == "quick":
        return {"names": [f"rve-70-{k}" for k in (1, 2, 3)], "stride": 5, "study": False}
    return {"names": None, "stride": 1, "study": True}


def compare_contact_forces(packing, F, frame, contact_state_fn=None) -> dict:
    """Two-sided match of native contacts and LIGGGHTS' contact rows of one state.

    ``frame`` is a ``compute pair/gran/local`` dump of the explicit-image route: rows whose id1
    or id2 is a central particle (id <= N). Each native contact (i, j, l) appears from both
    ends as (central particle, branch vector to the partner); each LIGGGHTS row likewise from
    its central end(s). Ends are matched per central particle by branch vector (within 1e-9 of
    the mean radius). Returns ``{"worst": max |f_native - f_LIGGGHTS| / max |f| over matched ends,
    "n_native", "n_liggghts": numbers of ends, "unmatched_native", "unmatched_liggghts": lists of
    (particle, branch vector) that found no partner on the other side}``.

    ``contact_state_fn`` replaces :func:`gransim.rve.contact_state` (the tests drop contacts
    with it to show the comparison fails).
    """
    from gransim.rve import contact_state

    cs = (contact_state_fn or contact_state)(packing, F, KN)
    n = packing.n
    native: dict = {}
    for i, j, l, f in zip(cs.i, cs.j, cs.branch, cs.force):
        native.setdefault(int(i), []).append((np.asarray(l), np.asarray(f)))
        native.setdefault(int(j), []).append((-np.asarray(l), -np.asarray(f)))
    id1 = np.asarray(frame["id1"], int) - 1
    id2 = np.asarray(frame["id2"], int) - 1
    p1 = np.column_stack([frame["x1"], frame["y1"]])
    p2 = np.column_stack([frame["x2"], frame["y2"]])
    f1 = np.column_stack([frame["fx"], frame["fy"]])
    lig: dict = {}
    for a, b, xa, xb, fa in zip(id1, id2, p1, p2, f1):
        if a < n:
            lig.setdefault(int(a), []).append((xb - xa, fa))
        if b < n:
            lig.setdefault(int(b), []).append((xa - xb, -fa))
    fmax = float(np.abs(cs.force).max()) if len(cs.force) else 1.0
    tol = 1e-9 * float(np.mean(packing.radii))
    worst = 0.0
    un_nat, un_lig = [], []
    for a in sorted(set(native) | set(lig)):
        mine, other = native.get(a, []), list(lig.get(a, []))
        for l, f in mine:
            d = [float(np.linalg.norm(l - lo)) for lo, _ in other]
            k = int(np.argmin(d)) if d else -1
            if k < 0 or d[k] > tol:
                un_nat.append((a, tuple(float(c) for c in l)))
                continue
            worst = max(worst, float(np.abs(f - other[k][1]).max()) / fmax)
            other.pop(k)
        un_lig += [(a, tuple(float(c) for c in lo)) for lo, _ in other]
    return {"worst": worst, "n_native": sum(len(v) for v in native.values()),
            "n_liggghts": sum(len(v) for v in lig.values()), "unmatched_native": un_nat,
            "unmatched_liggghts": un_lig}


CONTACT_REASON = ("two-sided: every contact end of gransim must be a LIGGGHTS row and every LIGGGHTS row with a "
                  "central particle a gransim contact end (same positions, same contact test), so both counts "
                  "are equal and nothing is left unmatched on either side")


def contact_records(label: str, cmp: dict) -> list:
    """Records of one state's two-sided contact comparison: the two counts, the unmatched ends on
    each side (listed in the metric), and the force difference over the matched ends."""
    from ..core import Record

    def shown(lst):
        s = "; ".join(f"disk {a} l=({b[0]:.3g}, {b[1]:.3g})" for a, b in lst[:4])
        return s + (" ..." if len(lst) > 4 else "")

    nn, nl = cmp["n_native"], cmp["n_liggghts"]
    un, ul = cmp["unmatched_native"], cmp["unmatched_liggghts"]
    recs = [Record(label, "contact_count", f"|n_gransim - n_LIGGGHTS| (gransim {nn}, LIGGGHTS {nl} ends)",
                   float(abs(nn - nl)), 0.0, nn == nl and nn > 0, CONTACT_REASON)]
    for side, lst in (("gransim", un), ("LIGGGHTS", ul)):
        metric = f"{side} contact ends without a partner" + (f": {shown(lst)}" if lst else "")
        recs.append(Record(label, "contact_unmatched", metric, float(len(lst)), 0.0, not lst, CONTACT_REASON))
    matched = nn - len(un)
    recs.append(compare(label, "contact_force", f"max_abs_diff/max_force over {matched} matched ends",
                        cmp["worst"] if matched > 0 else float("nan"), FORCE_TOL, FORCE_REASON))
    return recs


def expected_series(run) -> dict:
    """{(path, route): expected state indices k} of a Taylor job, from the parameters it was asked
    for (``states.json``: n_steps, stride, the paths and routes of the deck): the periodic route
    exists on compression paths only (LIGGGHTS' triclinic boxes are broken, shared notes)."""
    import json

    from reference_runs.decks.taylor import PATHS, ROUTES

    meta = json.loads((Path(run.job_dir) / "states.json").read_text())
    ks = list(range(0, int(meta["n_steps"]) + 1, int(meta["stride"])))
    asked = {(st["path"], st["route"]) for st in meta["states"]}
    paths = [p for p in PATHS if any(a[0] == p for a in asked)] or list(PATHS)
    routes = [r for r in ROUTES if any(a[1] == r for a in asked)] or list(ROUTES)
    return {(p, r): ks for p in paths for r in routes if r == "images" or p.startswith("compression")}


def series_evidence(label: str, run, expected: dict | None = None) -> list:
    """Evidence records of a Taylor run: every expected (path, route) series present, each with
    every expected state."""
    from ..core import evidence

    expected = expected_series(run) if expected is None else expected
    recs = [evidence(label, "LIGGGHTS (path, route) series", [f"{p}/{r}" for p, r in expected],
                     [f"{p}/{r}" for p, r in run.series])]
    for (p, r), ks in expected.items():
        have = [int(k) for k in run.series[(p, r)].k] if (p, r) in run.series else []
        recs.append(evidence(f"{label}/{PATH_NAMES[p]}/{r}", "LIGGGHTS states", ks, have))
    return recs


def _liggghts_runs(ctx: Context, packings: dict, stride: int) -> tuple[dict, str]:
    """name -> TaylorRun, from live LIGGGHTS jobs (cached) or the stored outputs."""
    from gransim.io import load_packing
    from reference_runs.store import RVE_CASE, STORED, TAYLOR_CASE
    from reference_runs.taylor import read_taylor_job, run_taylor

    if ctx.liggghts:
        jobs = ctx.work("reference", "taylor")
        runs = {name: run_taylor(p, KN, jobs / name, name=name, stride=stride, progress=False,
                                 timeout=ctx.job_timeout(_taylor_work(p, 50 // stride + 1)))
                for name, p in packings.items()}
        return runs, "live LIGGGHTS jobs (one job per RVE, all states of the four paths)"
    runs = {}
    for stored in (RVE_CASE, TAYLOR_CASE):
        d = STORED / stored
        runs[stored] = read_taylor_job(d, load_packing(d / "packing.h5"))
    return runs, "stored LIGGGHTS outputs (reference_runs/stored/), LIGGGHTS being absent"


def _taylor_work(packing, states_per_path: int) -> float:
    """Particle-steps equivalent of a Taylor job: 6 series of ``states_per_path`` ``run 0`` states of
    about 4 N atoms (central particles and their image copies), each costing a few set-up steps."""
    return 6 * states_per_path * 4 * packing.n * 20


def _contact_runs(ctx: Context, packings: dict):
    """Per-contact dumps: a few states per path of one RVE per size (live), or the stored lattice case."""
    from gransim.io import load_packing
    from reference_runs.store import STORED, TAYLOR_CASE
    from reference_runs.taylor import read_taylor_job, run_taylor

    if ctx.liggghts:
        names = [n for n in packings if n.endswith("-1")]
        jobs = ctx.work("reference", "taylor-contacts")
        return {n: run_taylor(packings[n], KN, jobs / n, name=n, routes=("images",), stride=25, contacts=True,
                              progress=False, timeout=ctx.job_timeout(_taylor_work(packings[n], 3)))
                for n in names}
    d = STORED / TAYLOR_CASE
    return {TAYLOR_CASE: read_taylor_job(d, load_packing(d / "packing.h5"))}


@case("taylor-rve", "Taylor RVE stresses: 15 RVEs, compression 11/22 and simple shear 12/21", order=10)
def taylor_rve(ctx: Context) -> CaseResult:
    from gransim.generation import standard_packings
    from gransim.io import load_packing

    s = _suite_settings(ctx.suite)
    res = CaseResult(
        "taylor-rve", "Taylor RVE stresses: 15 RVEs, compression 11/22 and simple shear 12/21",
        "Every RVE is mapped affinely (x = F X) along F11, F22: 1 -> 0.9 and F12, F21: 0 -> 0.1 (50 steps). "
        "gransim's Cauchy stress (numba Taylor kernel, tension positive) is compared state by state with "
        "LIGGGHTS' virial stress of the same configuration (elastic normal contact, kn = E_n = 2.8e7 N/m, "
        "<code>run 0</code>), per RVE, path and LIGGGHTS route: <i>periodic</i> = true periodic box "
        "(compression only), <i>images</i> = explicit periodic image copies in an open box (needed for "
        "shear: triclinic boxes lose their ghosts in LIGGGHTS 3.8.0). Metric: max over states of "
        "max|sigma_gransim - sigma_LIGGGHTS| / max|sigma_LIGGGHTS|.")
    names = s["names"]
    paths = standard_packings(ctx.results / "packings", names=names)
    packings = {n: load_packing(p) for n, p in paths.items()}
    runs, source = _liggghts_runs(ctx, packings, s["stride"])
    res.notes.append(f"Reference: {source}.")
    from ..core import evidence

    if ctx.liggghts:
        res.records.append(evidence("taylor-rve", "RVEs run by LIGGGHTS", sorted(packings), sorted(runs)))
    for name, run in runs.items():
        if not ctx.liggghts:
            res.records.append(stored_job_record(f"taylor-rve/{name.replace('rve-', '')}", run.job_dir))
        res.records += series_evidence(f"taylor-rve/{name.replace('rve-', '')}", run)
    from gransim.rve import TaylorMaterial

    rows = []
    for name, run in runs.items():
        mat = TaylorMaterial(run.packing, KN)  # one material (and candidate cache) per RVE, all paths
        for (path, route), ser in sorted(run.series.items()):
            sig_n = mat.evaluate(np.asarray(ser.F)).cauchy
            scale = np.abs(ser.cauchy).reshape(len(ser.F), -1).max(axis=1)
            diff = np.abs(sig_n - ser.cauchy).reshape(len(ser.F), -1).max(axis=1)
            rel = float(np.max(diff / np.where(scale > 0, scale, 1.0)))
            label = name.replace("rve-", "")
            res.records.append(compare(f"taylor-rve/{label}/{PATH_NAMES[path]}/{route}", "stress",
                                       "max_rel_diff", rel, STRESS_TOL, STRESS_REASON))
            rows.append([name, path, route, len(ser.F), rel])
    for name, run in _contact_runs(ctx, packings).items():
        exp = {k: v for k, v in expected_series(run).items() if k[1] == "images"}
        res.records += series_evidence(f"taylor-rve/{name.replace('rve-', '')}/contacts", run, exp)
        for (path, route), ser in sorted(run.series.items()):
            if route != "images":
                continue
            for k, F in zip(ser.k, ser.F):
                frame = run.contacts(path, route, int(k))
                cmp = compare_contact_forces(run.packing, F, frame)
                res.records += contact_records(f"taylor-rve/{name.replace('rve-', '')}/{PATH_NAMES[path]}/k{k}",
                                               cmp)
    res.tables.append(("Stress agreement per RVE, path and LIGGGHTS route",
                       ["packing", "path", "route", "states", "max rel diff"], rows))
    if s["study"]:
        from gransim.rve.study import run_study

        _, _, pngs = run_study(packings, ctx.work("rve_study"), normal_stiffness=KN)
        for png in pngs:
            dest = ctx.copy_figure(png, f"rve_study_{Path(png).name}")
            res.figures.append((dest, f"RVE study (Figs 3-5 of Meier et al.): {Path(png).stem}; mean and "
                                      "standard deviation over the 5 RVEs of each size"))
    return res
