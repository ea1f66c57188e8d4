"""Case ``slope``: the FE2 slope stability problem of Meier et al. section 5 (no LIGGGHTS side).

Not a code-to-code comparison: its checks are set against independent answers (Newton's
quadratic rate, which only a consistent tangent gives; the small-load solution against the
linear one; the Q1 patch test with the slope's material). Whether the service load completes,
the limit of the paper load and the final energy norms are reported as information, not
verdicts (:func:`gransim.fem.run.acceptance_records`). The results (von Mises with deformed
RVEs, load-settlement, Table 2) are in the report.
"""

from __future__ import annotations

import html

from ..core import PAIRS, CaseResult, Context, Record, case


@case("slope", "FE2 slope stability: Taylor RVE at every Gauss point", suites=("default", "full"), order=50)
def slope(ctx: Context) -> CaseResult:
    from gransim.fem.run import acceptance_records, run_slope_case

    res = CaseResult(
        "slope",
        "FE2 slope stability: Taylor RVE at every Gauss point",
        "Plane-strain slope (20 x 19 Q1 elements, 1520 Gauss points), the most uniform 700-disk RVE "
        "(contact normal density measure) as the material at every Gauss point (E_n = 2.8e7), dead load "
        "in step 1 then the eccentric footing force in 20 steps, Newton-Raphson on the relative energy "
        "norm. <i>service</i>: footing -5.0e6 N/m, must run to the end. <i>paper</i>: -4.0e7 N/m, "
        "expected to stop at a crest mechanism near 94% of the load (measured 0.943; the Taylor RVE "
        "carries no tension).",
    )
    for pair in PAIRS:
        res.skip_pair(
            pair,
            "no DEM code solves this problem: the FE2 checks are set against Newton's rate, the "
            "linear solution and the patch test (Taylor stresses are cross-checked in taylor-rve)",
        )
    summaries = {}
    for protocol in ("service", "paper"):
        out = ctx.work("slope", protocol)
        s = run_slope_case(protocol, out=out, figures="final", packing_dir=ctx.results / "packings")
        summaries[protocol] = s
        res.notes.append(f"<pre>{html.escape(s['report'])}</pre>")
        # the run drew each figure once (summary["files"]): the report copies those files, it never redraws
        state = "final state" if s["completed"] else "limit state (last converged step)"
        for key, cap in (("state_png", state), ("load_settlement_png", "load-settlement curve of the footing")):
            src = s["files"].get(key)
            if src is not None and src.exists():
                dest = ctx.copy_figure(src, f"slope_{protocol}_{src.name}")
                h5 = out / "slope.h5"
                res.add_figure(
                    dest,
                    f"slope, protocol {protocol}: {cap}",
                    data=h5 if h5.exists() else None,
                    headline=(protocol == "paper" and key == "state_png"),
                )
    for r in acceptance_records(summaries):
        res.records.append(
            Record(
                r["case"],
                r["quantity"],
                r["metric"],
                float(r["value"]),
                float(r["tolerance"]),
                bool(r["pass"]),
                r.get("note", ""),
                kind=r.get("kind", "check"),
            )
        )
    return res
