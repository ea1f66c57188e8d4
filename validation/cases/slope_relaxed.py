"""Case ``slope-relaxed``: the FE2 slope with the relaxed RVE beside the Taylor RVE.

Full suite only (3.5 minutes wall at load average ~10 on the 2-core machine: most of it the relaxed paper
protocol's limit search on the reduced mesh).

1. **Full mesh, standard RVE (why the full relaxed slope stops in the dead-load step).** The
   most uniform 700-disk RVE at every Gauss point: its shear stiffness mu = D:A:D at F = 1 for the
   Taylor and the relaxed RVE, each checked against the energy's central second difference
   (independent of the tangent), and the reduced FE tangent K(0) of the 20 x 19 slope with each:
   its negative eigenvalues and the shear strains of the linear dead-load solution
   (:mod:`gransim.fem.stability`). The full relaxed run itself (13 minutes) is not repeated here;
   its figures are in docs/slope.md.
2. **Reduced mesh, lattice RVE (the comparison where the relaxed slope runs).** 10 x 5 Q1, a
   30-disk jittered triangular lattice RVE, service and paper protocols in 4 footing steps, Taylor
   and relaxed: ``gransim slope-compare`` (:mod:`gransim.fem.compare`): both load-settlement curves,
   the stress difference map with the most different Gauss points and their RVEs, limit loads,
   energy norms and observed orders. Check: the relaxed Newton's final order (best of the last
   two over the norms above round-off) >= 1.8 in every step with four norms above it (a
   consistent tangent gives 2, an inconsistent one 1); the rebuilt RVEs give back the stored stress.
"""

from __future__ import annotations

import functools
import html

import numpy as np

from ..codes import NATIVE
from ..core import PAIRS, CaseResult, Context, case, peak
from ..judges import Bound
from ..matrix import Comparison, Run, evaluate


def lattice_packing():
    """30 disks on a jittered triangular lattice (spacing 1 mm, overlap 5e-4 of the contact
    distance), the stand-in RVE of tests/cli/test_slope_resume.py."""
    from gransim import Packing

    a, nx, ny = 1e-3, 5, 6
    h = a * np.sqrt(3) / 2
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x = np.column_stack([(ii + 0.5 * (jj % 2)).ravel() * a, jj.ravel() * h])
    x += np.random.default_rng(1).uniform(-2e-4, 2e-4, x.shape) * a
    return Packing(positions=x, radii=np.full(len(x), 0.5 * a * 1.0005), cell=np.diag([nx * a, ny * h]))


