"""``gransim voidcells RUN.h5 --strain 0.0001 0.0016``: Kuhn's void-cell maps and statistics."""

from __future__ import annotations

import csv
import math
from pathlib import Path

from ..errors import InputError
from ._paths import check_distinct, check_given_values, check_input, check_output

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
        "strains of a DEM run: PNG maps of alignment (Fig. 8), vorticity (Fig. 9), "
        "relative motion (Fig. 10), alpha histograms, VTK polygons and a table "
        "(mean alpha, fraction alpha <= 0, faces/edges/vertices, 2M/N), with a first "
        "row for the initial graph (the first snapshot of the compression phase).",
    )
    p.add_argument("run", help="DEM run file (HDF5, kind dem-run, docs/schema_dem.md)")
    p.add_argument(
        "--strain",
        type=float,
        nargs="+",
        default=[1e-4, 1.6e-3],
        help="axial compressive strains eps22 = -ln(Ly/Ly0) (default 0.0001 0.0016)",
    )
    p.add_argument(
        "--motion",
        choices=["velocity", "displacement"],
        default="velocity",
        help="particle velocities (default) or displacements to the next snapshot",
    )
    p.add_argument(
        "--velocities",
        choices=["remap", "absolute"],
        default="remap",
        help="stored velocities exclude the affine box remap (default; native DEM and "
        "LIGGGHTS 'fix deform remap x') or are absolute",
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


def format_table(rows: list) -> str:
    """Markdown table of the summaries, with the paper's values in the last rows."""
    cols = [
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
    ]
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        lines.append("| " + " | ".join(f"{r[c]:.4g}" if isinstance(r[c], float) else str(r[c]) for c in cols) + " |")
    lines.append(
        f"| Kuhn (1997), initial graph | 0 | | {PAPER['faces']} | {PAPER['edges']} | "
        f"{PAPER['vertices']} | 0 | {PAPER['coordination']} | | |"
    )
    lines.append(f"| Kuhn (1997) | 0.0001 | | | | | | | {PAPER['mean_alpha_at_0.0001']} | |")
    lines.append(f"| Kuhn (1997) | 0.0016 | | | | | | | | about {PAPER['fraction_alpha_le_0_at_0.0016']} |")
    return "\n".join(lines)


def handler(args) -> int:
    from ..io.hdf5 import atomic_path  # noqa: PLC0415 - start-up: h5py
    from ..voidcell import VoidCells  # noqa: PLC0415 - start-up: numba
    from ..voidcell.io import load_run_snapshots  # noqa: PLC0415 - start-up: numba
    from ..voidcell.plots import save_figures  # noqa: PLC0415 - start-up: numba
    from ..voidcell.vtk import cells_to_vtu  # noqa: PLC0415 - start-up: numba

    check_given_values(args)
    run = check_input(args.run, "RUN")
    out = Path(args.out) if args.out else run.with_name(run.stem + "_voidcells")
    if out.exists() and not out.is_dir():
        raise InputError(f"--out: {str(out)!r} exists and is not a directory; expected an output folder")
    for name in ("voidcells.csv", "voidcells.md"):  # the folder (or its first existing parent) is writable
        check_output(out / name, "--out")
    # the tables written into --out (the maps are strain_*.png / .vtu: not a run file's name)
    check_distinct([("--out", out / n) for n in ("voidcells.csv", "voidcells.md", "frames.csv")], [("RUN", run)])
    for v in args.strain:
        if not math.isfinite(v):
            raise InputError(f"--strain: {v!r} is not a finite number")
    rows = []
    strains = list(args.strain) if args.no_initial else [0.0] + list(args.strain)
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

        with open_result(run, kind="dem-run") as f:
            complete, why = check_complete(f, run, allow_incomplete=True)
        if not complete:
            print(f"WARNING: {run} is an incomplete run (complete = False): {why}")
    out.mkdir(parents=True, exist_ok=True)
    for rs in picked:
        vc = VoidCells().compute(rs.snapshot)
        tag = f"strain_{rs.requested:.6g}"
        if rs.requested == 0.0 and not args.no_initial:  # the initial graph: counts only
            rows.append({"strain": rs.strain, "requested": rs.requested, "step": rs.step, **vc.summary()})
            continue
        save_figures(vc, out / tag, label=f"eps22 = {100 * rs.strain:.3g}% (step {rs.step})")
        if not args.no_vtk:
            cells_to_vtu(out / f"{tag}.vtu", vc)
        rows.append({"strain": rs.strain, "requested": rs.requested, "step": rs.step, **vc.summary()})
    with atomic_path(out / "voidcells.csv", suffix=".csv") as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    if args.all_frames:
        frames = []
        for rs in frames_in:
            vc = VoidCells().compute(rs.snapshot)
            frames.append({"strain": rs.strain, "step": rs.step, **vc.summary()})
        with atomic_path(out / "frames.csv", suffix=".csv") as tmp:
            with open(tmp, "w", newline="") as fh:
                w = csv.DictWriter(fh, fieldnames=list(frames[0]))
                w.writeheader()
                w.writerows(frames)
        bad = [f["step"] for f in frames if f["euler"] != 0]
        print(
            f"{len(frames)} frames: F - E + V = 0 on {len(frames) - len(bad)} of them"
            + (f" (fails at steps {bad})" if bad else "")
            + f"; first frame (step {frames[0]['step']}): {frames[0]['faces']} faces, "
            f"{frames[0]['edges']} edges, {frames[0]['vertices']} vertices"
        )
    table = format_table(rows)
    with atomic_path(out / "voidcells.md", suffix=".md") as tmp:
        tmp.write_text(table + "\n")
    print(table)
    print(
        f"wrote {out}/ (PNG maps, voidcells.csv, voidcells.md{'' if args.no_vtk else ', .vtu'}"
        f"{', frames.csv' if args.all_frames else ''})"
    )
    return 0
