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

import html

import numpy as np

from ..core import PAIRS, CaseResult, Context, Record, case, peak


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


def _rec(case_, quantity, metric, value, tol, passed, note, kind="check"):
    return Record(case_, quantity, metric, float(value), float(tol), bool(passed), note, kind=kind)


@case("slope-relaxed", "FE2 slope: Taylor vs relaxed RVE", suites=("full",), order=51)
def slope_relaxed(ctx: Context) -> CaseResult:
    from gransim.fem.compare import QUADRATIC, compare_slopes, final_order
    from gransim.fem.mesh import SlopeGeometry
    from gransim.fem.run import default_rve_packing, run_slope_case
    from gransim.fem.stability import mean_overlap_strain, reference_stability, rve_shear_stiffness
    from gransim.io import save_packing

    res = CaseResult(
        "slope-relaxed",
        "FE2 slope: Taylor vs relaxed RVE",
        "The slope of Meier et al. section 5 with the relaxed RVE (periodic fluctuations minimise the "
        "contact energy at fixed F, condensed tangent) beside the Taylor RVE. Full mesh: why the relaxed "
        "slope stops in the dead-load step (RVE shear stiffness and the stability of the reference "
        "state). Reduced mesh with a lattice RVE: the comparison, limit loads and Newton's rate.",
    )
    for pair in PAIRS:
        res.skip_pair(pair, "no DEM code solves this problem: checks against the energy and Newton's rate")

    # -- 1. full mesh, standard RVE ---------------------------------------------------------
    packing = default_rve_packing(ctx.results / "packings")
    ov = mean_overlap_strain(packing)
    stab = {}
    for kind in ("taylor", "relaxed"):
        mu = rve_shear_stiffness(packing, kind)
        st = reference_stability(packing, kind)
        stab[kind] = (mu, st)
        res.records += [
            _rec(
                f"slope-relaxed/full/{kind}",
                "RVE shear stiffness",
                "|D:A:D - second difference of W| / |D:A:D| at F = 1, g = 1e-6",
                mu["relative_difference"],
                1e-2,
                mu["relative_difference"] <= 1e-2,
                "independent check of the tangent in pure shear: the energy's central second difference "
                "needs no tangent; grazing contacts give ~5e-4 for Taylor, a tangent a few percent off fails",
            ),
            _rec(
                f"slope-relaxed/full/{kind}",
                "RVE shear stiffness",
                "mu = D:A:D at F = 1 (N/m)",
                mu["tangent"],
                float("nan"),
                True,
                f"reported; pressure {mu['pressure']:.4g} N/m, mean overlap strain {ov:.3g}",
                kind="info",
            ),
            _rec(
                f"slope-relaxed/full/{kind}",
                "reference state",
                f"negative eigenvalues of K(0) ({st['n_unknowns']} unknowns)",
                st["n_negative"],
                float("nan"),
                True,
                f"reported; linear dead-load solution: max |u| {st['max_displacement']:.3g} m, shear strain "
                f"(Mohr radius) median {st['shear_median']:.3g}, max {st['shear_max']:.3g}",
                kind="info",
            ),
        ]
    (mt, st_t), (mr, st_r) = stab["taylor"], stab["relaxed"]
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

    # -- 2. reduced mesh, lattice RVE ---------------------------------------------------------
    work = ctx.work("slope-relaxed")
    lat = work / "lattice.h5"
    save_packing(lat, lattice_packing())
    paths, summaries = {}, {}
    for protocol in ("service", "paper"):
        for kind in ("taylor", "relaxed"):
            out = work / f"{kind}-{protocol}"
            s = run_slope_case(
                protocol,
                packing=str(lat),
                out=out,
                figures="none",
                geometry=SlopeGeometry(columns=10, rows=5),
                rve=kind,
                load_steps=4,
            )
            paths[(kind, protocol)] = out / "slope.h5"
            summaries[(kind, protocol)] = s
    cmp = compare_slopes(
        [
            paths[("taylor", "service")],
            paths[("relaxed", "service")],
            paths[("taylor", "paper")],
            paths[("relaxed", "paper")],
        ],
        work / "compare",
        packing=lat,
    )
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
    for (kind, protocol), s in summaries.items():
        name = f"slope-relaxed/reduced/{kind}-{protocol}"
        lam = s["result"].limit["last_converged_load"][1] if s["result"].limit else 1.0
        res.records.append(
            _rec(name, "limit load", "last converged footing fraction", lam, float("nan"), True, "reported", "info")
        )
        if kind != "relaxed":
            continue
        orders = {st.step: final_order(st.energy_norms) for st in s["result"].steps}
        judged = {k: v for k, v in orders.items() if np.isfinite(v)}
        worst = min(judged.values()) if judged else float("nan")
        where = min(judged, key=judged.get) if judged else None
        res.records.append(
            _rec(
                name,
                "newton",
                "min over steps of the final observed order (best of the last two, norms above 1e-24)"
                + (f"; lowest in step {where}" if where is not None else "; no step to judge"),
                worst,
                QUADRATIC,
                bool(judged) and worst >= QUADRATIC,
                "a consistent tangent gives order 2 in the last iterations; the relaxed RVE's condensed tangent "
                f"must show it too ({len(judged)} of {len(orders)} steps judged)",
            )
        )
    worst_replay = peak(cmp["replay_errors"].values())  # NaN when none or any is NaN
    res.records.append(
        _rec(
            "slope-relaxed/reduced/compare",
            "RVE pictures",
            "max relative |sigma(replayed RVE) - sigma(stored)|",
            worst_replay,
            1e-10,
            bool(np.isfinite(worst_replay) and worst_replay <= 1e-10),
            "the drawn RVEs are the run's: Taylor from F, relaxed by replaying the checkpoint's committed F",
        )
    )
    return res
