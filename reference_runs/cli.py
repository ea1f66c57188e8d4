"""The command-line sub-commands of reference_runs, registered with ``gransim`` as plug-ins.

``gransim reference`` (list, run CASE, taylor: LIGGGHTS or LAMMPS reference runs) and ``gransim
replay DECK`` (a user's LIGGGHTS or LAMMPS 2D disk deck run in its code and natively, compared step
by step: :mod:`reference_runs.replay`, docs/replay.md).

gransim never imports this package: ``pyproject.toml`` names :func:`register_reference` and
:func:`register_replay` in the entry-point group ``gransim.commands`` and :mod:`gransim.cli`
discovers them (:func:`gransim.cli.build_parser`). Module level imports only the standard library
and :mod:`gransim.paper` (``gransim --help`` stays fast); the work is imported in the handlers.
"""

from __future__ import annotations

import sys

from gransim.paper import KN_2D

DEFAULT_OUT = "results/reference"


def register_reference(subparsers) -> None:
    p = subparsers.add_parser(
        "reference",
        help="LIGGGHTS or LAMMPS reference runs (needs the binary)",
        description="Run reference jobs of LIGGGHTS-PUBLIC 3.8.0 (`liggghts`) or LAMMPS (`lmp`) and parse them.",
    )
    sub = p.add_subparsers(dest="reference_command", metavar="ACTION")
    sub.required = True

    pl = sub.add_parser("list", help="list the named reference cases")
    pl.set_defaults(func=_list)

    pr = sub.add_parser("run", help="run a named reference case")
    pr.add_argument("case", help="case name (see `gransim reference list`)")
    pr.add_argument("--out", default=None, help=f"output directory (default {DEFAULT_OUT}/CASE)")
    _job_options(pr)
    pr.set_defaults(func=_run)

    pt = sub.add_parser(
        "taylor",
        help="Taylor RVE states of packings along the study paths, vs numpy",
        description="Run the Taylor (affine) states of each packing along compression "
        "11/22 (F11, F22 from 1 to 1 - max-strain) and simple shear 12/21 "
        "(F12, F21 from 0 to max-strain) through LIGGGHTS, one job per "
        "packing, and compare the stresses with an independent numpy Taylor "
        "stress. Jobs already complete are skipped.",
    )
    pt.add_argument("packings", nargs="*", help="HDF5 files holding a /packing group (gransim save_packing)")
    pt.add_argument(
        "--rves",
        default=None,
        metavar="DIR",
        help="directory of RVE packing files (*.h5), e.g. the 15 RVEs of the study",
    )
    pt.add_argument("--demo", action="store_true", help="use 3 built-in 64-disk packings")
    pt.add_argument(
        "--standard",
        action="store_true",
        help="use the 15 study RVEs (rve-<N>-<seed> in --packings-dir, generated if missing)",
    )
    pt.add_argument("--packings-dir", default="results/packings", help="where the standard RVEs live")
    pt.add_argument(
        "--kn",
        type=float,
        default=None,
        help=f"2D normal contact stiffness kn = E_n * thickness, N/m (default {KN_2D:g}, "
        "gransim.paper.KN_2D: E_n of Meier et al. Table 1)",
    )
    pt.add_argument("--n-steps", type=int, default=50, help="states per path after the reference (50)")
    pt.add_argument("--stride", type=int, default=1, help="run every STRIDE-th state (and the last)")
    pt.add_argument("--max-strain", type=float, default=0.1, help="final |F - I| component (0.1)")
    pt.add_argument("--contacts", action="store_true", help="also dump per-contact forces of every state")
    pt.add_argument("--out", default=f"{DEFAULT_OUT}/taylor", help="output directory")
    _job_options(pt)
    pt.set_defaults(func=_taylor)


def _job_options(p) -> None:
    p.add_argument(
        "--engine",
        choices=("liggghts", "lammps"),
        default="liggghts",
        help="the code that runs the jobs (default liggghts)",
    )
    p.add_argument("--np", type=int, default=1, help="MPI processes (mpirun -np N)")
    p.add_argument("--timeout", type=float, default=3600.0, help="seconds per job")
    p.add_argument(
        "--force",
        action="store_true",
        help="rerun jobs even if complete outputs exist (discards them; needs the code). Without "
        "it a stored job is reused only after its log and outputs are re-hashed and checked "
        "against the deck, and rerun automatically when that fails",
    )


def _list(args) -> int:
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from reference_runs.cases import all_cases

    for name, case in sorted(all_cases().items()):
        print(f"{name:20s} {case.description}")
    return 0


def _run(args) -> int:
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from pathlib import Path

    from reference_runs.cases import get_case
    from reference_runs.runner import kill_children_on_signals

    case = get_case(args.case)
    out = Path(args.out or f"{DEFAULT_OUT}/{case.name}")
    with kill_children_on_signals():  # SIGTERM/SIGINT/SIGHUP: no reference process outlives us
        return case.run(
            out, np_procs=args.np, timeout=args.timeout, force=args.force, progress=True, engine=args.engine
        )


