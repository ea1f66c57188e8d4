"""Case ``taylor-rve``: Taylor RVE stresses and contact forces, native gransim vs LIGGGHTS.

Both codes evaluate the same closed-form sums (eqs 5, 10 of Meier et al.) on the same affinely
mapped particles; they differ only in summation order and in how the periodic images are
built (LIGGGHTS: periodic box for compression, explicit image copies for shear, because its
triclinic boxes are broken). So the expected difference is round-off.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gransim import generation, rve
from gransim.io import load_packing
from gransim.paper import KN_2D
from gransim.rve import TaylorMaterial
from gransim.rve.study import run_study
from reference_runs import store
from reference_runs.decks.taylor import PATHS, ROUTES
from reference_runs.store import RVE_CASE, TAYLOR_CASE, taylor_case
from reference_runs.taylor import read_taylor_job, run_taylor

from ..core import CaseResult, Context, Record, case, compare, evidence, in_pair, peak, stored_job_record

#: 2D normal contact stiffness of the RVE study (N/m): E_n of Meier et al. Table 1 per m of thickness
KN = KN_2D
STRESS_TOL = 1e-10
STRESS_REASON = (
    "same closed-form Love/Taylor sum in both codes; only summation order differs, so round-off "
    "(~1e-13 measured) is all that may remain; 1e-10 leaves 1000x margin and still catches "
    "any missed contact (~1e-3)"
)
FORCE_TOL = 1e-9
FORCE_REASON = (
    "per-contact force kn*eps*n from the same positions; eps = r_i + r_j - |l| loses digits by "
    "cancellation (|l|/eps ~ 4e3), so 1e-9 of the largest force is round-off with margin"
)

PATH_NAMES = {
    "compression-11": "compression11",
    "compression-22": "compression22",
    "shear-12": "shear12",
    "shear-21": "shear21",
}


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
    cs = (contact_state_fn or rve.contact_state)(packing, F, KN)
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
    diffs, un_nat, un_lig = [], [], []
    for a in sorted(set(native) | set(lig)):
        mine, other = native.get(a, []), list(lig.get(a, []))
        for l, f in mine:
            d = [float(np.linalg.norm(l - lo)) for lo, _ in other]
            k = int(np.argmin(d)) if d else -1
            if k < 0 or not d[k] <= tol:  # a NaN distance matches nothing
                un_nat.append((a, tuple(float(c) for c in l)))
                continue
            diffs.append(float(np.abs(f - other[k][1]).max()) / fmax)
            other.pop(k)
        un_lig += [(a, tuple(float(c) for c in lo)) for lo, _ in other]
    return {
        "worst": peak(diffs),  # NaN when a force is NaN (max() would drop it) or none matched
        "n_native": sum(len(v) for v in native.values()),
        "n_liggghts": sum(len(v) for v in lig.values()),
        "unmatched_native": un_nat,
        "unmatched_liggghts": un_lig,
    }


CONTACT_REASON = (
    "two-sided: every contact end of gransim must be a LIGGGHTS row and every LIGGGHTS row with a "
    "central particle a gransim contact end (same positions, same contact test), so both counts "
    "are equal and nothing is left unmatched on either side"
)


def contact_records(label: str, cmp: dict, code: str = "LIGGGHTS") -> list:
    """Records of one state's two-sided contact comparison: the two counts, the unmatched ends on
    each side (listed in the metric), and the force difference over the matched ends."""

    def shown(lst):
        s = "; ".join(f"disk {a} l=({b[0]:.3g}, {b[1]:.3g})" for a, b in lst[:4])
        return s + (" ..." if len(lst) > 4 else "")

    nn, nl = cmp["n_native"], cmp["n_liggghts"]
    un, ul = cmp["unmatched_native"], cmp["unmatched_liggghts"]
    recs = [
        Record(
            label,
            "contact_count",
            f"|n_gransim - n_{code}| (gransim {nn}, {code} {nl} ends)",
            float(abs(nn - nl)),
            0.0,
            nn == nl and nn > 0,
            CONTACT_REASON.replace("LIGGGHTS", code),
        )
    ]
    for side, lst in (("gransim", un), (code, ul)):
        metric = f"{side} contact ends without a partner" + (f": {shown(lst)}" if lst else "")
        recs.append(Record(label, "contact_unmatched", metric, float(len(lst)), 0.0, not lst, CONTACT_REASON))
    matched = nn - len(un)
    recs.append(
        compare(
            label,
            "contact_force",
            f"max_abs_diff/max_force over {matched} matched ends",
            cmp["worst"] if matched > 0 else float("nan"),
            FORCE_TOL,
            FORCE_REASON,
        )
    )
    return recs


def expected_series(run) -> dict:
    """{(path, route): expected state indices k} of a Taylor job, from the parameters it was asked
    for (``states.json``: n_steps, stride, the paths and routes of the deck): on LIGGGHTS the
    periodic route exists on compression paths only (its triclinic boxes are broken, shared
    notes); on LAMMPS on every path (a true triclinic box for shear)."""
    meta = json.loads((Path(run.job_dir) / "states.json").read_text())
    ks = list(range(0, int(meta["n_steps"]) + 1, int(meta["stride"])))
    asked = {(st["path"], st["route"]) for st in meta["states"]}
    paths = [p for p in PATHS if any(a[0] == p for a in asked)] or list(PATHS)
    routes = [r for r in ROUTES if any(a[1] == r for a in asked)] or list(ROUTES)
    every_path = meta.get("engine", "liggghts") == "lammps"
    return {(p, r): ks for p in paths for r in routes if r == "images" or every_path or p.startswith("compression")}


def series_evidence(label: str, run, expected: dict | None = None) -> list:
    """Evidence records of a Taylor run: every expected (path, route) series present, each with
    every expected state."""
    code = CODE.get(getattr(run, "engine", "liggghts"), "LIGGGHTS")
    expected = expected_series(run) if expected is None else expected
    recs = [
        evidence(
            label,
            f"{code} (path, route) series",
            [f"{p}/{r}" for p, r in expected],
            [f"{p}/{r}" for p, r in run.series],
        )
    ]
    for (p, r), ks in expected.items():
        have = [int(k) for k in run.series[(p, r)].k] if (p, r) in run.series else []
        recs.append(evidence(f"{label}/{PATH_NAMES[p]}/{r}", f"{code} states", ks, have))
    return recs


CODE = {"liggghts": "LIGGGHTS", "lammps": "LAMMPS"}
PAIR = {"liggghts": "native-liggghts", "lammps": "native-lammps"}
CROSS_REASON = (
    "both codes evaluate the same closed-form sum on the same positions (LAMMPS in a true periodic "
    "triclinic box, LIGGGHTS through explicit images where its box cannot be sheared): round-off only, "
    "as against the native stress"
)


def compare_contact_forces_by_pair(packing, F, frame, contact_state_fn=None) -> dict:
    """Two-sided match of native contacts and a LAMMPS periodic-route contact dump of one state
    (``id1 id2 dist fx fy``, each periodic contact once, force on id1 in gransim's frame).

    Ends are matched per (particle, partner) by contact distance (within 1e-9 of the mean radius).
    Returns the dict of :func:`compare_contact_forces`."""
    cs = (contact_state_fn or rve.contact_state)(packing, F, KN)
    native: dict = {}
    for i, j, l, f in zip(cs.i, cs.j, cs.branch, cs.force):
        d = float(np.linalg.norm(l))
        native.setdefault((int(i), int(j)), []).append((d, np.asarray(f)))
        native.setdefault((int(j), int(i)), []).append((d, -np.asarray(f)))
    other: dict = {}
    f1 = np.column_stack([frame["fx"], frame["fy"]])
    for a, b, d, f in zip(np.asarray(frame["id1"], int) - 1, np.asarray(frame["id2"], int) - 1, frame["dist"], f1):
        other.setdefault((int(a), int(b)), []).append((float(d), f))
        other.setdefault((int(b), int(a)), []).append((float(d), -f))
    fmax = float(np.abs(cs.force).max()) if len(cs.force) else 1.0
    tol = 1e-9 * float(np.mean(packing.radii))
    diffs, un_nat, un_oth = [], [], []
    for key in sorted(set(native) | set(other)):
        rest = list(other.get(key, []))
        for d, f in native.get(key, []):
            dd = [abs(d - do) for do, _ in rest]
            k = int(np.argmin(dd)) if dd else -1
            if k < 0 or not dd[k] <= tol:  # a NaN distance matches nothing
                un_nat.append((key[0], (float(key[1]), d)))
                continue
            diffs.append(float(np.abs(f - rest[k][1]).max()) / fmax)
            rest.pop(k)
        un_oth += [(key[0], (float(key[1]), do)) for do, _ in rest]
    return {
        "worst": peak(diffs),  # NaN when a force is NaN (max() would drop it) or none matched
        "n_native": sum(len(v) for v in native.values()),
        "n_liggghts": sum(len(v) for v in other.values()),
        "unmatched_native": un_nat,
        "unmatched_liggghts": un_oth,
    }


def _code_runs(ctx: Context, packings: dict, stride: int, engine: str = "liggghts") -> tuple[dict, str]:
    """name -> TaylorRun of ``engine``, from live jobs (cached) or the stored outputs."""
    code = CODE[engine]
    if getattr(ctx, engine):
        jobs = ctx.work("reference", "taylor" if engine == "liggghts" else "taylor-lammps")
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
        return runs, f"live {code} jobs (one job per RVE, all states of the four paths)"
    runs = {}
    for base in (RVE_CASE, TAYLOR_CASE):
        stored = taylor_case(base, engine)
        d = Path(store.STORED) / stored
        runs[stored] = read_taylor_job(d, load_packing(d / "packing.h5"))
    return runs, f"stored {code} outputs (reference_runs/stored/), {code} being absent"


def _liggghts_runs(ctx: Context, packings: dict, stride: int) -> tuple[dict, str]:
    """:func:`_code_runs` of LIGGGHTS."""
    return _code_runs(ctx, packings, stride, "liggghts")


def _taylor_work(packing, states_per_path: int) -> float:
    """Particle-steps equivalent of a Taylor job: 6 series of ``states_per_path`` ``run 0`` states of
    about 4 N atoms (central particles and their image copies), each costing a few set-up steps."""
    return 6 * states_per_path * 4 * packing.n * 20


def _contact_runs(ctx: Context, packings: dict, engine: str = "liggghts"):
    """Per-contact dumps: a few states per path of one RVE per size (live), or the stored lattice
    case. LIGGGHTS: the images route (its periodic boxes cannot shear); LAMMPS: the periodic
    route (every path in a true periodic box)."""
    route = "images" if engine == "liggghts" else "periodic"
    if getattr(ctx, engine):
        names = [n for n in packings if n.endswith("-1")]
        jobs = ctx.work("reference", "taylor-contacts" if engine == "liggghts" else "taylor-contacts-lammps")
        return {
            n: run_taylor(
                packings[n],
                KN,
                jobs / n,
                name=n,
                routes=(route,),
                stride=25,
                contacts=True,
                progress=False,
                timeout=ctx.job_timeout(_taylor_work(packings[n], 3)),
                engine=engine,
            )
            for n in names
        }, route
    d = Path(store.STORED) / taylor_case(TAYLOR_CASE, engine)
    return {taylor_case(TAYLOR_CASE, engine): read_taylor_job(d, load_packing(d / "packing.h5"))}, route


@case("taylor-rve", "Taylor RVE stresses: 15 RVEs, compression 11/22 and simple shear 12/21", order=10)
def taylor_rve(ctx: Context) -> CaseResult:
    s = _suite_settings(ctx.suite)
    res = CaseResult(
        "taylor-rve",
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

    res.declare("native-liggghts", STRESS_REASON)
    res.declare("native-lammps", STRESS_REASON)
    res.declare("liggghts-lammps", CROSS_REASON)
    rows = []
    code_runs = {}
    for engine in ("liggghts", "lammps"):
        code = CODE[engine]
        runs, source = _code_runs(ctx, packings, s["stride"], engine)
        code_runs[engine] = runs
        res.notes.append(f"{code} reference: {source}.")
        recs = []
        if getattr(ctx, engine):
            recs.append(evidence("taylor-rve", f"RVEs run by {code}", sorted(packings), sorted(runs)))
        for name, run in runs.items():
            label = f"taylor-rve/{engine}/{name.replace('rve-', '')}"
            if not getattr(ctx, engine):
                recs.append(stored_job_record(label, run.job_dir))
            recs += series_evidence(label, run)
        for name, run in runs.items():
            mat = TaylorMaterial(run.packing, KN)  # one material (and candidate cache) per RVE, all paths
            for (path, route), ser in sorted(run.series.items()):
                sig_n = mat.evaluate(np.asarray(ser.F)).cauchy
                scale = np.abs(ser.cauchy).reshape(len(ser.F), -1).max(axis=1)
                diff = np.abs(sig_n - ser.cauchy).reshape(len(ser.F), -1).max(axis=1)
                rel = peak(diff / np.where(scale > 0, scale, 1.0))
                label = f"taylor-rve/{engine}/{name.replace('rve-', '')}/{PATH_NAMES[path]}/{route}"
                sides = {"native": sig_n, code: ser.cauchy}
                recs.append(compare(label, "stress", "max_rel_diff", rel, STRESS_TOL, STRESS_REASON, inputs=sides))
                rows.append([code, name, path, route, len(ser.F), rel])
        contact_runs, croute = _contact_runs(ctx, packings, engine)
        for name, run in contact_runs.items():
            exp = {k: v for k, v in expected_series(run).items() if k[1] == croute}
            recs += series_evidence(f"taylor-rve/{engine}/{name.replace('rve-', '')}/contacts", run, exp)
            for (path, route), ser in sorted(run.series.items()):
                if route != croute:
                    continue
                for k, F in zip(ser.k, ser.F):
                    frame = run.contacts(path, route, int(k))
                    cmp = (
                        compare_contact_forces(run.packing, F, frame)
                        if engine == "liggghts"
                        else compare_contact_forces_by_pair(run.packing, F, frame)
                    )
                    recs += contact_records(
                        f"taylor-rve/{engine}/{name.replace('rve-', '')}/{PATH_NAMES[path]}/k{k}", cmp, code
                    )
        res.records += in_pair(recs, PAIR[engine])
    # the two codes against each other on every state both ran (same packing, path, route, k)
    lig, lmp = code_runs["liggghts"], code_runs["lammps"]

    recs, n_states = [], 0
    for name, run in lig.items():
        other = lmp.get(name) or lmp.get(taylor_case(name, "lammps"))
        if other is None:
            recs.append(evidence(f"taylor-rve/cross/{name}", "LAMMPS run of the RVE LIGGGHTS ran", [name], []))
            continue
        for key, ser in sorted(run.series.items()):
            if key not in other.series:
                recs.append(
                    evidence(
                        f"taylor-rve/cross/{name}", "LAMMPS series of the LIGGGHTS series", [f"{key[0]}/{key[1]}"], []
                    )
                )
                continue
            o = other.series[key]
            common = np.intersect1d(ser.k, o.k)
            recs.append(
                evidence(
                    f"taylor-rve/cross/{name}/{PATH_NAMES[key[0]]}/{key[1]}",
                    "states of both codes",
                    [int(k) for k in ser.k],
                    [int(k) for k in common],
                )
            )
            ia, ib = np.searchsorted(ser.k, common), np.searchsorted(o.k, common)
            a, b = ser.cauchy[ia], o.cauchy[ib]
            scale = np.abs(a).reshape(len(a), -1).max(axis=1)
            rel = np.abs(a - b).reshape(len(a), -1).max(axis=1) / np.where(scale > 0, scale, 1.0)
            recs.append(
                compare(
                    f"taylor-rve/cross/{name.replace('rve-', '')}/{PATH_NAMES[key[0]]}/{key[1]}",
                    "stress",
                    "max_rel_diff LIGGGHTS vs LAMMPS",
                    peak(rel),
                    STRESS_TOL,
                    CROSS_REASON,
                    inputs={"LIGGGHTS": a, "LAMMPS": b},
                )
            )
            n_states += len(common)
    res.records += in_pair(recs, "liggghts-lammps")
    res.notes.append(f"LIGGGHTS vs LAMMPS: {n_states} states compared directly.")
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
