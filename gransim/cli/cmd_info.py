"""``gransim info FILE.h5``: what a results file holds, its provenance and, for a packing, its statistics."""

from __future__ import annotations

import json

from ..errors import InputError, ResultFileError
from ._paths import check_given_values, check_input


def register(sub) -> None:
    p = sub.add_parser(
        "info",
        help="describe a gransim HDF5 file (packing statistics, provenance)",
        description="Print the provenance of a gransim results file; for a DEM run (biaxial or "
        "shear) whether it is complete, its series and snapshots; and, when it holds a "
        "packing, N, cell, packing fraction, void ratio, coordination and overlap "
        "statistics.",
    )
    p.add_argument("file", help="a gransim HDF5 results file")
    p.add_argument("--group", default="packing", help="group holding the packing (default: packing)")
    p.set_defaults(func=_run)


def format_stats(s: dict) -> str:
    """Human-readable lines for :func:`gransim.generation.packing_stats`."""
    c = s["cell"]
    return "\n".join(
        [
            f"N                      {s['n']}",
            f"cell (columns, m)      a1 = ({c[0][0]:.6g}, {c[1][0]:.6g})  a2 = ({c[0][1]:.6g}, {c[1][1]:.6g})",
            f"packing fraction       {s['solid_fraction']:.5f}",
            f"void ratio             {s['void_ratio']:.5f}",
            f"D50 / mean diameter    {s['d50'] * 1e3:.5g} mm / {s['mean_diameter'] * 1e3:.5g} mm "
            f"(range {s['d_min'] * 1e3:.4g}-{s['d_max'] * 1e3:.4g} mm)",
            f"contacts               {s['n_contacts']}",
            f"coordination 2Nc/N     {s['coordination']:.4f}",
            f"  without rattlers     {s['coordination_nonrattler']:.4f} "
            f"({s['n_rattlers']} rattlers, {100 * s['rattler_fraction']:.1f} %)",
            f"mean overlap           {s['mean_overlap']:.4g} m = {100 * s['mean_overlap_d50']:.4g} % of D50 "
            f"= {100 * s['mean_overlap_dmean']:.4g} % of mean diameter",
            f"max overlap            {s['max_overlap']:.4g} m = {100 * s['max_overlap_d50']:.4g} % of D50",
            f"fabric anisotropy a    {s['fabric_anisotropy']:.4f}",
        ]
    )


def _dem_run_status(path, prov: dict) -> None:
    """complete / stop_reason / unsettled phases / sampling of a DEM run file (a biaxial "dem-run"
    or a simple-shear "shear-run"), then its structure check (a truncated or corrupt file raises
    ResultFileError after these lines)."""
    from ..dem.output import read_run  # noqa: PLC0415 - start-up: numba

    complete = prov.get("complete")
    why = prov.get("stop_reason") or ""
    if complete is None:
        print("complete               MISSING (no 'complete' attribute: not a dem-run file of docs/schema_dem.md)")
    elif complete:
        print("complete               True")
    else:
        print(f"complete               False  INCOMPLETE RUN: {why or 'no stop_reason recorded'}")
    if why and complete:
        print(f"stop_reason            {why}")
    try:
        unsettled = json.loads(prov.get("unsettled_phases") or "[]")
    except (TypeError, json.JSONDecodeError):
        unsettled = [{"name": "?", "reason": f"unreadable unsettled_phases {prov.get('unsettled_phases')!r}"}]
    if unsettled:
        for u in unsettled:
            print(f"UNSETTLED phase        {u.get('name')}: {u.get('reason')} (continued with allow_unsettled)")
    elif complete and prov.get("kind") == "dem-run":  # a shear run has no settling phase
        print("unsettled phases       none")
    if prov.get("output_settings"):
        print(f"output settings        {prov['output_settings']}")
    try:
        run = read_run(path)
    except ResultFileError:
        print("structure              BROKEN (see the error)")
        raise
    s = run.series
    print(
        f"series                 {len(s['step'])} rows, steps {int(s['step'][0])}..{int(s['step'][-1])}; "
        f"{len(run.snapshot_steps)} snapshots"
    )
    c = s["cell"][-1]
    print(f"last cell (columns, m) a1 = ({c[0, 0]:.6g}, {c[1, 0]:.6g})  a2 = ({c[0, 1]:.6g}, {c[1, 1]:.6g})")
    if "shear_strain" in s:
        print(f"shear strain reached   {float(s['shear_strain'][-1]):.6g} (gamma = (xy - xy0)/Ly0)")


def _run(args) -> int:
    from ..generation import packing_stats  # noqa: PLC0415 - start-up: numba
    from ..io import load_packing, open_result, read_provenance  # noqa: PLC0415 - start-up: h5py

    check_given_values(args)
    check_input(args.file, "FILE")
    if not args.group.strip("/ "):
        raise InputError(f"--group: expected the name of an HDF5 group (e.g. packing), got {args.group!r}")
    prov = read_provenance(args.file)
    print(f"file                   {args.file}")
    print(
        f"kind                   {prov.get('kind')}  (gransim {prov.get('gransim_version')}, "
        f"commit {prov.get('git_commit')}, created {prov.get('created')})"
    )
    if prov.get("parameters"):
        print(f"parameters             {prov['parameters']}")
    if prov.get("kind") in ("dem-run", "shear-run"):
        _dem_run_status(args.file, prov)
    with open_result(args.file) as f:
        has_packing = args.group in f
        contents = sorted(f.keys())
    if not has_packing:
        if args.group != "packing":
            raise ResultFileError(f"{args.file}: no group {args.group!r} (has {contents})")
        print(f"groups                 {', '.join(contents) or '(none)'}")
        return 0
    print(format_stats(packing_stats(load_packing(args.file, group=args.group))))
    return 0