def _taylor(args) -> int:
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from pathlib import Path

    from gransim._validate import as_positive_float
    from gransim.errors import InputError
    from gransim.io import load_packing
    from reference_runs.cases import TAYLOR_RTOL, run_taylor_set

    kn = KN_2D if args.kn is None else as_positive_float(args.kn, "--kn (N/m)")
    files = [Path(p) for p in args.packings]
    if args.rves:
        files += sorted(Path(args.rves).glob("*.h5"))
    packings = {}
    for f in files:
        packings[f.stem] = load_packing(f)
    if args.demo:
        # lazy: this module is imported when `gransim` builds its parser (start-up time)
        from reference_runs.demo_packings import perturbed_lattice

        packings.update({f"lattice-8x8-seed{s}": perturbed_lattice(8, 8, seed=s) for s in (1, 2, 3)})
    if args.standard:
        # lazy: this module is imported when `gransim` builds its parser (start-up time)
        from reference_runs.cases import standard_rves

        packings.update(standard_rves(args.packings_dir))
    if not packings:
        raise InputError("no packings: give packing files, --rves DIR, --standard or --demo")
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from reference_runs.runner import kill_children_on_signals

    with kill_children_on_signals():  # SIGTERM/SIGINT/SIGHUP: no LIGGGHTS process outlives us
        _, worst = run_taylor_set(
            packings,
            args.out,
            kn=kn,
            n_steps=args.n_steps,
            stride=args.stride,
            max_strain=args.max_strain,
            contacts=args.contacts,
            np_procs=args.np,
            timeout=args.timeout,
            force=args.force,
            engine=args.engine,
        )
    ok = worst <= TAYLOR_RTOL
    code = {"liggghts": "LIGGGHTS", "lammps": "LAMMPS"}[args.engine]
    print(
        f"{len(packings)} packings: largest relative difference {code} vs numpy Taylor stress = "
        f"{worst:.3e} ({'PASS' if ok else 'FAIL'}, tolerance {TAYLOR_RTOL:g})"
    )
    return 0 if ok else 1


def register_replay(sub) -> None:
    p = sub.add_parser(
        "replay",
        help="replay a LIGGGHTS/LAMMPS 2D disk deck natively and in its code, and compare",
        description="Read a LIGGGHTS 3.8.0 or LAMMPS deck of 2D periodic disks (the supported subset: "
        "docs/replay.md; anything else is refused naming its line), run it unchanged in its "
        "code and with the native engine, compare thermo (box, compute pressure) and dumps "
        "step by step, and write OUTDIR/report.html, report.md and replay.h5. Exit status 0 "
        "when everything agrees within tolerance (positions 1e-10 D50, stress 1e-8 "
        "relative), 1 when not or when evidence is missing, 2 for bad input.",
    )
    p.add_argument("deck", help="the input deck")
    p.add_argument("--data", default=None, metavar="FILE", help="data file to use instead of the one read_data names")
    p.add_argument(
        "--engine",
        default=None,
        choices=["liggghts", "lammps"],
        help="the deck's code (default: detected from its syntax)",
    )
    p.add_argument(
        "-o", "--out", default=None, metavar="OUTDIR", help="output directory (default results/replay/<deck name>)"
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=None,
        metavar="S",
        help="kill the code's run after S seconds (default: no limit)",
    )
    p.add_argument(
        "--reference",
        default=None,
        metavar="DIR",
        help="a finished job directory of this deck (log.lammps and dumps) to compare with instead of running the code",
    )
    p.set_defaults(func=_replay)


def _replay(args) -> int:
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from pathlib import Path

    from gransim.errors import InputError

    deck = Path(args.deck)
    if not deck.is_file():
        raise InputError(f"DECK: {deck} is not a file")
    if args.data is not None and not Path(args.data).is_file():
        raise InputError(f"--data: {args.data} is not a file")
    if args.timeout is not None and not args.timeout > 0:
        raise InputError(f"--timeout: expected seconds > 0, got {args.timeout!r}")
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from reference_runs.errors import ReferenceRunError
    from reference_runs.replay.compare import replay

    def echo(msg):
        print(f"gransim replay: {msg}", file=sys.stderr, flush=True)

    try:
        res = replay(
            deck,
            data=args.data,
            engine=args.engine,
            outdir=args.out,
            timeout=args.timeout,
            reference=args.reference,
            echo=echo,
        )
    except ReferenceRunError as exc:
        print(f"gransim replay: error: the code's run failed: {exc}", file=sys.stderr)
        return 1
    bad = [c for c in res.checks if not c.passed]
    for c in bad:
        print(f"FAIL {c.quantity}: {c.metric} = {float(c.value):.3g} (tolerance {float(c.tolerance):.3g}) {c.detail}")
    print(
        f"{'PASS' if res.passed else 'FAIL'}: {len(res.checks) - len(bad)} of {len(res.checks)} checks "
        "agree; "
        f"report {res.outdir / 'report.html'}"
    )
    return 0 if res.passed else 1
