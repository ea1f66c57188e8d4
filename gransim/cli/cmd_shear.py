"""``gransim shear``: true periodic simple shear of a packing in a sheared (triclinic) cell with the
native DEM engine in LAMMPS' arithmetic (``gransim.dem.sheared``, docs/shear.md)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from ..errors import InputError
from ..progress import result_written
from ._engine_options import add_engine_options
from ._paths import check_count, check_distinct, check_figure, check_given_values, check_input, check_output
from .cmd_biaxial import parse_law_params

#: default inertial number when neither --rate nor --inertial-number is given
DEFAULT_INERTIAL_NUMBER = 1e-3


def register(sub) -> None:
    p = sub.add_parser(
        "shear",
        help="DEM simple shear of a packing in a sheared periodic cell (LAMMPS remap v)",
        description="Shear the packing (as it is: no consolidation first) by a tilt xy growing at a "
        "constant engineering rate (LAMMPS `fix deform 1 xy erate R remap v`, Lees-Edwards "
        "images), at constant volume or under a normal-stress servo on y. Writes a "
        "shear-run HDF5 file (docs/shear.md): the per-step series, snapshots, provenance; "
        "stresses tension positive.",
    )
    p.add_argument("--packing", required=True, help="packing HDF5 file (gransim pack / save_packing)")
    p.add_argument(
        "--strain",
        type=float,
        required=True,
        help="shear strain to reach, gamma = (xy - xy0)/Ly0 (> 0, the tilt must stay within Lx/2)",
    )
    rate = p.add_mutually_exclusive_group()
    rate.add_argument("--rate", type=float, help="engineering shear rate d gamma/dt, 1/s")
    rate.add_argument(
        "--inertial-number",
        type=float,
        help=f"inertial number I = rate D50 sqrt(rho/p) giving the rate (default "
        f"{DEFAULT_INERTIAL_NUMBER:g}; p = --servo, or the mean pressure of the packing "
        "at constant volume)",
    )
    y = p.add_mutually_exclusive_group()
    y.add_argument("--constant-volume", action="store_true", help="y fixed (the default)")
    y.add_argument(
        "--servo",
        type=float,
        metavar="P",
        help="hold the normal stress sigma_yy at P (N/m, compression, > 0) by moving y",
    )
    p.add_argument(
        "--flavour",
        default="lammps",
        help="whose arithmetic the engine follows: lammps (LAMMPS 29 Sep 2021, the only one "
        "with a sheared periodic cell; LIGGGHTS 3.8.0's triclinic box loses its ghosts)",
    )
    p.add_argument(
        "--kn", type=float, help="normal = tangential stiffness, N/m (default 1e5; a Hertz --law sets its own)"
    )
    p.add_argument("--damping-ratio", type=float, default=0.3, help="contact damping ratio (default 0.3)")
    p.add_argument("--steps-per-contact", type=float, default=50.0, help="contact time / dt (default 50)")
    p.add_argument("--series-every", type=int, default=10, help="series row every N steps (default 10)")
    p.add_argument(
        "--snapshot-every", type=int, default=0, help="snapshot every N steps (default 0: the first and the last only)"
    )
    p.add_argument(
        "--law",
        metavar="NAME",
        help="contact law by name, one in LAMMPS' arithmetic (hooke-lammps, hertz-lammps, "
        "hertz-granular-lammps, hooke-sds-lammps; docs/laws.md); default: the Hooke law of "
        "--kn/--damping-ratio. Recorded in the run file's settings JSON (law)",
    )
    p.add_argument(
        "--law-param",
        metavar="KEY=VALUE",
        action="append",
        default=[],
        help="a parameter of --law (repeat; SI units, as gransim biaxial --law-param)",
    )
    add_engine_options(p, "--order fast; the code order's sheared cell runs on one")
    p.add_argument("-o", "--output", required=True, help="run file (.h5)")
    p.add_argument("--plot", help="also write the shear stress and normal stress against the strain")
    p.set_defaults(func=_run)


def _check_options(args) -> None:
    """Every option and path, named as on the command line, before any work."""
    from .._validate import as_positive_float  # noqa: PLC0415 - start-up: numpy

    check_given_values(args)
    check_input(args.packing, "--packing")
    check_output(args.output, "-o/--output", (".h5", ".hdf5"))
    if args.plot:
        check_figure(args.plot, "--plot")
    check_distinct((("-o/--output", args.output), ("--plot", args.plot)), (("--packing", args.packing),))
    for name, v in (
        ("--strain", args.strain),
        ("--rate", args.rate),
        ("--inertial-number", args.inertial_number),
        ("--servo", args.servo),
        ("--kn", args.kn),
        ("--steps-per-contact", args.steps_per_contact),
    ):
        if v is not None:
            as_positive_float(v, name)
    as_positive_float(args.damping_ratio, "--damping-ratio", allow_zero=True)
    check_count(args.series_every, "--series-every", 1)
    check_count(args.snapshot_every, "--snapshot-every", 0)
    check_count(args.checkpoint_every, "--checkpoint-every", 0)
    check_count(args.threads, "--threads", 1)
    if args.threads is not None and args.order != "fast":
        raise InputError(
            f"--threads {args.threads}: the sheared cell in the code's order runs on one thread; give --order fast "
            "to run on threads, or drop --threads"
        )
    if args.threads is not None:
        from .._numba import check_threads  # noqa: PLC0415 - start-up: numba

        check_threads(args.threads, "--threads")
    if args.resume and not Path(args.output).exists():
        raise InputError(
            f"--resume: {args.output!r} (-o/--output) does not exist: no run to continue; drop --resume to start one"
        )
    if args.flavour != "lammps":
        from ..dem.settings import FLAVOURS  # noqa: PLC0415 - start-up: numba

        if args.flavour in FLAVOURS:
            raise InputError(
                f"--flavour {args.flavour}: the sheared periodic cell runs in LAMMPS' arithmetic "
                "only (LIGGGHTS 3.8.0's triclinic box loses the periodic ghosts); use --flavour "
                "lammps"
            )
        raise InputError(f"--flavour: expected lammps, got {args.flavour!r}")
    if args.law_param and not args.law:
        raise InputError("--law-param: given without --law (name the law the parameters belong to)")
    if args.law:
        from ..contacts.laws import law_code  # noqa: PLC0415 - start-up: numba

        try:
            code = law_code(args.law)
        except InputError as e:
            raise InputError(f"--law: {e}") from None
        if code != "lammps":
            raise InputError(
                f"--law {args.law}: a law in {code.upper()}' arithmetic; the sheared cell runs "
                "LAMMPS' (use a *-lammps law)"
            )
        if args.kn is not None and args.law.startswith("hertz"):
            raise InputError(
                f"--kn: not used with the Hertz law {args.law} (its stiffness scale comes from "
                "its --law-param material constants)"
            )
        parse_law_params(args.law_param)


def _run(args) -> int:
    import numpy as np  # noqa: PLC0415 - start-up: numpy

    from ..dem.biaxial import default_settings, inertial_number  # noqa: PLC0415 - start-up: numba
    from ..dem.sheared import ShearEngine, ShearLoading, run_shear_file  # noqa: PLC0415 - start-up: numba
    from ..io import load_packing  # noqa: PLC0415 - start-up: h5py

    _check_options(args)
    packing = load_packing(args.packing)
    C = np.asarray(packing.cell, float)
    if C[1, 0] != 0.0:
        raise InputError(
            f"--packing: {args.packing}: the cell must have a1 = (Lx, 0) (cell[1, 0] = 0), got cell[1, 0] = {C[1, 0]!r}"
        )
    law = law_options = None
    if args.law:
        from ..dem.biaxial import law_settings  # noqa: PLC0415 - start-up: numba

        opts = {"damping_ratio": args.damping_ratio, "steps_per_contact": args.steps_per_contact}
        if args.kn is not None:
            opts["kn"] = args.kn
        try:
            law, dem, _, law_options = law_settings(packing, args.law, parse_law_params(args.law_param), **opts)
        except InputError as e:
            raise InputError(f"--law-param: {e}") from None
    else:
        dem, _ = default_settings(
            packing,
            kn=1e5 if args.kn is None else args.kn,
            damping_ratio=args.damping_ratio,
            steps_per_contact=args.steps_per_contact,
            flavour="lammps",
        )
    lx, ly, xy0 = float(C[0, 0]), float(C[1, 1]), float(C[0, 1])
    if xy0 + args.strain * ly > 0.5 * lx:
        raise InputError(
            f"--strain {args.strain:g}: the tilt would reach {xy0 + args.strain * ly:.4g} m, beyond "
            f"Lx/2 = {0.5 * lx:.4g} m, where LAMMPS flips the box (the engine does not); "
            f"at most {(0.5 * lx - xy0) / ly:.4g} for this cell"
        )
    try:
        # the checks of the cell and dt, and the packing's pressure
        probe = ShearEngine(packing, dem, law=law)
    except InputError as exc:
        raise InputError(f"--packing: {args.packing}: {exc}") from None
    p_mean = float(0.5 * (probe.stress[0, 0] + probe.stress[1, 1]))  # compression positive
    p_ref = args.servo if args.servo is not None else p_mean
    if args.rate is not None:
        rate = args.rate
    else:
        inum = args.inertial_number if args.inertial_number is not None else DEFAULT_INERTIAL_NUMBER
        if not p_ref > 0:
            raise InputError(
                f"--inertial-number: the packing has no compressive pressure at constant volume "
                f"(mean stress {p_mean:.4g} N/m, compression positive), so I gives no rate: "
                "give --rate or --servo P"
            )
        rate = inum / (packing.d50 * np.sqrt(packing.density / p_ref))
    nsteps = int(np.ceil(args.strain / (rate * dem.dt) - 1e-9))
    if nsteps < 1:
        raise InputError(f"--strain {args.strain:g} at rate {rate:.4g} 1/s is less than one step of {dem.dt:.4g} s")
    if args.servo is not None:
        loading = ShearLoading(erate=rate, y="servo", target=args.servo, gain=0.01 / (dem.kn * dem.dt))
    else:
        loading = ShearLoading(erate=rate)
    # the end tilt is that of nsteps steps: strain = nsteps dt rate (>= --strain by < one step)
    extra = {
        "cli": {
            "strain": args.strain,
            "rate": rate,
            "inertial_number": args.inertial_number,
            "servo": args.servo,
            "packing": str(args.packing),
        },
        "inertial_number": inertial_number(packing, rate, p_ref) if p_ref > 0 else None,
    }
    summary = run_shear_file(
        packing,
        dataclasses.replace(dem),
        loading,
        nsteps,
        args.output,
        series_every=args.series_every,
        snapshot_every=args.snapshot_every,
        parameters=extra,
        law=law,
        law_options=law_options,
        checkpoint_every=args.checkpoint_every,
        resume=args.resume,
        order=args.order,
        threads=args.threads,
    )
    result_written(args.output)
    y = f"servo sigma_yy = {args.servo:g} N/m" if args.servo is not None else "constant volume"
    print(
        f"wrote {args.output}: {packing.n} disks, {nsteps} steps of {dem.dt:.3g} s, shear rate {rate:.4g} 1/s, "
        f"{y}, LAMMPS arithmetic"
    )
    for k, v in summary.items():
        print(f"  {k:20s} {v:.6g}" if isinstance(v, float) else f"  {k:20s} {v}")
    if args.plot:
        _plot(args.output, args.plot)
        print(f"wrote {args.plot}")
    return 0


def _plot(run_path, out) -> None:
    import h5py  # noqa: PLC0415 - start-up: h5py
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib

    from ..io import atomic_path  # noqa: PLC0415 - start-up: h5py

    out = Path(out)
    with h5py.File(run_path, "r") as f:
        g = f["series"]
        gam, st = g["shear_strain"][()], g["stress"][()]
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(gam, st[:, 0, 1], label=r"$\sigma_{xy}$")
    ax.plot(gam, -st[:, 1, 1], label=r"$-\sigma_{yy}$")
    ax.set_xlabel(r"shear strain $\gamma$")
    ax.set_ylabel("stress (N/m, tension positive)")
    ax.legend()
    fig.tight_layout()
    with atomic_path(out, suffix=out.suffix) as tmp:
        fig.savefig(tmp, dpi=120, format=out.suffix.lstrip(".") or "png")
    plt.close(fig)
