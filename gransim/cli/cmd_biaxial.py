"""``gransim biaxial``: the biaxial compression test of Kuhn, "Deformation measures for granular
materials" (1997), section 4, with the native DEM engine;
``gransim dem-export``: VTK of a snapshot and the stress-strain plot of a DEM run file."""

from __future__ import annotations

import dataclasses
import os

from ..errors import InputError
from ._engine_options import add_engine_options
from ._paths import (
    check_count,
    check_distinct,
    check_figure,
    check_given_values,
    check_input,
    check_number,
    check_output,
)


def register(sub) -> None:
    p = sub.add_parser(
        "biaxial",
        help="DEM biaxial compression test (isotropic consolidation, then constant-rate y "
        "compression at constant sigma_11)",
        description="Bring the packing isotropically to the confining stress (servo on both axes), then "
        "compress in y at a constant rate while a servo holds sigma_11. Defaults are quasi-static "
        "(inertial number 5e-5) and run the 1002-disk assembly in minutes. Writes a dem-run HDF5 "
        "file (docs/schema_dem.md).",
    )
    p.add_argument("--packing", required=True, help="packing HDF5 file (gransim pack / save_packing)")
    p.add_argument("-o", "--output", default="biaxial.h5", help="run file (default biaxial.h5)")
    p.add_argument("--strain", type=float, default=0.005, help="final axial strain |eps_22| (default 0.005)")
    p.add_argument("--kn", type=float, help="normal stiffness, N/m (default 1e5; a Hertz --law sets its own scale)")
    p.add_argument(
        "--kt-ratio", type=float, default=1.0, help="tangential / normal stiffness, kt = KT_RATIO kn (default 1, Kuhn)"
    )
    p.add_argument(
        "--mu", type=float, help="Coulomb friction coefficient (default 0.5, Kuhn; with --law: also the law's mu)"
    )
    p.add_argument(
        "--density",
        type=float,
        help="disk density, kg/m^2 (2D: mass per area, m = density pi r^2; default: the packing file's)",
    )
    p.add_argument(
        "--confining",
        type=float,
        help="sigma_11 = p, N/m (default 2.5e-4 kn: indentation ~2e-4 D50); the default strain "
        "rate follows from this value",
    )
    rate = p.add_mutually_exclusive_group()
    rate.add_argument("--strain-rate", type=float, help="axial strain rate, 1/s (default: from --inertial-number)")
    rate.add_argument(
        "--inertial-number",
        type=float,
        help="I = rate D50 sqrt(density / p) of the compression, with the final --confining "
        "and --density (default 5e-5, quasi-static)",
    )
    p.add_argument("--damping-ratio", type=float, default=0.3, help="contact damping ratio (default 0.3)")
    p.add_argument(
        "--steps-per-contact",
        type=float,
        default=50.0,
        help="contact time / dt (default 50; the stability limit needs >= 5 / (sqrt(1 + zeta^2) - zeta))",
    )
    p.add_argument(
        "--consolidation-tol",
        type=float,
        default=0.01,
        help="relative stress tolerance that ends the consolidation (default 0.01)",
    )
    p.add_argument("--consolidation-steps", type=int, default=200000, help="most consolidation steps")
    p.add_argument(
        "--allow-unsettled",
        action="store_true",
        help="go on with the compression when the consolidation has not settled within "
        "--consolidation-steps (recorded in the file); default: stop with exit 2",
    )
    p.add_argument("--series-every", type=int, default=10, help="stress row every N steps (default 10)")
    p.add_argument("--snapshot-every", type=int, default=10000, help="snapshot every N steps (default 10000)")
    p.add_argument(
        "--mode",
        choices=("serial", "parallel"),
        default="serial",
        help="serial (LIGGGHTS order, the codes' bits) or parallel (the step on numba threads, the "
        "same bits on any thread count, sums in another order: 1.3-1.6x on 2 threads from 1e4 "
        "disks; default serial)",
    )
    add_engine_options(p, "--order fast, or --mode parallel")
    p.add_argument(
        "--flavour",
        help="whose arithmetic the engine reproduces bit for bit: liggghts (LIGGGHTS-PUBLIC "
        "3.8.0, default) or lammps (LAMMPS 29 Sep 2021, docs/lammps.md); recorded in the "
        "run file's provenance (parameters dem.flavour); with --law: the law's code",
    )
    p.add_argument(
        "--law",
        metavar="NAME",
        help="contact law by name (gransim.contacts.laws.law_names(): hooke-liggghts, "
        "hooke-lammps, hertz-liggghts, hertz-lammps, hertz-granular-lammps, "
        "hooke-epsd2-liggghts, ...; docs/laws.md); default: the Hooke law of "
        "--kn/--damping-ratio. Recorded in the run file's settings JSON (law, "
        "law_options)",
    )
    p.add_argument(
        "--law-param",
        metavar="KEY=VALUE",
        action="append",
        default=[],
        help="a parameter of --law (repeat; SI units, e.g. youngs_modulus=7e8, restitution=0.6, "
        "damping=tsuji); kn, kt, gamma_n, gamma_t, mu/friction default to the protocol's",
    )
    p.add_argument("--plot", help="also write the stress-strain plot (Fig. 7b) to this image")
    p.set_defaults(func=_run)

    e = sub.add_parser(
        "dem-export", help="VTK of a DEM snapshot and/or the stress-strain plot of a run file (biaxial or shear)"
    )
    e.add_argument("run", help="DEM run file: dem-run (gransim biaxial) or shear-run (gransim shear)")
    e.add_argument("--step", type=int, help="snapshot step, >= 0 (default: the last)")
    e.add_argument("--vtu", help="write the snapshot to this .vtu file")
    e.add_argument(
        "--plot", help="write the stress-strain plot to this image (shear run: sigma_xy and -sigma_yy against gamma)"
    )
    e.add_argument(
        "--allow-incomplete",
        action="store_true",
        help="read a run file whose run did not finish (complete = False) anyway",
    )
    e.set_defaults(func=_export)


