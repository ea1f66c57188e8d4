"""``gransim rve-study``, ``gransim rve-stress`` and ``gransim rve-check``: Taylor RVE commands."""

from __future__ import annotations

import time
from pathlib import Path

from ..errors import InputError, SimulationError
from ..parallel import add_options, make_executor  # register() needs add_options: loaded by --help either way
from ._paths import (
    check_distinct,
    check_executor_options,
    check_given_values,
    check_input,
    check_number,
    check_output,
    check_output_dir,
    integer,
)

#: most load steps per path of rve-study (the paper uses 50)
MAX_STEPS = 100_000
#: where rve-study and rve-check keep the standard RVEs when no --packings are given
DEFAULT_PACKING_DIR = "results/packings"


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "rve-study",
        help="Taylor RVE stress paths (compression 11/22, shear 12/21) and contact fabric",
        description="Figs 3-5 of Meier, Steinmann & Kuhl: for every RVE, Cauchy stress along "
        "uniaxial "
        "compression (F11 or F22 from 1 to 1-c) and simple shear (F12 or F21 from 0 to s), "
        "mean and std per RVE size, contact normal densities. Writes OUT/rve_study.h5 and "
        "OUT/{compression,shear,fabric}.png. Without --packings the 15 standard RVEs "
        "(rve-70-1 .. rve-700-5) of gransim.generation are used (generated on first use).",
    )
    p.add_argument("--packings", nargs="+", metavar="FILE.h5", help="packing files (default: the 15 RVEs)")
    p.add_argument(
        "--packing-dir",
        metavar="DIR",
        help=f"where the standard RVEs are stored/generated, without --packings (default: {DEFAULT_PACKING_DIR})",
    )
    p.add_argument(
        "--kn",
        type=float,
        default=None,
        help="normal stiffness E_n in N/m (default 2.8e7, Table 1)",
    )
    p.add_argument("--steps", type=integer, default=50, help=f"load steps per path, 1 to {MAX_STEPS} (default 50)")
    p.add_argument(
        "-o",
        "--out",
        default="results/rve_study",
        help="output directory (default results/rve_study)",
    )

    add_options(p)  # --workers N / --scheduler ADDRESS: one task per RVE (gransim.parallel)
    p.set_defaults(func=_study)

    s = subparsers.add_parser(
        "rve-stress",
        help="W, P, sigma and tangent of one RVE at one deformation gradient",
        description="Taylor homogenization (eqs 6-12) of the packing in FILE.h5 (a packing file, "
        "or a "
        "rve-study file with --rve NAME) at F = [[a, b], [c, d]]. Tension positive; "
        "A[i,J,k,L] = dP_iJ/dF_kL.",
    )
    s.add_argument("file", metavar="FILE.h5")
    s.add_argument(
        "--F",
        nargs=4,
        type=float,
        metavar=("F11", "F12", "F21", "F22"),
        default=[1, 0, 0, 1],
        help="deformation gradient, row by row (default identity)",
    )
    s.add_argument("--kn", type=float, default=None, help="normal stiffness E_n in N/m (default 2.8e7)")
    s.add_argument("--rve", default=None, help="RVE name inside a rve-study file")
    s.set_defaults(func=_stress)

    c = subparsers.add_parser(
        "rve-check",
        help="cross-check the numba Taylor kernel against the brute-force sum on packings",
        description="Compares W, P, A and contact counts of the numba path with the plain-numpy "
        "sum over "
        "all periodic image pairs at 8 deformation gradients per packing; fails (exit 1) "
        "above --tol relative.",
    )
    c.add_argument("--packings", nargs="+", metavar="FILE.h5", help="packing files (default: the 15 RVEs)")
    c.add_argument(
        "--packing-dir",
        metavar="DIR",
        help=f"where the standard RVEs are stored/generated, without --packings (default: {DEFAULT_PACKING_DIR})",
    )
    c.add_argument("--kn", type=float, default=None, help="normal stiffness E_n in N/m (default 2.8e7)")
    c.add_argument("--tol", type=float, default=1e-12, help="relative tolerance, >= 0 (default 1e-12)")
    c.set_defaults(func=_check)


