"""``gransim femxdem``: Guo & Zhao's FEM x DEM biaxial specimen (macro problem; stand-in Gauss-point laws)."""

from __future__ import annotations

import signal
import sys
from pathlib import Path

from ..errors import GransimError, InputError
from ..parallel import add_options, make_executor  # register() needs add_options: loaded by --help either way
from ._paths import (
    check_count,
    check_distinct,
    check_executor_options,
    check_given_values,
    check_input,
    check_number,
    check_output,
    check_output_dir,
    integer,
    number,
    same_file,
)

#: the quick default (a 2 x 4 mesh, 10 steps, 25 Newton iterations a step) and the full benchmark
#: (--full: Guo & Zhao's 8 x 16, 100 steps, and their limit of 100 iterations, msFEM2D.py:204: past
#: the peak the contact-stiffness tangent needs 17-54 a step, docs/femxdem.md "Performance")
QUICK = {"mesh": (2, 4), "steps": 10, "max_iter": 25}
FULL = {"mesh": (8, 16), "steps": 100, "max_iter": 100}
#: both keep the contact-stiffness tangent (Guo & Zhao's) unless --tangent says otherwise: on the
#: full mesh past the peak the perturbation tangent halves the iterations from a given state but
#: leads to another equilibrium with dearer calls, for the same DEM CPU (docs/femxdem.md, "The tangent")
STANDINS = ("dem", "dem-lammps", "taylor", "j2")
#: the DEM RVEs (a tangent to choose, grains to draw)
DEM_RVES = ("dem", "dem-lammps")
#: the files a run writes into --out (besides checkpoint/)
OUTPUTS = ("femxdem.h5", "curves.png", "report.md")
#: most load steps; the confining pressure's bound (Pa: 100 MPa, beyond the crushing of quartz
#: grains and equal to the J2 stand-in's Young's modulus; measured: the 1 x 2 J2 mesh converges
#: there in 1-3 Newton iterations a step)
MAX_STEPS = 100_000
MAX_PRESSURE = 1.0e8
#: smallest top step (m) and Newton tolerance: below 1e-300 m the step's displacement norm
#: underflows and Newton never converges; the relative correction stalls near 2e-14 in double
#: precision (measured on the 2 x 4 J2 run), so a smaller tolerance is never met
MIN_TOP_STEP = 1.0e-12
MIN_TOL = 1.0e-12
#: the option of each BiaxialSpec field a checkpoint is compared on (--resume)
SPEC_OPTIONS = {
    "nx": "--mesh", "ny": "--mesh", "element": "--element", "gauss": "--gauss", "pressure": "--pressure",
    "top_step": "--top-step", "steps": "--steps", "tol": "--tol", "max_iter": "--max-iter",
}  # fmt: skip


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "femxdem",
        help="FEM x DEM biaxial test of Guo & Zhao (2014): Q8 specimen, stateful Gauss points on Dask, "
        "the DEM RVE (--rve dem) or stand-in laws",
        description="The 50 x 100 mm biaxial specimen of Guo & Zhao's FEM x DEM benchmark (biaxialSmooth.py): "
        "quadratic elements with 2 x 2 Gauss points, smooth platens, the bottom centre fixed, 100 kPa "
        "confining pressure (a follower load), the top moved down 1e-4 m per step, Newton to a relative "
        "correction of 1e-2. Default: a quick 2 x 4 mesh and 10 steps; --full: 8 x 16 elements (512 "
        "Gauss points) and 100 steps. The Gauss points hold Guo & Zhao's DEM RVE (--rve dem) or a stand-in law. "
        "Writes OUT/femxdem.h5, OUT/curves.png, OUT/report.md, at each --field-steps step the maps of "
        "deviatoric strain, void ratio and particle rotation (maps_K.png), a VTU of the quadratic mesh "
        "(mesh_K.vtu) and RVE pictures (rve_K_gG.png), and a checkpoint per converged step (--resume "
        "continues it, bit for bit).",
    )
    p.add_argument(
        "--rve",
        default="taylor",
        help="the Gauss-point law: dem (Guo & Zhao's 400-disk DEM RVE in YADE's arithmetic; the full benchmark "
        "needs the fast engine), dem-lammps (the same disks and cell with LAMMPS' gran/hooke/history law in LAMMPS' "
        "arithmetic: a Gauss point's history replays in LAMMPS; no disk rotation), or the stand-ins taylor (the "
        "affine Taylor RVE of Meier et al., consolidated to the confining pressure; default) and j2 (von Mises "
        "plasticity with a weaker centre element)",
    )
    p.add_argument(
        "--tangent",
        choices=["contact", "perturbation"],
        default=None,
        help="the DEM RVEs' tangent: contact (Guo & Zhao's contact-stiffness tangent, eq. 10; default) or "
        "perturbation (the central difference of 8 RVE calls of +-h from each committed state, computed once a "
        "load step: 1.4-2.3x fewer Newton iterations, 1.8x less DEM CPU on a 1 x 1 specimen over 40 steps, but "
        "no less on the 2 x 4 and 8 x 16 meshes, docs/femxdem.md 'The tangent')",
    )
    p.add_argument(
        "--tangent-step",
        type=number,
        default=None,
        metavar="H",
        help="the perturbation h of --tangent perturbation (default 3e-4: of 1e-4, 3e-4 and 1e-3 the fewest DEM "
        "steps over 40 load steps of a 1 x 1 specimen; 2e-5 to 1e-2)",
    )
    p.add_argument("--full", action="store_true", help="the full benchmark: 8 x 16 elements, 100 steps")
    p.add_argument("--mesh", default=None, help="NXxNY elements (default 2x4; 8x16 with --full)")
    p.add_argument("--steps", type=integer, default=None, help="load steps (default 10; 100 with --full)")
    p.add_argument("--element", choices=["Q8", "Q9"], default="Q8", help="Q8 (default, Guo & Zhao's) or Q9")
    p.add_argument("--gauss", type=integer, default=None, help="Gauss points per direction (default 2; Q9: 3)")
    p.add_argument("--pressure", type=number, default=1.0e5, help="confining pressure (Pa, default 1e5)")
    p.add_argument("--top-step", type=number, default=1.0e-4, help="top platen displacement per step (m, 1e-4)")
    p.add_argument("--tol", type=number, default=1e-2, help="Newton: relative correction tolerance (1e-2)")
    p.add_argument(
        "--max-iter",
        type=integer,
        default=None,
        help="Newton iterations per step before the run stops (default 25; 100 with --full, Guo & Zhao's limit)",
    )
    p.add_argument("--packing", default=None, help="--rve taylor: HDF5 packing of the RVE (default: the most "
                   "uniform standard 700-disk RVE)")  # fmt: skip
    p.add_argument("--packing-dir", default=None, help="--rve taylor without --packing: where the standard "
                   "packings are cached (default results/packings)")  # fmt: skip
    p.add_argument("--out", default=None, help="output directory (default results/femxdem-<rve>)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run from OUT/checkpoint/")
    p.add_argument("--stop-after", type=integer, default=None, metavar="K", help="stop after step K (tests)")
    p.add_argument("--field-steps", default=None, metavar="K,K,...",
                   help="load steps whose maps (deviatoric strain, void ratio, rotation), VTU and RVE pictures are "
                   "written (default: the last)")  # fmt: skip
    p.add_argument("--rve-pictures", default=None, metavar="G,G,...",
                   help="--rve dem, dem-lammps: Gauss points whose RVE is drawn at the field steps (disks coloured by "
                   "rotation, which dem-lammps does not define; force chains; default: the most strained point of "
                   "each field step)")  # fmt: skip
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