def _check_options(args) -> None:
    """Every numeric option and output path, named as on the command line, before any work."""
    from .._validate import as_positive_float  # noqa: PLC0415 - start-up: numpy

    check_given_values(args)
    check_input(args.packing, "--packing")
    check_output(args.output, "-o/--output")
    if args.plot:
        check_figure(args.plot, "--plot")
    check_distinct((("-o/--output", args.output), ("--plot", args.plot)), (("--packing", args.packing),))
    for name, v in (
        ("--kn (N/m)", args.kn),
        ("--strain", args.strain),
        ("--confining (N/m)", args.confining),
        ("--strain-rate (1/s)", args.strain_rate),
        ("--inertial-number", args.inertial_number),
        ("--density (kg/m^2)", args.density),
        ("--steps-per-contact", args.steps_per_contact),
    ):
        if v is not None:
            as_positive_float(v, name)
    if args.strain >= 0.5:
        raise InputError(f"--strain: expected a small strain < 0.5, got {args.strain!r}")
    # |sigma - p| / p below it ends the consolidation: 1 or more would accept any stress
    check_number(args.consolidation_tol, "--consolidation-tol", low=0, high=1, low_open=True, high_open=True)
    for name, v in (("--damping-ratio", args.damping_ratio), ("--kt-ratio", args.kt_ratio), ("--mu", args.mu)):
        if v is not None:
            as_positive_float(v, name, allow_zero=True)
    for name, v, lo in (
        ("--consolidation-steps", args.consolidation_steps, 1),
        ("--series-every", args.series_every, 1),
        ("--snapshot-every", args.snapshot_every, 1),
        ("--checkpoint-every", args.checkpoint_every, 0),
    ):
        check_count(v, name, lo)  # within 64 bits too (the step counters)
    check_count(args.threads, "--threads", 1)
    if args.resume:
        from ..dem.output import part_paths  # noqa: PLC0415 - start-up: numba

        if not os.path.exists(args.output) and not part_paths(args.output):
            raise InputError(
                f"--resume: {args.output!r} (-o/--output) does not exist: no run to continue; drop "
                "--resume to start one"
            )
    if args.order == "fast" and args.mode != "serial":
        raise InputError("--mode: the fast order has its own threads (--order fast --threads N); drop --mode")
    if args.threads is not None and args.mode != "parallel" and args.order != "fast":
        raise InputError(
            f"--threads {args.threads}: only --mode parallel or --order fast run on threads (--mode {args.mode} "
            "runs on one); drop --threads or give --mode parallel or --order fast"
        )
    from ..dem.settings import FLAVOURS  # noqa: PLC0415 - start-up: numba

    if args.flavour is not None and args.flavour not in FLAVOURS:
        raise InputError(f"--flavour: expected one of {', '.join(FLAVOURS)}, got {args.flavour!r}")
    if args.law_param and not args.law:
        raise InputError("--law-param: given without --law (name the law the parameters belong to)")
    if args.law:
        from ..contacts.laws import law_code  # noqa: PLC0415 - start-up: numba

        try:
            code = law_code(args.law)
        except InputError as e:
            raise InputError(f"--law: {e}") from None
        if args.flavour is not None and args.flavour != code:
            raise InputError(f"--flavour {args.flavour}: the law {args.law} is {code}'s; drop --flavour or give {code}")
        parse_law_params(args.law_param)
    if args.threads is not None:
        from .._numba import check_threads  # noqa: PLC0415 - start-up: numba

        check_threads(args.threads, "--threads")