def plan(ctx: Context, outs: dict) -> tuple[list, list]:
    """The runs of the case and their comparisons (``outs`` collects what the report shows: the
    full-mesh figures per RVE kind, the reduced runs' summaries and the comparison of the slopes).

    Runs (all native): per RVE kind on the full mesh, its shear stiffness checked against the
    energy and the stability of the slope's reference state; per kind and protocol the reduced
    slope; the comparison of the four reduced slopes (``gransim slope-compare``). Comparisons: each
    against its closed forms and bounds with the shared analytic judge."""
    from gransim.fem.compare import QUADRATIC, compare_slopes, final_order
    from gransim.fem.mesh import SlopeGeometry
    from gransim.fem.run import default_rve_packing, run_slope_case
    from gransim.fem.stability import mean_overlap_strain, reference_stability, rve_shear_stiffness
    from gransim.io import save_packing

    packing = functools.cache(lambda: default_rve_packing(ctx.results / "packings"))
    work = ctx.work("slope-relaxed")
    lat = work / "lattice.h5"

    def full(kind):
        def make():
            mu, st = rve_shear_stiffness(packing(), kind), reference_stability(packing(), kind)
            outs[("full", kind)] = (mu, st)
            outs["overlap"] = mean_overlap_strain(packing())
            return {
                ("", "RVE shear stiffness"): mu["relative_difference"],
                ("", "shear modulus"): mu["tangent"],
                ("", "reference state"): float(st["n_negative"]),
            }

        return make

    def reduced(kind, protocol):
        def make():
            if not lat.exists():
                save_packing(lat, lattice_packing())
            out = work / f"{kind}-{protocol}"
            s = run_slope_case(protocol, packing=str(lat), out=out, figures="none",
                               geometry=SlopeGeometry(columns=10, rows=5), rve=kind, load_steps=4)  # fmt: skip
            outs[(kind, protocol)] = (s, out / "slope.h5")
            lam = s["result"].limit["last_converged_load"][1] if s["result"].limit else 1.0
            fig = {("", "limit load"): float(lam)}
            orders = {st.step: final_order(st.energy_norms) for st in s["result"].steps}
            judged = {k: v for k, v in orders.items() if np.isfinite(v)}
            fig[("", "newton order")] = min(judged.values()) if judged else float("nan")
            outs[("orders", kind, protocol)] = (judged, orders)
            return fig

        return make

    def compared():
        for k in reduced_keys:  # the four slopes first (each made once)
            comparison_runs[k]()
        order = (("taylor", "service"), ("relaxed", "service"), ("taylor", "paper"), ("relaxed", "paper"))
        paths = [outs[key][1] for key in order]
        cmp = compare_slopes(paths, work / "compare", packing=lat)
        outs["compare"] = cmp
        return {("", "RVE pictures"): peak(cmp["replay_errors"].values())}  # NaN when none or any is NaN

    runs, comps = [], []
    for kind in ("taylor", "relaxed"):
        runs.append(Run(f"full/{kind}", NATIVE, "", f"the most uniform 700-disk RVE, {kind}, on the full mesh",
                        full(kind)))  # fmt: skip
        comps.append(Comparison(
            "analytic", f"slope-relaxed/full/{kind}", (f"full/{kind}",), REASON,
            {"expected": [("", "RVE shear stiffness"), ("", "shear modulus"), ("", "reference state")],
             "values": dict, "bound": FULL_BOUNDS, "metric": lambda item, quantity, vals: FULL_METRICS[quantity]},
        ))  # fmt: skip
    comparison_runs, reduced_keys = {}, []
    for protocol in ("service", "paper"):
        for kind in ("taylor", "relaxed"):
            key = f"reduced/{kind}-{protocol}"
            comparison_runs[key] = functools.cache(reduced(kind, protocol))
            reduced_keys.append(key)
            runs.append(Run(key, NATIVE, "", f"the reduced slope, {kind} RVE, {protocol} protocol",
                            comparison_runs[key]))  # fmt: skip
            expected = [("", "limit load")] + ([("", "newton order")] if kind == "relaxed" else [])
            comps.append(Comparison(
                "analytic", f"slope-relaxed/{key}", (key,), REASON,
                {"expected": expected, "values": dict,
                 "bound": {"limit load": Bound(float("nan"), "reported", "info"),
                           "newton order": Bound(QUADRATIC, NEWTON_REASON, "at_least")},
                 "metric": lambda item, quantity, vals, kind=kind, protocol=protocol: _reduced_metric(
                     quantity, outs.get(("orders", kind, protocol)))},
            ))  # fmt: skip
    runs.append(Run("reduced/compare", NATIVE, "", "gransim slope-compare of the four reduced slopes", compared))
    comps.append(Comparison(
        "analytic", "slope-relaxed/reduced/compare", ("reduced/compare",), REASON,
        {"expected": [("", "RVE pictures")], "values": dict, "bound": {"RVE pictures": Bound(1e-10, PICTURES_REASON)},
         "metric": lambda item, quantity, vals: "max relative |sigma(replayed RVE) - sigma(stored)|"},
    ))  # fmt: skip
    return runs, comps


REASON = "no DEM code solves this problem: checks against the energy and Newton's rate"
FULL_BOUNDS = {
    "RVE shear stiffness": Bound(
        1e-2,
        "independent check of the tangent in pure shear: the energy's central second difference needs no tangent; "
        "grazing contacts give ~5e-4 for Taylor, a tangent a few percent off fails",
    ),
    "shear modulus": Bound(float("nan"), "reported", "info"),
    "reference state": Bound(
        float("nan"), "reported: the linear dead-load solution's figures are in the notes", "info"
    ),
}
FULL_METRICS = {
    "RVE shear stiffness": "|D:A:D - second difference of W| / |D:A:D| at F = 1, g = 1e-6",
    "shear modulus": "mu = D:A:D at F = 1 (N/m)",
    "reference state": "negative eigenvalues of K(0) of the slope",
}
NEWTON_REASON = (
    "a consistent tangent gives order 2 in the last iterations; the relaxed RVE's condensed tangent must show it too"
)
PICTURES_REASON = "the drawn RVEs are the run's: Taylor from F, relaxed by replaying the checkpoint's committed F"


