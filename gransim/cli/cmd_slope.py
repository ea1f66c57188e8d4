"""``gransim slope``: the slope stability problem of Meier et al. section 5 with a Taylor RVE material."""

from __future__ import annotations


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "slope", help="FE2-style slope stability: Q1 total-Lagrangian FE with a Taylor RVE per Gauss point",
        description="Solve the slope of Meier, Steinmann & Kuhl section 5 (geometry of issue 8): dead load "
                    "in step 1, then the footing force in 20 steps. Writes per-step VTU and PNG, the "
                    "convergence table (Table 2), the load-settlement curve and an HDF5 file.")
    p.add_argument("--protocol", choices=["service", "paper"], default="service",
                   help="service: footing -5.0e6 N/m (runs to the end); paper: -4.0e7 N/m (stops at the "
                        "crest mechanism near 92%% of the load)")
    p.add_argument("--material", choices=["taylor", "neo-hookean"], default="taylor",
                   help="taylor: the Taylor RVE (gransim.rve); neo-hookean: continuum test material "
                        "(E = 3e7 Pa, nu = 0.3)")
    p.add_argument("--packing", default=None,
                   help="HDF5 packing file for the RVE (default: the most uniform of the five standard "
                        "700-particle quartz-sand RVEs)")
    p.add_argument("--rves", choices=["most-uniform", "five"], default="most-uniform",
                   help="most-uniform: one RVE everywhere; five: the five 700-particle RVEs in turn")
    p.add_argument("--packing-dir", default="results/packings",
                   help="where the standard packings are generated/cached")
    p.add_argument("--out", default=None, help="output directory (default results/slope-<protocol>)")
    p.add_argument("--figures", choices=["all", "final", "none"], default="all",
                   help="PNG pictures for every converged step, only the last one, or none")
    p.add_argument("--tol", type=float, default=1e-20, help="relative energy norm tolerance")
    p.add_argument("--min-fraction", type=float, default=1.0 / 64,
                   help="smallest load increment, as a fraction of one step, before the run stops")
    p.set_defaults(func=handler)


def handler(args) -> int:
    import sys

    from ..errors import ConvergenceError
    from ..fem.run import run_slope_case
    from ._paths import check_input, check_number, check_output_dir

    out = check_output_dir(args.out or f"results/slope-{args.protocol}", "--out")
    check_output_dir(args.packing_dir, "--packing-dir")
    if args.packing is not None:
        from ..io import load_packing

        check_input(args.packing, "--packing")
        load_packing(args.packing)  # a bad file is refused now, not after the mesh is built
    # the energy norm of a Newton correction, relative to the first: below 1 to mean anything
    check_number(args.tol, "--tol", low=0, high=1, low_open=True, high_open=True)
    check_number(args.min_fraction, "--min-fraction", low=0, high=1, low_open=True)
    summary = run_slope_case(args.protocol, material=args.material, packing=args.packing, out=out,
                             figures=args.figures, tol=args.tol, min_fraction=args.min_fraction,
                             assignment=args.rves, packing_dir=args.packing_dir)
    print(summary["report"])
    if not summary["completed"]:
        print(f"outputs of every converged step kept in {out}", file=sys.stderr)
        raise ConvergenceError(summary["message"])
    return 0
