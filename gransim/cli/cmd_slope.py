"""``gransim slope``: the slope stability problem of Meier et al. section 5 with a Taylor RVE material."""

from __future__ import annotations

import sys
from pathlib import Path

from ..errors import ConvergenceError, InputError
from ..parallel import add_options, make_executor  # register() needs add_options: loaded by --help either way
from ._paths import (
    check_count,
    check_distinct,
    check_executor_options,
    check_given_values,
    check_input,
    check_number,
    check_output_dir,
)


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "slope",
        help="FE2-style slope stability: Q1 total-Lagrangian FE with an RVE (Taylor or relaxed) per Gauss point",
        description="Solve the slope of Meier, Steinmann & Kuhl section 5 (geometry: gransim's reading of "
        "their lost Fig. 6): dead load "
        "in step 1, then the footing force in 20 steps. Writes per-step VTU and PNG, the "
        "convergence table (Table 2), the load-settlement curve and an HDF5 file; a "
        "checkpoint after every converged step (--resume continues). --workers N / --scheduler ADDRESS evaluate "
        "the Gauss points on Dask.",
    )
    p.add_argument(
        "--protocol",
        choices=["service", "paper"],
        default="service",
        help="service: footing -5.0e6 N/m (runs to the end); paper: -4.0e7 N/m (stops at the "
        "crest mechanism near 94%% of the load: measured 0.943)",
    )
    p.add_argument(
        "--material",
        choices=["taylor", "neo-hookean"],
        default="taylor",
        help="taylor: the Taylor RVE (gransim.rve); neo-hookean: continuum test material (E = 3e7 Pa, nu = 0.3)",
    )
    p.add_argument(
        "--rve",
        default="taylor",
        help="the RVE material at every Gauss point: taylor (affine, Meier et al.) or relaxed "
        "(periodic fluctuations minimise the energy at fixed F, condensed consistent "
        "tangent; Gauss-point history committed at every converged load step)",
    )
    p.add_argument(
        "--relaxed-start",
        choices=["committed", "trial"],
        help="--rve relaxed (or --compare): where each FE Newton iteration's RVE relaxation starts at a Gauss point: "
        "committed (default), its last committed state; trial, its previous FE iterate of the same "
        "attempt (back to the committed state after a failed attempt): 1-2 RVE Newton iterations near "
        "FE convergence, but where an RVE rearranges its state follows the FE iterates (docs/slope.md)",
    )
    p.add_argument(
        "--mesh",
        default="20x19",
        help="COLUMNSxROWS of the slope mesh (default 20x19, 1520 Gauss points; e.g. 10x5 for a feasible relaxed run)",
    )
    p.add_argument("--load-steps", type=int, default=20, help="footing load steps after the dead load")
    p.add_argument(
        "--dead-load-steps",
        type=int,
        default=1,
        help="apply the dead load in this many equal steps (default 1, the paper's protocol); two "
        "runs with the same value share the converged loads k/K, which slope-compare maps when "
        "one material cannot carry the whole dead load",
    )
    p.add_argument(
        "--compare",
        action="store_true",
        help="run both RVE materials (taylor, relaxed) into OUT/taylor and OUT/relaxed and "
        "write OUT/compare_load_settlement.png and OUT/compare.md",
    )
    p.add_argument(
        "--packing",
        default=None,
        help="HDF5 packing file for the RVE (default: the most uniform of the five standard "
        "700-particle quartz-sand RVEs)",
    )
    p.add_argument(
        "--rves",
        choices=["most-uniform", "five"],
        default="most-uniform",
        help="most-uniform: one RVE everywhere; five: the five 700-particle RVEs in turn",
    )
    p.add_argument("--packing-dir", default="results/packings", help="where the standard packings are generated/cached")
    p.add_argument("--out", default=None, help="output directory (default results/slope-<protocol>)")
    p.add_argument(
        "--figures",
        choices=["final", "all", "none"],
        default="final",
        help="final (default): the picture and VTU of the last converged state and the "
        "load-settlement curve; all: also a PNG and a VTU for every converged step; none: "
        "no PNG or VTU (tables, report and slope.h5 are always written)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue an interrupted run from OUT/checkpoint/ (one file per converged load "
        "step); the result is bitwise that of an uninterrupted run; a checkpoint of "
        "other parameters is refused",
    )
    p.add_argument(
        "--stop-after",
        type=int,
        default=None,
        metavar="K",
        help="stop after load step K, its checkpoint written (to test --resume)",
    )

    add_options(p)
    p.add_argument("--tol", type=float, default=1e-20, help="relative energy norm tolerance")
    p.add_argument(
        "--min-fraction",
        type=float,
        default=1.0 / 64,
        help="smallest load increment, as a fraction of one step, before the run stops",
    )
    p.set_defaults(func=handler)


#: most load steps (--load-steps, --dead-load-steps): the schedule is a list of that length
MAX_LOAD_STEPS = 100_000
#: most elements of --mesh: 4 Gauss points each, every one an RVE (the default mesh has 380)
MAX_ELEMENTS = 1_000_000


