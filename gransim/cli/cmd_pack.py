"""``gransim pack``: one periodic packing from a grain size distribution, written to HDF5."""

from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser("pack", help="generate a dense periodic disk packing (HDF5)",
                       description="Generate a dense, isotropic, periodic packing of N disks from a grain size "
                                   "distribution by pressure-controlled FIRE minimisation, and write it to HDF5. "
                                   "Target: a mean contact overlap (default 2.7e-4 of the mean diameter) or a "
                                   "solid fraction.")
    p.add_argument("--distribution", default="quartz-sand",
                   help="quartz-sand, kuhn-1002, or a CSV sieve curve in mm (default: quartz-sand)")
    p.add_argument("--n", type=int, required=True, help="number of disks (>= 2)")
    p.add_argument("--seed", type=int, default=1, help="random seed (default 1)")
    p.add_argument("-o", "--output", required=True, help="output HDF5 file")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--solid-fraction", type=float, help="target packing fraction (at or above jamming)")
    g.add_argument("--mean-overlap", type=float,
                   help="target mean overlap relative to the mean diameter (default 2.7e-4)")
    p.add_argument("--mean-diameter", type=float, help="scale the distribution to this mean diameter (m)")
    p.add_argument("--density", type=float, default=2650.0, help="mass per area, kg/m^2 (default 2650)")
    p.add_argument("--vtu", help="also export the packing to this VTK (.vtu) file")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from ..generation import make_packing, packing_stats
    from ..io import packing_to_vtu, save_packing
    from .cmd_info import format_stats

    packing = make_packing(args.distribution, args.n, args.seed, solid_fraction=args.solid_fraction,
                           mean_overlap=args.mean_overlap, mean_diameter=args.mean_diameter,
                           density=args.density)
    save_packing(args.output, packing)
    if args.vtu:
        packing_to_vtu(args.vtu, packing)
    m = packing.metadata
    print(f"wrote {args.output} ({m['fire_steps']} FIRE steps, {m['seconds']:.2f} s)")
    print(format_stats(packing_stats(packing)))
    return 0
