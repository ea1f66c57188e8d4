"""``gransim pack``: one periodic packing from a grain size distribution, written to HDF5."""

from __future__ import annotations

import os
import sys

from ..errors import InputError
from ..progress import deferred_interrupts, result_written
from ._paths import check_distinct, check_given_values, check_number, check_output, integer
from .cmd_info import format_stats


def register(sub) -> None:
    p = sub.add_parser(
        "pack",
        help="generate a dense periodic disk packing (HDF5)",
        description="Generate a dense, isotropic, periodic packing of N disks from a grain size "
        "distribution by pressure-controlled FIRE minimisation, and write it to HDF5. "
        "Target: a mean contact overlap (default 2.7e-4 of the mean diameter) or a "
        "solid fraction.",
    )
    p.add_argument(
        "--distribution",
        default="quartz-sand",
        help="quartz-sand, kuhn-1002, or a CSV sieve curve in mm (default: quartz-sand)",
    )
    p.add_argument("--n", type=integer, required=True, help="number of disks (>= 2; 1e5 is accepted)")
    p.add_argument("--seed", type=integer, default=1, help="random seed (>= 0, default 1)")
    p.add_argument("-o", "--output", required=True, help="output HDF5 file")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--solid-fraction", type=float, help="target packing fraction (at or above jamming)")
    g.add_argument(
        "--mean-overlap", type=float, help="target mean overlap relative to the mean diameter (default 2.7e-4)"
    )
    p.add_argument(
        "--force-tol", type=float, help="FIRE stop criterion: residual force / mean contact force (default 1e-3)"
    )
    p.add_argument(
        "--residual",
        choices=("max", "rms"),
        help="norm of the residual: the largest net force on a disk (default) or the root mean "
        "square over all disks (the same demand at every N: use it for 1e5 disks and more)",
    )
    p.add_argument(
        "--method",
        choices=("random", "front"),
        help="start of the FIRE protocol: uniform random centres (default; the standard "
        "RVEs) or an advancing front of touching disks (a dense contact-free start)",
    )
    p.add_argument(
        "--cell",
        choices=("scale", "shape"),
        help="cell degrees of freedom of the FIRE protocol: the side of a square cell (default; the "
        "standard RVEs) or the whole cell shape (a shear-stress-free packing in a sheared cell, "
        "stable to shear; default --force-tol 1e-5)",
    )
    p.add_argument(
        "--friction",
        type=float,
        help="make the packing by isotropic frictional DEM compaction of a granular gas with this "
        "preparation friction coefficient instead of FIRE (looser assemblies: the Kuhn assembly "
        "uses 0.05); excludes --solid-fraction and --mean-overlap",
    )
    p.add_argument(
        "--pressure",
        type=float,
        help="with --friction: compaction stress relative to the contact stiffness (default 1e-4)",
    )
    p.add_argument("--mean-diameter", type=float, help="scale the distribution to this mean diameter (m)")
    p.add_argument("--density", type=float, default=2650.0, help="mass per area, kg/m^2 (default 2650)")
    p.add_argument("--vtu", help="also export the packing to this VTK (.vtu) file")
    p.set_defaults(func=_run)


