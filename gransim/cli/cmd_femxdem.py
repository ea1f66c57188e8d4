"""``gransim femxdem``: Guo & Zhao's FEM x DEM biaxial specimen (macro problem; stand-in Gauss-point laws)."""

from __future__ import annotations

import sys

from ..errors import InputError
from ..parallel import add_options, make_executor  # register() needs add_options: loaded by --help either way
from ._paths import (
    check_count,
    check_executor_options,
    check_given_values,
    check_input,
    check_number,
    check_output_dir,
    integer,
    number,
)

#: the quick default (a 2 x 4 mesh, 10 steps) and the full benchmark (--full: Guo & Zhao's 8 x 16, 100 steps)
QUICK = {"mesh": (2, 4), "steps": 10}
FULL = {"mesh": (8, 16), "steps": 100}
STANDINS = ("taylor", "j2")


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "femxdem",
        help="FEM x DEM biaxial test of Guo & Zhao (2014): Q8 specimen, stateful Gauss points on Dask "
        "(today with stand-in laws, not yet the DEM RVE)",
        description="The 50 x 100 mm biaxial specimen of Guo & Zhao's FEM x DEM benchmark (biaxialSmooth.py): "
        "quadratic elements with 2 x 2 Gauss points, smooth platens, the bottom centre fixed, 100 kPa "
        "confining pressure (a follower load), the top moved down 1e-4 m per step, Newton to a relative "
        "correction of 1e-2. Default: a quick 2 x 4 mesh and 10 steps; --full: 8 x 16 elements (512 "
        "Gauss points) and 100 steps. The Gauss points hold a STAND-IN law (--rve): the DEM RVE is not "
        "available yet. Writes OUT/femxdem.h5, OUT/curves.png, OUT/report.md and a checkpoint per "
        "converged step (--resume continues it, bit for bit).",
    )
    p.add_argument(
        "--rve",
        default="taylor",
        help="the Gauss-point law (a stand-in until the DEM RVE plugs in): taylor (the affine Taylor RVE of "
        "Meier et al., consolidated to the confining pressure; default) or j2 (von Mises plasticity with a "
        "weaker centre element)",
    )
    p.add_argument("--full", action="store_true", help="the full benchmark: 8 x 16 elements, 100 steps")
    p.add_argument("--mesh", default=None, help="NXxNY elements (default 2x4; 8x16 with --full)")
    p.add_argument("--steps", type=integer, default=None, help="load steps (default 10; 100 with --full)")
    p.add_argument("--element", choices=["Q8", "Q9"], default="Q8", help="Q8 (default, Guo & Zhao's) or Q9")
    p.add_argument("--gauss", type=integer, default=None, help="Gauss points per direction (default 2; Q9: 3)")
    p.add_argument("--pressure", type=number, default=1.0e5, help="confining pressure (Pa, default 1e5)")
    p.add_argument("--top-step", type=number, default=1.0e-4, help="top platen displacement per step (m, 1e-4)")
    p.add_argument("--tol", type=number, default=1e-2, help="Newton: relative correction tolerance (1e-2)")
    p.add_argument("--max-iter", type=integer, default=25, help="Newton iterations per step before the run stops")
    p.add_argument("--packing", default=None, help="--rve taylor: HDF5 packing of the RVE (default: the most "
                   "uniform standard 700-disk RVE)")  # fmt: skip
    p.add_argument("--packing-dir", default="results/packings", help="where the standard packings are cached")
    p.add_argument("--out", default=None, help="output directory (default results/femxdem-<rve>)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run from OUT/checkpoint/")
    p.add_argument("--stop-after", type=integer, default=None, metavar="K", help="stop after step K (tests)")
    add_options(p)
    p.set_defaults(func=handler)


def _mesh(text: str) -> tuple[int, int]:
    try:
        nx, ny = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise InputError(f"--mesh: expected NXxNY (two integers, e.g. 8x16), got {text!r}") from None
    if not (1 <= nx <= 200 and 1 <= ny <= 200):
        raise InputError(f"--mesh: expected 1 to 200 elements each way, got {text!r}")
    return nx, ny


def handler(args) -> int:
    check_given_values(args)
    if args.rve not in STANDINS:
        raise InputError(
            f"--rve: expected one of {', '.join(STANDINS)} (stand-ins: the DEM RVE is not available yet), "
            f"got {args.rve!r}"
        )
    base = FULL if args.full else QUICK
    nx, ny = _mesh(args.mesh) if args.mesh else base["mesh"]
    steps = base["steps"] if args.steps is None else check_count(args.steps, "--steps", 1, 100_000)
    gauss = args.gauss if args.gauss is not None else (3 if args.element == "Q9" else 2)
    check_count(gauss, "--gauss", 2, 5)
    check_number(args.pressure, "--pressure", low=0)
    check_number(args.top_step, "--top-step", low=0, low_open=True, high=0.05)
    check_number(args.tol, "--tol", low=0, high=1, low_open=True, high_open=True)
    check_count(args.max_iter, "--max-iter", 1, 1000)
    check_count(args.stop_after, "--stop-after", 1, steps)
    check_executor_options(args.workers, args.scheduler)
    if args.packing is not None:
        if args.rve != "taylor":
            raise InputError(f"--packing: applies to --rve taylor only, not --rve {args.rve}")
        check_input(args.packing, "--packing")
    out = check_output_dir(args.out or f"results/femxdem-{args.rve}", "--out")
    check_output_dir(args.packing_dir, "--packing-dir")
    from .._numba import wait_passively  # noqa: PLC0415 - start-up: numba
    from ..fem.biaxial import BiaxialSpec  # noqa: PLC0415 - start-up: scipy
    from ..fem.femxdem import FemxdemInterrupted, run_femxdem  # noqa: PLC0415 - start-up: scipy

    spec = BiaxialSpec(
        nx=nx, ny=ny, element=args.element, gauss=gauss, pressure=args.pressure,
        top_step=args.top_step, steps=steps, tol=args.tol, max_iter=args.max_iter,
    )  # fmt: skip
    wait_passively()  # before any parallel kernel starts the OpenMP runtime, and before the workers start
    with make_executor(args.workers, args.scheduler) as executor:
        try:
            summary = run_femxdem(
                spec, args.rve, out, executor, resume=args.resume, stop_after=args.stop_after,
                packing=args.packing, packing_dir=args.packing_dir,
            )  # fmt: skip
        except FemxdemInterrupted as exc:
            print(str(exc), file=sys.stderr)
            return 0
    print(summary["report"])
    return 0