def _int_list(text: str, option: str, low: int, high: int) -> tuple:
    """Comma-separated integers in [low, high], each once (exit 2 naming ``option``)."""
    try:
        vals = tuple(int(v) for v in text.split(","))
    except ValueError:
        raise InputError(f"{option}: expected comma-separated integers (e.g. 1,5,10), got {text!r}") from None
    bad = [v for v in vals if not low <= v <= high]
    if bad:
        raise InputError(f"{option}: expected integers from {low} to {high}, got {bad[0]}")
    if len(set(vals)) != len(vals):
        raise InputError(f"{option}: {text!r} names a value twice")
    return tuple(sorted(vals))


def field_outputs(field_steps, pictures) -> list:
    """The files a run writes per field step (besides :data:`OUTPUTS`); ``pictures`` None: one
    picture per step, of a point known only then (not listed)."""
    names = []
    for k in field_steps:
        names += [f"maps_{k:03d}.png", f"mesh_{k:03d}.vtu"]
        names += [f"rve_{k:03d}_g{g:05d}.png" for g in pictures or ()]
    return names


def _spare_workers(executor) -> None:
    """Let the LocalCluster's worker processes ignore SIGINT and SIGHUP.

    Ctrl-C and a terminal's hang-up reach the whole foreground process group, workers included:
    a worker killed by it loses its Gauss points' states while the driver finishes the step in
    progress, and the driver then waited 30 s per lost connection before an internal error
    (measured: exit 1 instead of 130). The driver alone acts on the signal (the step finishes, its
    checkpoint is written, the cluster is closed: its nannies stop the workers with SIGTERM). The
    handler is set in each worker's main thread (``Client.run`` runs there); an existing cluster
    (``--scheduler``) is not ours to change."""
    if getattr(executor, "cluster", None) is None:
        return
    executor.client.run(_ignore_terminal_signals)


