"""``gransim slope-compare``: slope results side by side (Taylor vs relaxed RVE)."""

from __future__ import annotations

from ..errors import InputError
from ._paths import check_count, check_distinct, check_given_values, check_input, check_output, check_output_dir


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "slope-compare",
        help="compare slope.h5 results: load-settlement curves, stress difference map with RVEs, Newton orders",
        description="Read two or more slope.h5 files of `gransim slope` (e.g. --rve taylor and --rve relaxed) and "
        "write OUT/compare_load_settlement.png (every curve), OUT/compare_map.png (the Cauchy stress "
        "difference of the first two at their last common converged step, the Gauss points that differ "
        "most marked and their RVEs drawn: Taylor centres F X, relaxed F X + w, w replayed from the run's "
        "checkpoint) and OUT/compare.md (status and limit load of each, energy norms and observed orders).",
    )
    p.add_argument("results", nargs="+", help="slope.h5 files (the map compares the first two)")
    p.add_argument("--out", default="results/slope-compare", help="output directory")
    p.add_argument("--points", type=int, default=4, help="how many of the most different Gauss points to mark")
    p.add_argument("--packing", default=None, help="the runs' RVE packing file when they used --packing")
    p.add_argument("--packing-dir", default="results/packings", help="the runs' --packing-dir (standard RVEs)")
    p.set_defaults(func=handler)


def handler(args) -> int:
    check_given_values(args)
    if len(args.results) < 2:
        raise InputError(f"slope-compare: expected at least two slope.h5 files, got {len(args.results)}")
    check_count(args.points, "--points", 0)
    for r in args.results:
        check_input(r, "slope result")
    if args.packing is not None:
        check_input(args.packing, "--packing")
    out = check_output_dir(args.out, "--out")
    written = [out / n for n in ("compare_load_settlement.png", "compare_map.png", "compare.md")]
    for w in written:
        check_output(w, "--out")
    check_distinct(
        [("--out", w) for w in written],
        [("slope result", r) for r in args.results] + [("--packing", args.packing)],
    )
    check_output_dir(args.packing_dir, "--packing-dir")  # the standard RVEs are generated there when missing
    from ..fem.compare import compare_slopes  # noqa: PLC0415 - start-up: numba

    res = compare_slopes(args.results, out, args.points, args.packing, args.packing_dir)
    print(res["markdown"])
    return 0