def handler(args) -> int:
    check_given_values(args)
    out = check_output_dir(args.out or f"results/slope-{args.protocol}", "--out")
    check_output_dir(args.packing_dir, "--packing-dir")
    if args.packing is not None:
        from ..io import load_packing  # noqa: PLC0415 - start-up: h5py

        check_input(args.packing, "--packing")
        # the HDF5 files a run writes into --out (--compare: one run per RVE material in a sub-folder)
        runs = [out, out / "taylor", out / "relaxed"]
        check_distinct([("--out", r / "slope.h5") for r in runs], [("--packing", args.packing)])
        for r in runs:
            if Path(args.packing).resolve().is_relative_to((r / "checkpoint").resolve()):
                raise InputError(
                    f"--packing: {args.packing!r} is in the checkpoint folder of --out "
                    f"({str(r / 'checkpoint')!r}), which the run rewrites; keep the packing elsewhere"
                )
        load_packing(args.packing)  # a bad file is refused now, not after the mesh is built
    # the energy norm of a Newton correction, relative to the first: below 1 to mean anything
    check_number(args.tol, "--tol", low=0, high=1, low_open=True, high_open=True)
    check_number(args.min_fraction, "--min-fraction", low=0, high=1, low_open=True)
    from ..fem.materials import RVE_KINDS  # noqa: PLC0415 - start-up: scipy
    from ..fem.mesh import SlopeGeometry  # noqa: PLC0415 - start-up: scipy

    if args.rve not in RVE_KINDS:
        raise InputError(f"--rve: expected taylor or relaxed, got {args.rve!r}")
    if args.rve == "relaxed" and args.material != "taylor":
        raise InputError(f"--rve relaxed: needs the RVE material (--material taylor), got --material {args.material}")
    try:
        cols, rows = (int(v) for v in args.mesh.lower().split("x"))
    except ValueError:
        raise InputError(f"--mesh: expected COLUMNSxROWS (two integers, e.g. 20x19), got {args.mesh!r}") from None
    if cols < 2 or rows < 2:
        raise InputError(f"--mesh: expected at least 2 columns and 2 rows, got {args.mesh!r}")
    if cols * rows > MAX_ELEMENTS:
        raise InputError(f"--mesh: expected at most {MAX_ELEMENTS} elements (COLUMNS x ROWS), got {args.mesh!r}")
    check_count(args.load_steps, "--load-steps", 1, MAX_LOAD_STEPS)
    check_count(args.dead_load_steps, "--dead-load-steps", 1, MAX_LOAD_STEPS)
    total = args.dead_load_steps + args.load_steps
    check_count(args.stop_after, "--stop-after", 1)
    if args.stop_after is not None and args.stop_after > total:
        raise InputError(
            f"--stop-after {args.stop_after}: the run has {total} load steps (--dead-load-steps "
            f"{args.dead_load_steps} + --load-steps {args.load_steps}), so it would never stop there"
        )
    check_executor_options(args.workers, args.scheduler)
    if args.relaxed_start is not None and args.rve != "relaxed" and not args.compare:
        raise InputError(
            f"--relaxed-start {args.relaxed_start}: applies to the relaxed RVE only (--rve relaxed or "
            f"--compare), not to --rve {args.rve}"
        )
    args.relaxed_start = args.relaxed_start or "committed"
    if args.resume and args.compare:
        raise InputError("--resume: resumes one run; not with --compare")
    geometry = SlopeGeometry(columns=cols, rows=rows)
    kw = {
        "material": args.material,
        "packing": args.packing,
        "figures": args.figures,
        "tol": args.tol,
        "min_fraction": args.min_fraction,
        "assignment": args.rves,
        "packing_dir": args.packing_dir,
        "geometry": geometry,
        "load_steps": args.load_steps,
        "dead_load_steps": args.dead_load_steps,
        "relaxed_start": args.relaxed_start,
    }
    from .._numba import wait_passively  # noqa: PLC0415 - start-up: numba
    from ..fem.run import SlopeInterrupted  # noqa: PLC0415 - start-up: numba

    wait_passively()  # before any parallel kernel starts the OpenMP runtime, and before the workers start
    with make_executor(args.workers, args.scheduler) as executor:
        kw["executor"] = executor
        try:
            return _run(args, out, kw)
        except SlopeInterrupted as exc:
            print(str(exc), file=sys.stderr)
            return 0


def _run(args, out, kw) -> int:
    from ..fem.run import compare_slope, run_slope_case  # noqa: PLC0415 - start-up: numba

    if args.compare:
        if args.material != "taylor":
            raise InputError(f"--compare: needs the RVE material (--material taylor), got {args.material}")
        summaries = compare_slope(args.protocol, out=out, **{k: v for k, v in kw.items() if k != "material"})
        for s in summaries.values():
            print(s["report"])
            print()
        failed = [k for k, s in summaries.items() if not s["completed"]]
        if failed:
            raise ConvergenceError("; ".join(f"{k}: {summaries[k]['message']}" for k in failed))
        return 0
    summary = run_slope_case(args.protocol, out=out, rve=args.rve, resume=args.resume, stop_after=args.stop_after, **kw)
    print(summary["report"])
    if not summary["completed"]:
        print(f"outputs of every converged step kept in {out}", file=sys.stderr)
        raise ConvergenceError(summary["message"])
    return 0