def parse_law_params(items) -> dict:
    """``KEY=VALUE`` strings of --law-param as a dict: numbers as floats, true/false as bools,
    other values (``damping=tsuji``) as strings; InputError for a malformed or repeated item."""
    out = {}
    for it in items:
        key, sep, val = str(it).partition("=")
        key, val = key.strip(), val.strip()
        if not sep or not key.isidentifier() or not val:
            raise InputError(f"--law-param: expected KEY=VALUE (e.g. youngs_modulus=7e8), got {it!r}")
        if key in out:
            raise InputError(f"--law-param: {key} given twice")
        if val.lower() in ("true", "false"):
            out[key] = val.lower() == "true"
            continue
        try:
            out[key] = float(val)
        except ValueError:
            out[key] = val
    return out


def protocol_settings(args, packing):
    """The packing (with --density), law, DEMSettings, BiaxialSettings and law options of a run
    from the parsed options: every physical parameter from its option, the derived ones (strain
    rate from the inertial number, servo gain, dt) from the final values. InputError naming the
    option."""
    from ..dem.biaxial import default_settings, law_settings  # noqa: PLC0415 - start-up: numba
    from ..dem.engine import contact_time, damping_ratio, stability_limit  # noqa: PLC0415 - start-up: numba

    if args.density is not None:
        packing = packing.replace(density=args.density)
    opts = {
        "damping_ratio": args.damping_ratio,
        "steps_per_contact": args.steps_per_contact,
        "strain_rate": args.strain_rate,
        "inertial_number": args.inertial_number,
        "strain": args.strain,
        "kt_ratio": args.kt_ratio,
        "confining": args.confining,
        "consolidation_steps": args.consolidation_steps,
        "consolidation_tol": args.consolidation_tol,
    }
    if args.kn is not None:
        opts["kn"] = args.kn
    if args.mu is not None:
        opts["mu"] = args.mu
    law, law_options = None, None
    if args.law:
        if args.kn is not None and args.law.startswith("hertz"):
            raise InputError(
                f"--kn: not used with the Hertz law {args.law} (its stiffness scale comes from "
                "its --law-param material constants)"
            )
        try:
            law, dem, bi, law_options = law_settings(packing, args.law, parse_law_params(args.law_param), **opts)
        except InputError as e:
            raise InputError(f"--law-param: {e}") from None
    else:
        dem, bi = default_settings(packing, flavour=args.flavour or "liggghts", **opts)
    dem = dataclasses.replace(dem, mode=args.mode)
    lim = stability_limit(packing, dem)
    if dem.dt > lim:
        need = contact_time(packing, max(dem.kn, dem.kt)) / lim
        raise InputError(
            f"--steps-per-contact {args.steps_per_contact:g} with --damping-ratio "
            f"{args.damping_ratio:g}: "
            f"dt = {dem.dt:.4g} s is above the stability limit {lim:.4g} s of velocity "
            f"Verlet with "
            f"damping (damping ratio {damping_ratio(packing, dem):.3g} for the two "
            f"lightest disks); "
            f"use --steps-per-contact >= {need:.3g} or a smaller --damping-ratio"
        )
    return packing, law, dem, bi, law_options


