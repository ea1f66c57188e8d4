"""``gransim voidcells RUN.h5 --strain 0.0001 0.0016``: Kuhn's void-cell maps and statistics of a
biaxial run (``gransim biaxial``) or a simple-shear run in a sheared cell (``gransim shear``)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

from ..errors import InputError
from ._paths import check_distinct, check_given_values, check_input, check_output

#: the strains of Kuhn's Figs 8-10 (eps22 = 0.01% and 0.16%), the default of a biaxial run
DEFAULT_AXIAL_STRAINS = (1e-4, 1.6e-3)
#: the paper's figures (Kuhn 1997, sec. 4) set beside ours in the table
PAPER = {
    "faces": 762,
    "edges": 1633,
    "vertices": 871,
    "coordination": 3.75,
    "mean_alpha_at_0.0001": 0.73,
    "fraction_alpha_le_0_at_0.0016": 0.22,
}


def register(subparsers):
    p = subparsers.add_parser(
        "voidcells",
        help="void-cell deformation maps and statistics of a DEM run (Kuhn (1997))",
        description="Particle graph, void cells and their velocity gradients (eq 7) at chosen "
        "strains of a DEM run, biaxial (gransim biaxial) or simple shear in a sheared cell "
        "(gransim shear): PNG maps of alignment (Fig. 8), vorticity (Fig. 9), relative motion "
        "(Fig. 10), alpha histograms, VTK polygons, a table (mean alpha, fraction alpha <= 0, rms "
        "relative motion, faces/edges/vertices, 2M/N) and an HDF5 file of the per-cell measures, "
        "with a first row for the initial graph (the first snapshot of the loading). A measure the "
        "loading leaves undefined (eq 21 without a mean L_22, e.g. simple shear at constant "
        "volume) reads 'undefined (...)' with the reason.",
    )
    p.add_argument("run", help="DEM run file (HDF5, kind dem-run or shear-run: docs/schema_dem.md, docs/shear.md)")
    p.add_argument(
        "--strain",
        type=float,
        nargs="+",
        default=None,
        help="strains of the run's loading: the axial compressive strain eps22 = -ln(Ly/Ly0) of a "
        "biaxial run (default 0.0001 0.0016, Kuhn's figures), the shear strain gamma = "
        "(xy - xy0)/Ly0 of a shear run (default: its last snapshot)",
    )
    p.add_argument(
        "--motion",
        choices=["velocity", "displacement"],
        default="velocity",
        help="particle velocities (default) or displacements to the next snapshot",
    )
    p.add_argument(
        "--velocities",
        choices=["auto", "remap", "absolute"],
        default="auto",
        help="what the stored velocities are: auto (default: as the run's kind stores them), remap "
        "(without the affine box remap: native biaxial, LIGGGHTS 'fix deform remap x') or absolute "
        "(lab frame: the sheared cell, LAMMPS 'remap v')",
    )
    p.add_argument("--out", default=None, help="output folder (default: RUN stem + '_voidcells')")
    p.add_argument(
        "--all-frames",
        action="store_true",
        help="also analyse every snapshot: counts, Euler's formula, mean alpha per frame (frames.csv)",
    )
    p.add_argument(
        "--no-initial",
        action="store_true",
        help="leave out the row of the first compression snapshot (the initial graph)",
    )
    p.add_argument("--no-vtk", action="store_true", help="skip the .vtu export")
    p.add_argument(
        "--allow-incomplete",
        action="store_true",
        help="read a run file whose run did not finish (complete = False) anyway",
    )
    p.set_defaults(func=handler)


#: the table's columns (voidcells.md; voidcells.csv has every key of VoidCells.summary)
COLUMNS = [
    "requested",
    "strain",
    "step",
    "faces",
    "edges",
    "vertices",
    "euler",
    "coordination_2M_over_N",
    "mean_alpha",
    "fraction_alpha_le_0",
    "rms_v_rel",
]


def _cell(v) -> str:
    """A table cell: numbers to 4 digits, text with its bars escaped (|L| is not a column break)."""
    return f"{v:.4g}" if isinstance(v, float) else str(v).replace("|", "\\|")


def format_table(rows: list, measure: str = "axial") -> str:
    """Markdown table of the summaries; for a biaxial run (``measure`` "axial") the paper's values
    in the last rows (Kuhn's test is biaxial: a shear run has nothing to set beside them)."""
    cols = COLUMNS
    head = ["requested", "strain eps22" if measure == "axial" else "strain gamma"] + cols[2:]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(_cell(r.get(c, "")) for c in cols) + " |")
    if measure != "axial":
        return "\n".join(lines)
    lines.append(
        f"| Kuhn (1997), initial graph | 0 | | {PAPER['faces']} | {PAPER['edges']} | "
        f"{PAPER['vertices']} | 0 | {PAPER['coordination']} | | | |"
    )
    lines.append(f"| Kuhn (1997) | 0.0001 | | | | | | | {PAPER['mean_alpha_at_0.0001']} | | |")
    lines.append(f"| Kuhn (1997) | 0.0016 | | | | | | | | about {PAPER['fraction_alpha_le_0_at_0.0016']} | |")
    return "\n".join(lines)


def _write_csv(path, rows) -> None:
    from ..io.hdf5 import atomic_path  # noqa: PLC0415 - start-up: h5py

    keys = list(dict.fromkeys(k for r in rows for k in r))  # every row's keys, first-seen order
    with atomic_path(path, suffix=".csv") as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=keys)
            w.writeheader()
            w.writerows(rows)