def _check_packing_options(args) -> None:
    """--packings files exist and have distinct names; --packing-dir (only without --packings: it
    is where the standard RVEs are kept) can hold the standard RVEs."""
    check_given_values(args)
    if args.packings and args.packing_dir is not None:
        raise InputError("--packing-dir: holds the standard RVEs, not used with --packings; give one of them")
    if args.packings:
        seen = {}
        for f in args.packings:
            check_input(f, "--packings")
            stem = Path(f).stem
            if stem in seen:
                raise InputError(
                    f"--packings: {seen[stem]!r} and {f!r} both give the RVE name {stem!r} "
                    "(RVEs are named by file stem); rename one"
                )
            seen[stem] = f
    else:
        args.packing_dir = DEFAULT_PACKING_DIR if args.packing_dir is None else args.packing_dir
        check_output_dir(args.packing_dir, "--packing-dir")
    check_number(args.kn, "--kn", low=0, low_open=True)


def _packings(args) -> dict:
    from ..rve.study import load_packings  # noqa: PLC0415 - start-up: numba

    if args.packings:
        return load_packings({Path(f).stem: f for f in args.packings})
    try:
        from ..generation import standard_packings  # noqa: PLC0415 - start-up: numba
    except ImportError:
        raise InputError(
            "no --packings given and gransim.generation (the standard 15 RVEs) is not "
            "available; pass --packings FILE.h5 ..."
        ) from None
    return load_packings(standard_packings(args.packing_dir, names=standard_rve_names()))


def standard_rve_names() -> list[str]:
    """The 15 RVEs of the paper's section 4 among the standard packings (rve-70-1 .. rve-700-5)."""
    from ..generation import STANDARD_PACKINGS  # noqa: PLC0415 - start-up: numba

    return [k for k in STANDARD_PACKINGS if k.startswith("rve-")]


def _kn(args) -> float:
    from ..rve.study import PAPER_NORMAL_STIFFNESS  # noqa: PLC0415 - start-up: numba

    return PAPER_NORMAL_STIFFNESS if args.kn is None else args.kn


def _study(args) -> int:
    from ..rve.study import run_study  # noqa: PLC0415 - start-up: numba

    _check_packing_options(args)
    check_number(args.steps, "--steps", low=1, high=MAX_STEPS, integer=True)
    out = check_output_dir(args.out, "-o/--out")
    written = [out / "rve_study.h5"] + [out / f"{name}.png" for name in ("compression", "shear", "fabric")]
    for path in written:
        check_output(path, "-o/--out")
    check_distinct([("-o/--out", w) for w in written], [("--packings", f) for f in args.packings or ()])
    check_executor_options(args.workers, args.scheduler)
    packings = _packings(args)
    with make_executor(args.workers, args.scheduler) as executor:
        t0 = time.perf_counter()
        result, h5, pngs = run_study(
            packings, args.out, normal_stiffness=_kn(args), steps=args.steps, executor=executor
        )
        dt = time.perf_counter() - t0
    print(f"{len(result.names)} RVEs x {len(result.paths)} paths x {args.steps + 1} states in {dt:.2f} s")
    for n, (mean, std, count) in result.summary().items():
        q = result.paths.index("compression11")
        print(
            f"  N={n:5d} ({count} RVEs): sigma11 at F11={result.drive[q, -1]:.3f}: "
            f"{mean[q, -1, 0, 0]:.6g} +- {std[q, -1, 0, 0]:.3g} N/m; "
            f"most uniform: {result.most_uniform(n)}"
        )
    print(f"wrote {h5}")
    for p in pngs:
        print(f"wrote {p}")
    return 0