def _run(args) -> int:
    from ..dem.biaxial import inertial_number, run_biaxial  # noqa: PLC0415 - start-up: numba
    from ..dem.output import OutputSettings, plot_stress_strain  # noqa: PLC0415 - start-up: numba
    from ..io import load_packing  # noqa: PLC0415 - start-up: h5py

    _check_options(args)
    packing, law, dem, bi, law_options = protocol_settings(args, load_packing(args.packing))
    out = OutputSettings(
        series_every=args.series_every, snapshot_every=args.snapshot_every, checkpoint_every=args.checkpoint_every
    )
    summary = run_biaxial(
        packing,
        dem,
        bi,
        args.output,
        output=out,
        resume=args.resume,
        threads=args.threads,
        allow_unsettled=args.allow_unsettled,
        law=law,
        law_options=law_options,
        order=args.order,
    )
    i_num = inertial_number(packing, bi.strain_rate, bi.confining)
    print(
        f"wrote {args.output}: {packing.n} disks, dt {dem.dt:.3g} s, confining {bi.confining:.4g} N/m, "
        f"rate {bi.strain_rate:.3g} 1/s (I = {i_num:.3g}), "
        f"mu {dem.mu:g}, {dem.flavour} arithmetic" + (f", law {args.law}" if args.law else "")
    )
    for k, v in summary.items():
        print(f"  {k:32s} {v:.6g}" if isinstance(v, float) else f"  {k:32s} {v}")
    if summary.get("unsettled_phases", "none") != "none":
        print(f"  WARNING: {summary['unsettled_phases']} did not settle (--allow-unsettled; recorded in the file)")
    if args.plot:
        plot_stress_strain(args.output, args.plot)
        print(f"wrote {args.plot}")
    return 0


def _export(args) -> int:
    from ..dem.output import plot_stress_strain, read_run, require_complete, snapshot_to_vtu  # noqa: PLC0415 - start-up: numba

    check_given_values(args)
    if not (args.vtu or args.plot):
        raise InputError("dem-export: give --vtu and/or --plot")
    check_input(args.run, "RUN")
    check_count(args.step, "--step", 0)
    if args.step is not None and not args.vtu:
        raise InputError("--step: picks the snapshot of --vtu (the plot shows the whole run); give --vtu")
    if args.vtu:
        check_output(args.vtu, "--vtu", (".vtu",))
    if args.plot:
        check_figure(args.plot, "--plot")
    check_distinct((("--vtu", args.vtu), ("--plot", args.plot)), (("RUN", args.run),))
    run = read_run(args.run)
    if args.step is not None and args.step not in run.snapshot_steps:
        have = run.snapshot_steps
        raise InputError(
            f"--step {args.step}: {args.run} has no snapshot at that step (it has {len(have)}: "
            f"{', '.join(map(str, have[:5]))}{' ... ' + str(have[-1]) if len(have) > 5 else ''})"
        )
    if not args.allow_incomplete:
        require_complete(run, args.run, hint="--allow-incomplete reads it anyway")
    elif not run.complete:
        why = run.stop_reason or "no stop_reason"
        print(f"WARNING: {args.run} is an incomplete run (complete = False): {why}")
    if args.vtu:
        snapshot_to_vtu(args.run, args.step, args.vtu, allow_incomplete=args.allow_incomplete)
        print(f"wrote {args.vtu}")
    if args.plot:
        plot_stress_strain(args.run, args.plot, allow_incomplete=args.allow_incomplete)
        print(f"wrote {args.plot}")
    return 0
