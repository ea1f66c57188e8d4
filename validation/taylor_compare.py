"""Taylor states of a code's job and of gransim, as comparable evidence (the taylor-rve case's data access).

A Taylor job (:func:`reference_runs.taylor.run_taylor`, stored or live) holds, per RVE, the virial
stress of every state along the four paths (``series``: (path, route) -> states k, F, Cauchy stress)
and, for the contact jobs, the contact rows of each state. Here: the states a job was asked for
(:func:`expected_series`) and the evidence records of what it holds (:func:`series_evidence`), the
two-sided contact matchers of the two output forms (:func:`compare_contact_forces`: LIGGGHTS' images
route, matched by branch vector; :func:`compare_contact_forces_by_pair`: LAMMPS' periodic route,
matched by pair and distance) and their records (:func:`contact_records`). The judges
(:mod:`validation.judges`) compare with them.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gransim import rve
from gransim.paper import KN_2D
from reference_runs.decks.taylor import PATHS, ROUTES

from .codes import code_label
from .core import Record, compare, evidence, peak

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
    code = code_label(getattr(run, "engine", "liggghts"))
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
