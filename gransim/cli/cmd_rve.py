"""``gransim rve-study``, ``gransim rve-stress`` and ``gransim rve-check``: Taylor RVE commands."""

from __future__ import annotations

from pathlib import Path


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
    p.add_argument(
        "--packings", nargs="+", metavar="FILE.h5", help="packing files (default: the 15 RVEs)"
    )
    p.add_argument(
        "--packing-dir",
        default="results/packings",
        metavar="DIR",
        help="where the standard RVEs are stored/generated (default: results/packings)",
    )
    p.add_argument(
        "--kn",
        type=float,
        default=None,
        help="normal stiffness E_n in N/m (default 2.8e7, Table 1)",
    )
    p.add_argument("--steps", type=int, default=50, help="load steps per path (default 50)")
    p.add_argument(
        "-o",
        "--out",
        default="results/rve_study",
        help="output directory (default results/rve_study)",
    )
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
    s.add_argument(
        "--kn", type=float, default=None, help="normal stiffness E_n in N/m (default 2.8e7)"
    )
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
    c.add_argument(
        "--packings", nargs="+", metavar="FILE.h5", help="packing files (default: the 15 RVEs)"
    )
    c.add_argument("--packing-dir", default="results/packings", metavar="DIR")
    c.add_argument("--kn", type=float, default=None)
    c.add_argument("--tol", type=float, default=1e-12)
    c.set_defaults(func=_check)


def _packings(args) -> dict:
    from ..errors import InputError
    from ..rve.study import load_packings

    if args.packings:
        return load_packings({Path(f).stem: f for f in args.packings})
    try:
        from ..generation import standard_packings
    except ImportError:
        raise InputError(
            "no --packings given and gransim.generation (the standard 15 RVEs) is not "
            "available; pass --packings FILE.h5 ..."
        ) from None
    return load_packings(standard_packings(args.packing_dir, names=standard_rve_names()))


def standard_rve_names() -> list[str]:
    """The 15 RVEs of the paper's section 4 among the standard packings (rve-70-1 .. rve-700-5)."""
    from ..generation import STANDARD_PACKINGS

    return [k for k in STANDARD_PACKINGS if k.startswith("rve-")]


def _kn(args) -> float:
    from ..rve.study import PAPER_NORMAL_STIFFNESS

    return PAPER_NORMAL_STIFFNESS if args.kn is None else args.kn


def _study(args) -> int:
    import time

    from ..rve.study import run_study

    packings = _packings(args)
    t0 = time.perf_counter()
    result, h5, pngs = run_study(packings, args.out, normal_stiffness=_kn(args), steps=args.steps)
    dt = time.perf_counter() - t0
    print(
        f"{len(result.names)} RVEs x {len(result.paths)} paths x {args.steps + 1} states "
        f"in {dt:.2f} s"
    )
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


def _stress(args) -> int:
    import numpy as np

    from ..io import open_result
    from ..rve import homogenize
    from ..rve.study import read_study_packing

    with open_result(args.file) as f:
        kind = f.attrs.get("kind")
    if kind == "rve-study":
        if args.rve is None:
            from ..errors import InputError

            raise InputError(f"{args.file} is a rve-study file: choose an RVE with --rve NAME")
        packing = read_study_packing(args.file, args.rve)
    else:
        from ..io import load_packing

        packing = load_packing(args.file)
    F = np.array(args.F, dtype=float).reshape(2, 2)
    res = homogenize(packing, F, _kn(args))
    np.set_printoptions(precision=10, suppress=False, linewidth=120)
    print(
        f"packing: N = {packing.n}, V_rve = det C = {packing.area:.10g} m^2; "
        f"E_n = {_kn(args):.6g} N/m"
    )
    print(f"F =\n{F}")
    print(f"active contacts: {res.n_contacts}")
    print(f"W (J/m^2) = {res.energy:.12g}")
    print(f"P (N/m) =\n{res.piola}")
    print(f"sigma (N/m, tension +) =\n{res.cauchy}")
    print("A[i,J,k,L] = dP_iJ/dF_kL (N/m), rows (i,J), columns (k,L) in order 11 12 21 22:")
    print(res.tangent.reshape(4, 4))
    return 0


def _check(args) -> int:
    from ..rve.reference import crosscheck

    recs = crosscheck(_packings(args), _kn(args))
    worst = max(max(r["rel_energy"], r["rel_piola"], r["rel_tangent"]) for r in recs)
    bad = [
        r
        for r in recs
        if not r["contacts_equal"]
        or max(r["rel_energy"], r["rel_piola"], r["rel_tangent"]) > args.tol
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