def _ignore_terminal_signals() -> None:
    for name in ("SIGINT", "SIGHUP"):
        signal.signal(getattr(signal, name), signal.SIG_IGN)


def check_options(args) -> dict:
    """Every option, checked once before any computation (exit 2 naming the option); returns the
    values the run needs (``spec`` keywords, ``out``, ``packing`` (the --packing read, or None),
    ``packing_dir``, ``resumed``: the last step of the checkpoint continued, 0 for a new run)."""
    check_given_values(args)
    if args.rve not in STANDINS:
        raise InputError(f"--rve: expected one of {', '.join(STANDINS)}, got {args.rve!r}")
    if args.full and args.mesh is not None and args.steps is not None:
        raise InputError("--full: sets the mesh and the steps, both given here (--mesh, --steps); drop one")
    base = FULL if args.full else QUICK
    nx, ny = _mesh(args.mesh) if args.mesh is not None else base["mesh"]
    steps = base["steps"] if args.steps is None else check_count(args.steps, "--steps", 1, MAX_STEPS)
    gauss = args.gauss if args.gauss is not None else (3 if args.element == "Q9" else 2)
    check_count(gauss, "--gauss", 2, 5)
    if args.element == "Q9" and gauss < 3:
        raise InputError(
            f"--gauss: --element Q9 needs --gauss 3 or more, got {gauss}: with 2 x 2 points Q9 has hourglass "
            "modes (a singular stiffness)"
        )
    # the Taylor stand-in is consolidated to a mean stress of -p: at p = 0 its frictionless disks
    # just touch, and no stretch is singled out (gransim.fem.femxdem.standin_law)
    check_number(args.pressure, "--pressure", low=0, high=MAX_PRESSURE, low_open=args.rve == "taylor")
    if args.rve in DEM_RVES and args.pressure != 1e5:
        raise InputError(
            f"--pressure: --rve {args.rve}'s RVE was consolidated to 1e5 Pa (prepareRVE.py), got {args.pressure:g}"
        )
    if args.tangent is not None and args.rve not in DEM_RVES:
        raise InputError(
            f"--tangent: applies to the DEM RVEs (--rve {', '.join(DEM_RVES)}); the stand-in {args.rve} has its "
            "exact tangent"
        )
    if args.tangent_step is not None:
        if args.tangent != "perturbation":
            raise InputError("--tangent-step: applies to --tangent perturbation only")
        from ..fem.perturbation import MAX_STEP, MIN_STEP  # noqa: PLC0415 - start-up: numpy

        check_number(args.tangent_step, "--tangent-step", low=MIN_STEP, high=MAX_STEP)
    check_number(args.top_step, "--top-step", low=MIN_TOP_STEP, high=0.05)
    check_number(args.tol, "--tol", low=MIN_TOL, high=1, high_open=True)
    max_iter = base["max_iter"] if args.max_iter is None else check_count(args.max_iter, "--max-iter", 1, 1000)
    from ..fem.biaxial import BiaxialSpec  # noqa: PLC0415 - start-up: numpy

    height = BiaxialSpec.height
    if steps * args.top_step >= height:
        raise InputError(
            f"--steps {steps} x --top-step {args.top_step:g} m = {steps * args.top_step:g} m: the top platen would "
            f"reach the bottom of the {height:g} m specimen; give fewer steps or a smaller --top-step"
        )
    check_count(args.stop_after, "--stop-after", 1, steps)
    field_steps = (steps,) if args.field_steps is None else _int_list(args.field_steps, "--field-steps", 1, steps)
    pictures = None
    if args.rve_pictures is not None:
        if args.rve not in DEM_RVES:
            raise InputError(
                f"--rve-pictures: applies to the DEM RVEs (--rve {', '.join(DEM_RVES)}); the stand-in {args.rve} "
                "has no grains"
            )
        pictures = _int_list(args.rve_pictures, "--rve-pictures", 0, nx * ny * gauss**2 - 1)
    check_executor_options(args.workers, args.scheduler)
    if args.packing is not None:
        if args.rve != "taylor":
            raise InputError(f"--packing: applies to --rve taylor only, not --rve {args.rve}")
        check_input(args.packing, "--packing")
    if args.packing_dir is not None and (args.rve != "taylor" or args.packing is not None):
        why = "--packing gives the RVE" if args.rve == "taylor" else f"--rve {args.rve} reads no packing"
        raise InputError(f"--packing-dir: would be ignored ({why})")
    packing_dir = args.packing_dir if args.packing_dir is not None else "results/packings"
    check_output_dir(packing_dir, "--packing-dir")
    out = check_output_dir(args.out if args.out is not None else f"results/femxdem-{args.rve}", "--out")
    check_output_dir(out / "checkpoint", "--out")  # a file of that name would stop the run at step 1
    outputs = [
        ("--out", check_output(out / name, "--out")) for name in OUTPUTS + tuple(field_outputs(field_steps, pictures))
    ]
    check_distinct(outputs, [("--packing", args.packing)])
    ck = out / "checkpoint"
    if args.packing is not None and (
        same_file(Path(args.packing).resolve().parent, ck)
        or any(same_file(args.packing, f) for f in (*ck.glob("step_*.h5"), *ck.glob("states_*.h5")))
    ):
        raise InputError(
            f"--packing: {args.packing!r} is in the checkpoint folder of --out, whose files a run replaces; "
            "move the packing elsewhere"
        )
    packing = None
    if args.packing is not None:  # read here, so that a file that is no packing is refused naming the option
        from ..io import load_packing  # noqa: PLC0415 - start-up: h5py

        try:
            packing = load_packing(args.packing)
        except GransimError as exc:
            raise InputError(f"--packing: {exc}") from None
    spec = {
        "nx": nx, "ny": ny, "element": args.element, "gauss": gauss, "pressure": args.pressure,
        "top_step": args.top_step, "steps": steps, "tol": args.tol, "max_iter": max_iter,
    }  # fmt: skip
    resumed = 0
    if args.resume:
        from ..fem.femxdem import check_resumable  # noqa: PLC0415 - start-up: h5py

        resumed = check_resumable(
            out, BiaxialSpec(**spec), args.rve, SPEC_OPTIONS, tangent=args.tangent, tangent_step=args.tangent_step
        )
        if args.stop_after is not None and args.stop_after <= resumed:
            raise InputError(
                f"--stop-after: the checkpoint in {out / 'checkpoint'} is already at step {resumed}; "
                f"give a later step (up to {steps}) or leave --stop-after out"
            )
    return {
        "spec": spec, "out": out, "packing": packing, "packing_dir": packing_dir, "resumed": resumed,
        "field_steps": field_steps, "rve_pictures": pictures,
    }  # fmt: skip


