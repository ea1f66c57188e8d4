"""``gransim packings``: the 15 RVEs of Meier et al. and Kuhn's 1002-disk assembly, with a statistics table."""

from __future__ import annotations

from ..errors import InputError
from ._paths import check_given_values, check_output_dir, same_file


def register(sub) -> None:
    p = sub.add_parser(
        "packings",
        help="generate the 15 standard RVEs and the Kuhn assembly",
        description="Generate (or reuse, when up to date) the standard assemblies: 5 RVEs each of "
        "70, 350 and 700 disks of quartz-sand (rve-<N>-<seed>) and the 1002-disk "
        "Kuhn assembly (kuhn-1002), then print their statistics.",
    )
    p.add_argument("--out", default="results/packings", help="output directory (default results/packings)")
    p.add_argument("--only", action="append", metavar="NAME", help="only this packing (repeatable)")
    p.add_argument("--force", action="store_true", help="regenerate even when the files are up to date")
    p.set_defaults(func=_run)


def _run(args) -> int:
    # imports here, not at the top: `gransim --help` must not load numba and h5py (start-up time)
    from ..generation import STANDARD_PACKINGS, packing_stats, standard_packings  # noqa: PLC0415 - start-up: numba
    from ..generation.standard import SHIPPED_DIR  # noqa: PLC0415 - start-up: numba
    from ..io import load_packing  # noqa: PLC0415 - start-up: h5py

    check_given_values(args)
    unknown = [n for n in args.only or () if n not in STANDARD_PACKINGS]
    if unknown:
        raise InputError(
            f"--only: unknown standard packing {unknown[0]!r}; choose from: {', '.join(STANDARD_PACKINGS)}"
        )
    check_output_dir(args.out, "--out")
    if same_file(args.out, SHIPPED_DIR):
        raise InputError(
            f"--out: {args.out!r} is gransim's shipped copy of the standard packings (the source "
            "of every other --out); choose another directory"
        )
    paths = standard_packings(args.out, names=args.only, force=args.force)
    head = (
        f"{'name':<11} {'N':>5} {'phi':>7} {'e':>7} {'Z':>6} {'Z_nr':>6} {'ratt%':>6} "
        f"{'<eps>/D50':>10} {'max/D50':>9} {'a_fab':>6}  file"
    )
    print(head)
    print("-" * len(head))
    for name, path in paths.items():
        s = packing_stats(load_packing(path))
        print(
            f"{name:<11} {s['n']:>5} {s['solid_fraction']:>7.4f} {s['void_ratio']:>7.4f} "
            f"{s['coordination']:>6.3f} {s['coordination_nonrattler']:>6.3f} {100 * s['rattler_fraction']:>6.1f} "
            f"{s['mean_overlap_d50']:>10.2e} {s['max_overlap_d50']:>9.2e} {s['fabric_anisotropy']:>6.3f}  {path}"
        )
    return 0
