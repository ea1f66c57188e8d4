"""``gransim replay DECK``: run a user's LIGGGHTS or LAMMPS 2D disk deck in its code and natively,
compare step by step and write the report (reference_runs/replay, docs/replay.md)."""

from __future__ import annotations

import sys


def register(sub) -> None:
    p = sub.add_parser(
        "replay", help="replay a LIGGGHTS/LAMMPS 2D disk deck natively and in its code, and compare",
        description="Read a LIGGGHTS 3.8.0 or LAMMPS deck of 2D periodic disks (the supported subset: "
                    "docs/replay.md; anything else is refused naming its line), run it unchanged in its "
                    "code and with the native engine, compare thermo (box, compute pressure) and dumps "
                    "step by step, and write OUTDIR/report.html, report.md and replay.h5. Exit status 0 "
                    "when everything agrees within tolerance (positions 1e-10 D50, stress 1e-8 "
                    "relative), 1 when not or when evidence is missing, 2 for bad input.")
    p.add_argument("deck", help="the input deck")
    p.add_argument("--data", default=None, metavar="FILE",
                   help="data file to use instead of the one read_data names")
    p.add_argument("--engine", default=None, choices=["liggghts", "lammps"],
                   help="the deck's code (default: detected from its syntax)")
    p.add_argument("-o", "--out", default=None, metavar="OUTDIR",
                   help="output directory (default results/replay/<deck name>)")
    p.add_argument("--timeout", type=float, default=None, metavar="S",
                   help="kill the code's run after S seconds (default: no limit)")
    p.add_argument("--reference", default=None, metavar="DIR",
                   help="a finished job directory of this deck (log.lammps and dumps) to compare with "
                        "instead of running the code")
    p.set_defaults(func=_run)


def _run(args) -> int:
    from pathlib import Path

    from gransim.errors import InputError

    deck = Path(args.deck)
    if not deck.is_file():
        raise InputError(f"DECK: {deck} is not a file")
    if args.data is not None and not Path(args.data).is_file():
        raise InputError(f"--data: {args.data} is not a file")
    if args.timeout is not None and not args.timeout > 0:
        raise InputError(f"--timeout: expected seconds > 0, got {args.timeout!r}")
    from reference_runs.errors import ReferenceRunError
    from reference_runs.replay.compare import replay

    def echo(msg):
        print(f"gransim replay: {msg}", file=sys.stderr, flush=True)

    try:
        res = replay(deck, data=args.data, engine=args.engine, outdir=args.out, timeout=args.timeout,
                     reference=args.reference, echo=echo)
    except ReferenceRunError as exc:
        print(f"gransim replay: error: the code's run failed: {exc}", file=sys.stderr)
        return 1
    bad = [c for c in res.checks if not c.passed]
    for c in bad:
        print(f"FAIL {c.quantity}: {c.metric} = {float(c.value):.3g} (tolerance {float(c.tolerance):.3g}) "
              f"{c.detail}")
    print(f"{'PASS' if res.passed else 'FAIL'}: {len(res.checks) - len(bad)} of {len(res.checks)} checks "
          "agree; "
          f"report {res.outdir / 'report.html'}")
    return 0 if res.passed else 1