def handler(args) -> int:
    opts = check_options(args)
    from .._numba import wait_passively  # noqa: PLC0415 - start-up: numba
    from ..fem.biaxial import BiaxialSpec  # noqa: PLC0415 - start-up: scipy
    from ..fem.femxdem import FemxdemInterrupted, run_femxdem  # noqa: PLC0415 - start-up: scipy
    from ..fem.incremental import StepFailure  # noqa: PLC0415 - start-up: scipy

    spec = BiaxialSpec(**opts["spec"])
    wait_passively()  # before any parallel kernel starts the OpenMP runtime, and before the workers start
    with make_executor(args.workers, args.scheduler) as executor:
        _spare_workers(executor)
        try:
            summary = run_femxdem(
                spec, args.rve, opts["out"], executor, resume=args.resume, stop_after=args.stop_after,
                packing=opts["packing"], packing_dir=opts["packing_dir"], field_steps=opts["field_steps"],
                rve_pictures=opts["rve_pictures"], tangent=args.tangent, tangent_step=args.tangent_step,
            )  # fmt: skip
        except FemxdemInterrupted as exc:
            print(str(exc), file=sys.stderr)
            return 0
        except StepFailure as exc:  # a failing computation (README: exit 1); the converged steps are written
            print(f"gransim femxdem: error: {exc}", file=sys.stderr)
            return 1
    print(summary["report"])
    return 0