def _check(args) -> None:
    """Every option checked before the packing starts (names in the messages are the options)."""
    # imports here, not at the top: `gransim --help` must not load numba and h5py (start-up time)
    from ..generation import get_distribution  # noqa: PLC0415 - start-up: numba
    from ..generation.pack import (  # noqa: PLC0415 - start-up: numba
        MAX_MEAN_OVERLAP,
        MAX_SOLID_FRACTION,
        MEMORY_WARN_FRACTION,
        check_packing_memory,
    )

    check_given_values(args)
    try:
        get_distribution(args.distribution)  # unknown name, missing or malformed CSV
    except InputError as exc:
        raise InputError(f"--distribution: {exc}") from None
    check_number(args.n, "--n", low=2, integer=True)
    check_number(args.seed, "--seed", low=0, high=2**63 - 1, integer=True)
    check_output(args.output, "-o/--output")
    if args.vtu is not None:
        check_output(args.vtu, "--vtu", (".vtu",))
    # a --distribution CSV sieve curve is an input file (a name like quartz-sand is not a file)
    curve = args.distribution if os.path.isfile(args.distribution) else None
    check_distinct((("-o/--output", args.output), ("--vtu", args.vtu)), (("--distribution", curve),))
    check_number(args.solid_fraction, "--solid-fraction", low=0, high=MAX_SOLID_FRACTION, low_open=True, high_open=True)
    check_number(args.mean_overlap, "--mean-overlap", low=0, high=MAX_MEAN_OVERLAP, low_open=True)
    check_number(args.force_tol, "--force-tol", low=0, low_open=True)
    check_number(args.friction, "--friction", low=0)
    check_number(args.pressure, "--pressure", low=0, high=1, low_open=True, high_open=True)
    check_number(args.mean_diameter, "--mean-diameter", low=0, low_open=True)
    check_number(args.density, "--density", low=0, low_open=True)
    # one figure for both protocols: measured peak RSS per disk of make_packing 850-1130 B
    # (generation/pack.py), of compact_packing (--friction 0.05, same method) 720 B at N = 3000 and
    # 768 B at N = 1e4, both below PACKING_BYTES_PER_DISK = 2500 B
    frac = check_packing_memory(args.n, "--n")
    if frac > MEMORY_WARN_FRACTION:
        print(
            f"gransim pack: warning: --n {args.n} needs about {100 * frac:.0f}% of the available memory",
            file=sys.stderr,
        )


def _run(args) -> int:
    from ..generation import compact_packing, make_packing, packing_stats  # noqa: PLC0415 - start-up: numba
    from ..io import packing_to_vtu, save_packing  # noqa: PLC0415 - start-up: h5py

    _check(args)
    if args.friction is not None:
        if args.solid_fraction is not None or args.mean_overlap is not None:
            raise InputError(
                "--friction (DEM compaction) takes no --solid-fraction or --mean-overlap target: "
                "the friction sets the density and --pressure the overlaps"
            )
        if args.force_tol is not None or args.residual is not None or args.method is not None or args.cell is not None:
            raise InputError(
                "--force-tol, --residual, --method and --cell belong to the FIRE protocol, not to "
                "--friction (the compaction stops at an unbalanced force ratio of 1e-3)"
            )
        kw = {} if args.pressure is None else {"pressure": args.pressure}
        packing = compact_packing(
            args.distribution,
            args.n,
            args.seed,
            args.friction,
            mean_diameter=args.mean_diameter,
            density=args.density,
            **kw,
        )
        how = f"{packing.metadata['dem_steps']} DEM steps"
    else:
        if args.pressure is not None:
            raise InputError("--pressure needs --friction (it is the stress of the DEM compaction)")
        kw = {
            k: v
            for k, v in (
                ("force_tol", args.force_tol),
                ("residual", args.residual),
                ("method", args.method),
                ("cell", args.cell),
            )
            if v is not None
        }
        packing = make_packing(
            args.distribution,
            args.n,
            args.seed,
            solid_fraction=args.solid_fraction,
            mean_overlap=args.mean_overlap,
            mean_diameter=args.mean_diameter,
            density=args.density,
            **kw,
        )
        how = f"{packing.metadata['fire_steps']} FIRE steps"
    with deferred_interrupts():  # a signal during the write abandons it; after it, the packing is whole
        save_packing(args.output, packing)
        result_written(args.output)
    if args.vtu:
        packing_to_vtu(args.vtu, packing)
    m = packing.metadata
    print(f"wrote {args.output} ({how}, {m['seconds']:.2f} s)")
    print(format_stats(packing_stats(packing)))
    return 0