def check_F(values, packing, option: str = "--F"):
    """The deformation gradient of rve-stress: finite, det F > 0, the deformed cell still larger
    than the largest disk, and a candidate search that fits into memory. Returns F (2, 2)."""
    import numpy as np  # noqa: PLC0415 - start-up: numpy

    from ..rve.taylor import check_candidate_budget, shortest_lattice_vector  # noqa: PLC0415 - start-up: numba

    F = np.array(values, dtype=float).reshape(2, 2)
    if not np.all(np.isfinite(F)):
        raise InputError(f"{option}: expected finite entries, got {F.ravel().tolist()}")
    with np.errstate(all="ignore"):
        det = float(F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0])
        Cd = F @ packing.cell
        cell_ok = bool(np.all(np.isfinite(Cd)) and np.isfinite(Cd[0, 0] * Cd[1, 1] - Cd[0, 1] * Cd[1, 0]))
    if not det > 0 or not np.isfinite(det):
        raise InputError(
            f"{option}: det F must be > 0 and finite (the map must keep orientation), got "
            f"det F = {det:.6g} for F = {F.ravel().tolist()}"
        )
    if not cell_ok:
        raise InputError(f"{option}: F = {F.ravel().tolist()} maps the cell out of the float64 range")
    b1 = float(np.linalg.norm(shortest_lattice_vector(Cd)))
    dmax = 2.0 * float(packing.radii.max())
    if b1 < dmax:
        raise InputError(
            f"{option}: F = {F.ravel().tolist()} collapses the RVE: the deformed cell's shortest lattice "
            f"vector ({b1:.4g} m) is shorter than the largest disk diameter ({dmax:.4g} m), so a disk "
            f"would overlap its own periodic image (smallest stretch of F: "
            f"{float(np.linalg.svd(F, compute_uv=False).min()):.3g})"
        )
    check_candidate_budget(packing, F, name=option)
    return F


def _read_stress_packing(args):
    from ..io import load_packing, open_result  # noqa: PLC0415 - start-up: h5py
    from ..rve.study import read_study_packing, study_rve_names  # noqa: PLC0415 - start-up: numba

    check_input(args.file, "FILE.h5")
    with open_result(args.file) as f:
        kind = f.attrs.get("kind")
    if kind == "rve-study":
        names = study_rve_names(args.file)
        if args.rve is None:
            raise InputError(
                f"{args.file} is a rve-study file: choose an RVE with --rve NAME (one of: {', '.join(names)})"
            )
        if args.rve not in names:
            raise InputError(f"--rve: {args.file} has no RVE {args.rve!r}; choose one of: {', '.join(names)}")
        return read_study_packing(args.file, args.rve)
    if args.rve is not None:
        raise InputError(
            f"--rve applies to rve-study files; {args.file} holds a {kind!r}, not a set of RVEs (drop --rve)"
        )
    return load_packing(args.file)


def _stress(args) -> int:
    import numpy as np  # noqa: PLC0415 - start-up: numpy

    from ..rve import homogenize  # noqa: PLC0415 - start-up: numba

    check_given_values(args)
    check_number(args.kn, "--kn", low=0, low_open=True)
    packing = _read_stress_packing(args)
    F = check_F(args.F, packing)
    res = homogenize(packing, F, _kn(args))
    if not (
        np.all(np.isfinite(res.cauchy))
        and np.isfinite(res.energy)
        and np.all(np.isfinite(res.piola))
        and np.all(np.isfinite(res.tangent))
    ):
        raise SimulationError(f"non-finite result at F = {F.ravel().tolist()} (W = {res.energy!r}); nothing written")
    np.set_printoptions(precision=10, suppress=False, linewidth=120)
    print(f"packing: N = {packing.n}, V_rve = det C = {packing.area:.10g} m^2; E_n = {_kn(args):.6g} N/m")
    print(f"F =\n{F}")
    print(f"active contacts: {res.n_contacts}")
    print(f"W (J/m^2) = {res.energy:.12g}")
    print(f"P (N/m) =\n{res.piola}")
    print(f"sigma (N/m, tension +) =\n{res.cauchy}")
    print("A[i,J,k,L] = dP_iJ/dF_kL (N/m), rows (i,J), columns (k,L) in order 11 12 21 22:")
    print(res.tangent.reshape(4, 4))
    return 0


def _check(args) -> int:
    from ..rve.reference import crosscheck  # noqa: PLC0415 - start-up: numba

    _check_packing_options(args)
    check_number(args.tol, "--tol", low=0)
    recs = crosscheck(_packings(args), _kn(args))
    worst = max(max(r["rel_energy"], r["rel_piola"], r["rel_tangent"]) for r in recs)
    bad = [
        r for r in recs if not r["contacts_equal"] or max(r["rel_energy"], r["rel_piola"], r["rel_tangent"]) > args.tol
    ]
    names = sorted({r["rve"] for r in recs})
    print(
        f"{len(names)} packings x {len(recs) // max(1, len(names))} deformations: largest relative "
        f"difference {worst:.3g} (tolerance {args.tol:g}); contact counts equal: "
        f"{all(r['contacts_equal'] for r in recs)}"
    )
    for r in bad:
        print(f"  FAIL {r['rve']} F={r['F']}: {r}")
    return 1 if bad else 0