def _analyse(rs):
    """(VoidCells, None), or (None, why) for a snapshot whose graph has no void-cell tessellation."""
    from ..voidcell import VoidCells  # noqa: PLC0415 - start-up: numba

    try:
        return VoidCells().compute(rs.snapshot), None
    except InputError as exc:
        return None, f"no void-cell tessellation ({exc})"


def handler(args) -> int:
    from ..voidcell.io import describe_run, load_run_snapshots  # noqa: PLC0415 - start-up: numba
    from ..voidcell.plots import save_figures  # noqa: PLC0415 - start-up: numba
    from ..voidcell.results import write_results  # noqa: PLC0415 - start-up: h5py
    from ..voidcell.vtk import cells_to_vtu  # noqa: PLC0415 - start-up: numba

    check_given_values(args)
    run = check_input(args.run, "RUN")
    out = Path(args.out) if args.out else run.with_name(run.stem + "_voidcells")
    if out.exists() and not out.is_dir():
        raise InputError(f"--out: {str(out)!r} exists and is not a directory; expected an output folder")
    tables = ("voidcells.csv", "voidcells.md", "voidcells.h5", "frames.csv")
    for name in tables[:3]:  # the folder (or its first existing parent) is writable
        check_output(out / name, "--out")
    # the tables written into --out (the maps are strain_*.png / .vtu: not a run file's name)
    check_distinct([("--out", out / n) for n in tables], [("RUN", run)])
    for v in args.strain or ():
        if not math.isfinite(v):
            raise InputError(f"--strain: {v!r} is not a finite number")
    info = describe_run(run, allow_incomplete=args.allow_incomplete)
    if args.strain is not None:
        requested = list(args.strain)
    elif info.measure == "axial":
        requested = list(DEFAULT_AXIAL_STRAINS)
    else:  # a shear run: its last snapshot (the last but one for displacements to the next)
        requested = [float(info.strains[-2 if args.motion == "displacement" and len(info.strains) > 1 else -1])]
    strains = requested if args.no_initial else [0.0] + requested
    try:
        picked = load_run_snapshots(
            run, strains, motion=args.motion, velocities=args.velocities, allow_incomplete=args.allow_incomplete
        )
    except InputError as exc:
        if str(exc).startswith("strain "):  # a requested strain outside the run: name the option
            raise InputError(f"--{exc}") from None
        raise
    if args.all_frames:  # read (and check) every frame before the long computation
        frames_in = load_run_snapshots(
            run, None, motion=args.motion, velocities=args.velocities, allow_incomplete=args.allow_incomplete
        )
    if args.allow_incomplete:
        from ..io.hdf5 import open_result  # noqa: PLC0415 - start-up: h5py
        from ..voidcell.io import check_complete  # noqa: PLC0415 - start-up: numba

        with open_result(run) as f:
            complete, why = check_complete(f, run, allow_incomplete=True)
        if not complete:
            print(f"WARNING: {run} is an incomplete run (complete = False): {why}")
    out.mkdir(parents=True, exist_ok=True)
    name = "eps22" if info.measure == "axial" else "gamma"
    rows, results = [], []
    for n, rs in enumerate(picked):
        vc, why = _analyse(rs)
        row = {"strain": rs.strain, "requested": rs.requested, "step": rs.step}
        if vc is None:
            print(f"WARNING: step {rs.step} ({name} = {rs.strain:.4g}): {why}")
            rows.append({**row, "faces": why})
            continue
        rows.append({**row, **vc.summary()})
        results.append((rs, vc))
        if n == 0 and not args.no_initial:  # the initial graph: counts only
            continue
        tag = f"strain_{rs.requested:.6g}"
        save_figures(vc, out / tag, label=f"{name} = {100 * rs.strain:.3g}% (step {rs.step})")
        if not args.no_vtk:
            cells_to_vtu(out / f"{tag}.vtu", vc)
    _write_csv(out / "voidcells.csv", rows)
    write_results(out / "voidcells.h5", results, run=run, kind=info.kind, motion=args.motion)
    if args.all_frames:
        frames = []
        for rs in frames_in:
            vc, why = _analyse(rs)
            row = {"strain": rs.strain, "step": rs.step}
            frames.append({**row, **vc.summary()} if vc is not None else {**row, "faces": why})
        _write_csv(out / "frames.csv", frames)
        ok = [f for f in frames if isinstance(f["faces"], int)]
        bad = [f["step"] for f in ok if f["euler"] != 0]
        none = [f["step"] for f in frames if not isinstance(f["faces"], int)]
        print(
            f"{len(frames)} frames: F - E + V = 0 on {len(ok) - len(bad)} of them"
            + (f" (fails at steps {bad})" if bad else "")
            + (f"; no tessellation at steps {none}" if none else "")
            + (
                f"; first frame (step {ok[0]['step']}): {ok[0]['faces']} faces, "
                f"{ok[0]['edges']} edges, {ok[0]['vertices']} vertices"
                if ok
                else ""
            )
        )
    table = format_table(rows, info.measure)
    from ..io.hdf5 import atomic_path  # noqa: PLC0415 - start-up: h5py

    with atomic_path(out / "voidcells.md", suffix=".md") as tmp:
        tmp.write_text(table + "\n")
    print(table)
    print(
        f"wrote {out}/ (PNG maps, voidcells.csv, voidcells.md, voidcells.h5{'' if args.no_vtk else ', .vtu'}"
        f"{', frames.csv' if args.all_frames else ''})"
    )
    return 0
