"""Case ``slope``: the FE2 slope stability problem of Meier et al. section 5 (no LIGGGHTS side).

Not a code-to-code comparison: its checks are set against independent answers (Newton's
quadratic rate, which only a consistent tangent gives; the small-load solution against the
linear one; the Q1 patch test with the slope's material). Whether the service load completes,
the limit of the paper load and the final energy norms are reported as information, not
verdicts. The case declares its two runs (service and paper protocols) and judges what each
measured of itself (:func:`gransim.fem.run.acceptance_figures`) with the shared analytic judge
against the bounds of :data:`BOUNDS`. The results (von Mises with deformed
RVEs, load-settlement, Table 2) are in the report.
"""

from __future__ import annotations

import html

from ..core import PAIRS, CaseResult, Context, case
from ..judges import Bound
from ..matrix import Comparison, Run, evaluate

PROTOCOLS = ("service", "paper")
#: the quantities of gransim.fem.run.acceptance_figures each protocol is judged on, and how
BOUNDS = {
    "completed": Bound(float("nan"), "reported: the -5e6 N/m service load is expected to run to the end", "info"),
    "limit load": Bound(
        float("nan"),
        "reported, not judged: the paper gives no limit load; the Taylor RVE carries no tension, so a crest "
        "mechanism is expected before the full load",
        "info",
    ),
    "final energy norm": Bound(
        float("nan"), "reported: the stopping criterion (tol 1e-20, or the residual at round-off)", "info"
    ),
    "newton order": Bound(
        1.5,
        "quadratic convergence (order 2) holds for a consistent tangent only; an inconsistent tangent gives "
        "order 1, below the 1.5 bound",
        "at_least",
    ),
    "small load": Bound(
        1e-2,
        "the Newton solution differs from the linear one (tangent at F = 1) by the small load's nonlinearity "
        "(measured: 5.0e-3 for the Taylor RVE, whose contacts open and close, 1.2e-5 for the smooth neo-Hookean "
        "stand-in); a tangent or residual off by a few percent gives a difference of that order, above 1e-2 "
        "(tests/fem: 20% off fails); NaN when the linear check could not be made",
    ),
    "patch test": Bound(
        1e-9,
        "exact case: a Q1 patch under an affine boundary field is solved by that field with P(F0) of the "
        "slope's RVE at every Gauss point; round-off ~1e-13",
    ),
}
METRICS = {
    "completed": "load path completed (1 = yes)",
    "limit load": "last converged footing fraction",
    "final energy norm": "largest final relative energy norm",
    "newton order": "min over steps of the best of the last two observed orders",
    "small load": "|q_newton - q_linear| / |q_linear| at 1e-3 of the dead load",
    "patch test": "max relative error of u and P on an affine patch",
}
#: what each protocol reports (info) besides the checks every protocol answers
REPORTED = {"service": ("completed",), "paper": ("limit load",)}
CHECKED = ("final energy norm", "newton order", "small load", "patch test")


def plan(ctx: Context, summaries: dict) -> tuple[list, list]:
    """The runs (the slope under each protocol, natively) and their comparisons with the closed
    forms and bounds of :data:`BOUNDS` (:func:`validation.judges.analytic`); ``summaries`` collects
    the runs' summaries (key: protocol)."""
    from gransim.fem.run import acceptance_figures, run_slope_case

    def make(protocol):
        def run():
            out = ctx.work("slope", protocol)
            s = run_slope_case(protocol, out=out, figures="final", packing_dir=ctx.results / "packings")
            summaries[protocol] = (s, out)
            return s

        return run

    runs = [Run(f"native/{p}", "native", "", f"gransim slope --protocol {p}", make(p)) for p in PROTOCOLS]
    comps = [
        Comparison(
            "analytic",
            f"slope/{p}",
            (f"native/{p}",),
            "the FE2 checks are set against Newton's rate, the linear solution and the patch test",
            {
                "expected": [("", q) for q in (*REPORTED[p], *CHECKED)],
                "values": lambda s: {("", q): v for q, v in acceptance_figures(s).items()},
                "bound": BOUNDS,
                "metric": lambda item, q, vals: METRICS[q],
            },
        )
        for p in PROTOCOLS
    ]
    return runs, comps


@case("slope", "FE2 slope stability: Taylor RVE at every Gauss point", suites=("default", "full"), order=50)
def slope(ctx: Context) -> CaseResult:
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
    summaries: dict = {}
    evaluate(res, ctx, *plan(ctx, summaries))
    for protocol in PROTOCOLS:
        s, out = summaries[protocol]
        res.notes.append(f"<pre>{html.escape(s['report'])}</pre>")
        if s.get("linear_check") is None:
            res.notes.append(
                f"{protocol}: the linear check could not be made: {s.get('linear_check_error') or 'not run'}"
            )
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
    return res