def _reduced_metric(quantity: str, orders) -> str:
    if quantity == "limit load":
        return "last converged footing fraction"
    judged, all_steps = orders if orders else ({}, {})
    where = min(judged, key=judged.get) if judged else None
    return (
        "min over steps of the final observed order (best of the last two, norms above 1e-24)"
        + (f"; lowest in step {where}" if where is not None else "; no step to judge")
        + f" ({len(judged)} of {len(all_steps)} steps judged)"
    )


@case("slope-relaxed", "FE2 slope: Taylor vs relaxed RVE", suites=("full",), order=51)
def slope_relaxed(ctx: Context) -> CaseResult:
    res = CaseResult(
        "slope-relaxed",
        "FE2 slope: Taylor vs relaxed RVE",
        "The slope of Meier et al. section 5 with the relaxed RVE (periodic fluctuations minimise the "
        "contact energy at fixed F, condensed tangent) beside the Taylor RVE. Full mesh: why the relaxed "
        "slope stops in the dead-load step (RVE shear stiffness and the stability of the reference "
        "state). Reduced mesh with a lattice RVE: the comparison, limit loads and Newton's rate.",
    )
    for pair in PAIRS:
        res.skip_pair(pair, REASON)
    outs: dict = {}
    evaluate(res, ctx, *plan(ctx, outs))
    (mt, st_t), (mr, st_r) = outs[("full", "taylor")], outs[("full", "relaxed")]
    for kind, (mu, st) in (("taylor", (mt, st_t)), ("relaxed", (mr, st_r))):
        res.notes.append(
            f"{kind}: pressure {mu['pressure']:.4g} N/m; K(0) has {st['n_unknowns']} unknowns; linear dead-load "
            f"solution: max |u| {st['max_displacement']:.3g} m, shear strain (Mohr radius) median "
            f"{st['shear_median']:.3g}, max {st['shear_max']:.3g}"
        )
    ov = outs["overlap"]
    res.notes.append(
        "<p>Full mesh, the most uniform 700-disk RVE (mean overlap strain "
        f"{ov:.3g}): shear stiffness mu = D:A:D at F = 1 Taylor {mt['tangent']:.4g} N/m, relaxed "
        f"{mr['tangent']:.4g} N/m (ratio {mr['tangent'] / mt['tangent']:.3g}). K(0) of the slope: "
        f"{st_t['n_negative']} negative eigenvalues with Taylor, {st_r['n_negative']} with relaxed. Linear "
        f"dead-load shear strains (median / max): Taylor {st_t['shear_median']:.3g} / {st_t['shear_max']:.3g}, "
        f"relaxed {st_r['shear_median']:.3g} / {st_r['shear_max']:.3g}. The relaxed packing at its generation "
        "pressure is at the jamming point: under the dead load its RVEs must rearrange far beyond their "
        "overlap strain, and the relaxed slope stops in step 1 (docs/slope.md: the full run).</p>"
    )
    cmp = outs["compare"]
    for key, cap in (
        ("load_settlement", "reduced slope (10 x 5, lattice RVE): load-settlement, Taylor and relaxed, both protocols"),
        (
            "map",
            "reduced slope, service: |sigma_relaxed - sigma_Taylor| per Gauss point, the most different "
            "marked, their RVEs (top Taylor, bottom relaxed)",
        ),
    ):
        src = cmp["files"].get(key)
        if src is not None and src.exists():
            res.add_figure(ctx.copy_figure(src, f"slope_relaxed_{src.name}"), cap, headline=(key == "map"))
    res.notes.append(f"<pre>{html.escape(cmp['markdown'])}</pre>")
    return res
