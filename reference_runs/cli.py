"""The command-line sub-commands of reference_runs, registered with ``gransim`` as plug-ins.

``gransim reference`` (list, run CASE, taylor: LIGGGHTS or LAMMPS reference runs; taylor also on
YADE, :mod:`reference_runs.yade.taylor_set`) and ``gransim
replay DECK`` (a user's LIGGGHTS or LAMMPS 2D disk deck run in its code and natively, compared step
by step: :mod:`reference_runs.replay`, docs/replay.md).

gransim never imports this package: ``pyproject.toml`` names :func:`register_reference` and
:func:`register_replay` in the entry-point group ``gransim.commands`` and :mod:`gransim.cli`
discovers them (:func:`gransim.cli.build_parser`). Module level imports only the standard library,
:mod:`gransim.paper`, :mod:`gransim.errors` and :mod:`gransim.cli._paths` (``gransim --help`` stays
fast); the work is imported in the handlers. Every option and output path is checked in the
handler before anything runs (an :class:`~gransim.errors.InputError` naming the option: exit 2),
and the reference jobs a command starts die with it (:func:`jobs_die_with_us`; a SIGKILL is
covered by each job's watchdog, :func:`reference_runs.runner.start_watched`).
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
from pathlib import Path

from gransim.cli._paths import integer, number
from gransim.errors import InputError
from gransim.paper import KN_2D

DEFAULT_OUT = "results/reference"


# ----------------------------------------------------------------------------- checks at the boundary
# Every option is checked here, once, before anything runs: a bad value is an InputError naming the
# option (exit 2). gransim.errors is light (no numpy), so this module keeps `gransim --help` fast.
def _bad(option: str, want: str, value) -> Exception:
    return InputError(f"{option}: expected {want}, got {value!r}")


def _real(value) -> float:
    """``float(value)``, NaN for what is no number (argparse gives ``[]`` for ``--option=--``)."""
    if isinstance(value, bool):
        return math.nan
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def check_count(value, option: str, low: int = 1) -> int:
    """An integer option >= ``low`` (argparse gave an int), else InputError naming ``option``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise _bad(option, f"an integer >= {low}", value)
    return value


def check_seconds(value, option: str):
    """A duration option: None (no limit) or a finite number of seconds > 0."""
    if value is None:
        return None
    v = _real(value)
    if not (math.isfinite(v) and v > 0):
        raise _bad(option, "a finite number of seconds > 0", value)
    return v


def check_between(value, option: str, low: float, high: float | None = None) -> float:
    """A real option in the open interval (low, high) (high None: no upper bound), finite."""
    v = _real(value)
    if not (math.isfinite(v) and v > low and (high is None or v < high)):
        want = f"a finite number > {low:g}" + ("" if high is None else f" and < {high:g}")
        raise _bad(option, want, value)
    return v


def check_input_file(path, option: str) -> Path:
    """An existing, readable regular file."""
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{option}: {str(p)!r} is not a file" + ("" if p.exists() else " (no such file)"))
    if not os.access(p, os.R_OK):
        raise InputError(f"{option}: {str(p)!r} is not readable")
    return p


def check_input_dir(path, option: str) -> Path:
    """An existing, readable directory."""
    p = Path(path)
    if not p.is_dir():
        raise InputError(f"{option}: {str(p)!r} is not a directory" + ("" if p.exists() else " (no such directory)"))
    if not os.access(p, os.R_OK | os.X_OK):
        raise InputError(f"{option}: directory {str(p)!r} is not readable")
    return p


def check_writable_dir(path, option: str) -> Path:
    """An output directory: created now (with its parents) and a file written into it and removed,
    so that a path below a file, on a read-only file system or in a directory without write
    permission (which ``os.access`` does not see for root) is refused before any work, naming
    ``option``."""
    if str(path).strip() == "":
        raise InputError(f"{option}: expected a directory name, got an empty string")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{option}: {str(p)!r} exists and is not a directory")
    try:
        p.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=p, prefix=".gransim-write-check-"):
            pass
    except OSError as exc:
        raise InputError(f"{option}: cannot write into {str(p)!r}: {exc.strerror or exc}") from None
    return p


@contextlib.contextmanager
def jobs_die_with_us(command: str):
    """SIGTERM, SIGINT, SIGHUP kill the reference jobs before the command ends
    (:func:`reference_runs.runner.kill_children_on_signals`); a termination is said in one line.
    The command's temporary files go to a directory of its own, removed on every exit, a SIGKILL
    included (:func:`reference_runs.runner.private_tempdir`)."""
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from reference_runs.runner import Terminated, kill_children_on_signals, private_tempdir

    try:
        with kill_children_on_signals(), private_tempdir(f"gransim-{command}-"):
            yield
    except Terminated as exc:
        print(f"gransim {command}: {exc}; its reference jobs were killed", file=sys.stderr, flush=True)
        raise


def register_reference(subparsers) -> None:
    p = subparsers.add_parser(
        "reference",
        help="LIGGGHTS, LAMMPS or YADE reference runs (needs the binary)",
        description="Run reference jobs of LIGGGHTS-PUBLIC 3.8.0 (`liggghts`) or LAMMPS (`lmp`), and the "
        "Taylor states also of YADE 2023.02a (`yade`), and parse them.",
    )
    sub = p.add_subparsers(dest="reference_command", metavar="ACTION")
    sub.required = True

    pl = sub.add_parser("list", help="list the named reference cases")
    pl.set_defaults(func=_list)

    pr = sub.add_parser("run", help="run a named reference case")
    pr.add_argument("case", help="case name (see `gransim reference list`)")
    pr.add_argument("--out", default=None, help=f"output directory (default {DEFAULT_OUT}/CASE)")
    _job_options(pr)
    pr.set_defaults(func=_run)

    pt = sub.add_parser(
        "taylor",
        help="Taylor RVE states of packings along the study paths, vs numpy",
        description="Run the Taylor (affine) states of each packing along compression "
        "11/22 (F11, F22 from 1 to 1 - max-strain) and simple shear 12/21 "
        "(F12, F21 from 0 to max-strain) through LIGGGHTS, LAMMPS or YADE, one job per "
        "packing, and compare the stresses with an independent numpy Taylor "
        "stress (YADE: also its getStressAndTangent tangent with the material part of "
        "gransim's Taylor tangent, and the contacts). Jobs already complete are skipped. "
        "Exit status 0 when everything agrees, 1 when not (YADE: also when a job failed), 2 "
        "for bad input or a missing code.",
    )
    pt.add_argument("packings", nargs="*", help="HDF5 files holding a /packing group (gransim save_packing)")
    pt.add_argument(
        "--rves",
        default=None,
        metavar="DIR",
        help="directory of RVE packing files (*.h5), e.g. the 15 RVEs of the study",
    )
    pt.add_argument("--demo", action="store_true", help="use 3 built-in 64-disk packings")
    pt.add_argument(
        "--standard",
        action="store_true",
        help="use the 15 study RVEs (rve-<N>-<seed> in --packings-dir, generated if missing)",
    )
    pt.add_argument("--packings-dir", default="results/packings", help="where the standard RVEs live")
    pt.add_argument(
        "--kn",
        type=number,
        default=None,
        help=f"2D normal contact stiffness kn = E_n * thickness, N/m (default {KN_2D:g}, "
        "gransim.paper.KN_2D: E_n of Meier et al. Table 1)",
    )
    pt.add_argument("--n-steps", type=integer, default=50, help="states per path after the reference (50)")
    pt.add_argument("--stride", type=integer, default=1, help="run every STRIDE-th state (and the last)")
    pt.add_argument("--max-strain", type=number, default=0.1, help="final |F - I| component (0.1)")
    pt.add_argument(
        "--contacts",
        action="store_true",
        help="also dump per-contact forces of every state (YADE writes them always, in taylor.out)",
    )
    pt.add_argument("--out", default=f"{DEFAULT_OUT}/taylor", help="output directory")
    _job_options(pt, engines=("liggghts", "lammps", "yade"))
    pt.set_defaults(func=_taylor)


def _check_job_options(args) -> None:
    check_count(args.np, "--np")
    args.timeout = check_seconds(args.timeout, "--timeout")


def _job_options(p, engines=("liggghts", "lammps")) -> None:
    p.add_argument(
        "--engine",
        choices=engines,
        default="liggghts",
        help="the code that runs the jobs (default liggghts)",
    )
    one = " (YADE: 1, a YADE job is one process)" if "yade" in engines else ""
    p.add_argument("--np", type=integer, default=1, help=f"MPI processes (mpirun -np N), >= 1{one}")
    p.add_argument("--timeout", type=number, default=3600.0, help="seconds per job (> 0)")
    p.add_argument(
        "--force",
        action="store_true",
        help="rerun jobs even if complete outputs exist (discards them; needs the code). Without "
        "it a stored job is reused only after its log and outputs are re-hashed and checked "
        "against the deck, and rerun automatically when that fails",
    )


def _list(args) -> int:
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from reference_runs.cases import all_cases

    for name, case in sorted(all_cases().items()):
        print(f"{name:20s} {case.description}")
    return 0


def _run(args) -> int:
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from reference_runs.cases import get_case

    case = get_case(args.case)
    _check_job_options(args)
    out = check_writable_dir(args.out or f"{DEFAULT_OUT}/{case.name}", "--out")
    with jobs_die_with_us("reference"):  # SIGTERM/SIGINT/SIGHUP: no reference process outlives us
        return case.run(
            out, np_procs=args.np, timeout=args.timeout, force=args.force, progress=True, engine=args.engine
        )


def _taylor(args) -> int:
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    kn = KN_2D if args.kn is None else check_between(args.kn, "--kn (N/m)", 0.0)
    check_count(args.n_steps, "--n-steps")
    check_count(args.stride, "--stride")
    check_between(args.max_strain, "--max-strain", 0.0, 1.0)  # F11 = 1 - max-strain > 0
    _check_job_options(args)
    if args.engine == "yade" and args.np != 1:
        raise InputError(f"--np: a YADE job runs as one process (1), got {args.np}")
    files = [check_input_file(p, "PACKINGS") for p in args.packings]
    if args.rves:
        files += sorted(check_input_dir(args.rves, "--rves").glob("*.h5"))
    if args.standard:
        check_writable_dir(args.packings_dir, "--packings-dir")  # missing RVEs are generated there
    if not (files or args.demo or args.standard):
        raise InputError("no packings: give packing files, --rves DIR, --standard or --demo")
    out = check_writable_dir(args.out, "--out")
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from gransim.io import load_packing
    from reference_runs.cases import TAYLOR_RTOL, run_taylor_set

    packings = {}
    for f in files:
        packings[f.stem] = load_packing(f)
    if args.demo:
        # lazy: this module is imported when `gransim` builds its parser (start-up time)
        from reference_runs.demo_packings import perturbed_lattice

        packings.update({f"lattice-8x8-seed{s}": perturbed_lattice(8, 8, seed=s) for s in (1, 2, 3)})
    if args.standard:
        # lazy: this module is imported when `gransim` builds its parser (start-up time)
        from reference_runs.cases import standard_rves

        packings.update(standard_rves(args.packings_dir))
    if not packings:
        raise InputError(f"no packings: --rves {args.rves} holds no *.h5 file")
    if args.engine == "yade":
        return _taylor_yade(args, packings, out, kn)
    with jobs_die_with_us("reference"):  # SIGTERM/SIGINT/SIGHUP: no reference process outlives us
        _, worst = run_taylor_set(
            packings,
            out,
            kn=kn,
            n_steps=args.n_steps,
            stride=args.stride,
            max_strain=args.max_strain,
            contacts=args.contacts,
            np_procs=args.np,
            timeout=args.timeout,
            force=args.force,
            engine=args.engine,
        )
    ok = worst <= TAYLOR_RTOL
    code = {"liggghts": "LIGGGHTS", "lammps": "LAMMPS"}[args.engine]
    print(
        f"{len(packings)} packings: largest relative difference {code} vs numpy Taylor stress = "
        f"{worst:.3e} ({'PASS' if ok else 'FAIL'}, tolerance {TAYLOR_RTOL:g})"
    )
    return 0 if ok else 1


def _taylor_yade(args, packings: dict, out: Path, kn: float) -> int:
    """``reference taylor --engine yade``: the stresses against numpy, the tangent against the
    material part of gransim's (:mod:`reference_runs.yade.taylor_set`). A missing ``yade`` is an
    error of the set-up (status 2, naming the package); a YADE job that fails (exit status,
    timeout, incomplete output) is a failed computation (status 1, the job's own message)."""
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from reference_runs.cases import TAYLOR_RTOL
    from reference_runs.engines import YADE
    from reference_runs.errors import ReferenceRunError
    from reference_runs.judge import within
    from reference_runs.yade.compare import TANGENT_RTOL
    from reference_runs.yade.taylor_set import run_yade_taylor_set

    try:
        with jobs_die_with_us("reference"):  # SIGTERM/SIGINT/SIGHUP: no YADE process outlives us
            res = run_yade_taylor_set(
                packings,
                out,
                kn=kn,
                n_steps=args.n_steps,
                stride=args.stride,
                max_strain=args.max_strain,
                timeout=args.timeout,
                force=args.force,
            )
    except ReferenceRunError as exc:
        if not YADE.available():
            raise  # the binary is missing: the message says how to install it (status 2)
        print(f"gransim reference: error: the YADE run failed: {exc}", file=sys.stderr)
        return 1
    ok_s, ok_t = within(res.stress, TAYLOR_RTOL), within(res.tangent, TANGENT_RTOL)
    print(
        f"{len(packings)} packings: largest relative difference YADE vs numpy Taylor stress = "
        f"{res.stress:.3e} ({'PASS' if ok_s else 'FAIL'}, tolerance {TAYLOR_RTOL:g}); YADE tangent vs "
        f"the material part of gransim's = {res.tangent:.3e} ({'PASS' if ok_t else 'FAIL'}, tolerance "
        f"{TANGENT_RTOL:g}); contacts {'the same' if res.contacts_match else 'DIFFER (FAIL)'}"
    )
    return 0 if ok_s and ok_t and res.contacts_match else 1


def register_replay(sub) -> None:
    p = sub.add_parser(
        "replay",
        help="replay a LIGGGHTS/LAMMPS 2D disk deck or a YADE script natively and in its code, and compare",
        description="Read a LIGGGHTS 3.8.0 or LAMMPS deck of 2D periodic disks (the supported subset: "
        "docs/replay.md; anything else is refused naming its line), run it unchanged in its "
        "code and with the native engine, compare thermo (box, compute pressure) and dumps "
        "step by step, and write OUTDIR/report.html, report.md and replay.h5. A YADE script (.py) of the "
        "supported shape (docs/replay.md, 'YADE scripts') is read without running it, run in YADE and in "
        "YADE's native arithmetic and compared frame by frame, bit for bit. Exit status 0 "
        "when everything agrees within tolerance (positions 1e-10 D50, stress 1e-8 "
        "relative), 1 when not or when evidence is missing, 2 for bad input.",
    )
    p.add_argument("deck", help="the input deck")
    p.add_argument("--data", default=None, metavar="FILE", help="data file to use instead of the one read_data names")
    p.add_argument(
        "--engine",
        default=None,
        choices=["liggghts", "lammps", "yade"],
        help="the deck's code (default: detected from its syntax; a .py file is a YADE script)",
    )
    p.add_argument(
        "-o", "--out", default=None, metavar="OUTDIR", help="output directory (default results/replay/<deck name>)"
    )
    p.add_argument(
        "--timeout",
        type=number,
        default=None,
        metavar="S",
        help="kill the code's run after S seconds (> 0; default: no limit)",
    )
    p.add_argument(
        "--reference",
        default=None,
        metavar="DIR",
        help="a finished job directory of this deck (log.lammps and dumps) to compare with instead of running the code",
    )
    p.add_argument(
        "--var",
        nargs=2,
        action="append",
        default=None,
        metavar=("NAME", "VALUE"),
        help="a variable of the deck, as the codes' -var NAME VALUE (index style; repeatable): "
        "substituted natively and passed to the code's command line",
    )
    p.set_defaults(func=_replay)


def check_variables(pairs) -> dict:
    """``--var NAME VALUE`` pairs as {NAME: VALUE}: a name of letters, digits and underscores,
    given once; a value of one word (the codes' ``-var`` reads one argument per value). The rule
    is :func:`reference_runs.engines.check_variables`, the one ``run_job`` applies; messages name
    ``--var``."""
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from reference_runs.engines import check_variables as check

    return check(pairs, option="--var")


def _replay(args) -> int:
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    deck = check_input_file(args.deck, "DECK")
    if args.data is not None:
        check_input_file(args.data, "--data")
    timeout = check_seconds(args.timeout, "--timeout")
    if args.reference is not None:
        check_input_dir(args.reference, "--reference")
    variables = check_variables(args.var)
    out = check_writable_dir(args.out if args.out is not None else Path("results/replay") / deck.name, "-o/--out")
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from reference_runs.errors import ReferenceRunError
    from reference_runs.replay.compare import replay

    def echo(msg):
        print(f"gransim replay: {msg}", file=sys.stderr, flush=True)

    try:
        with jobs_die_with_us("replay"):  # SIGTERM/SIGINT/SIGHUP: no process of the code outlives us
            res = replay(
                deck,
                data=args.data,
                engine=args.engine,
                outdir=out,
                timeout=timeout,
                reference=args.reference,
                echo=echo,
                variables=variables,
            )
    except ReferenceRunError as exc:
        print(f"gransim replay: error: the code's run failed: {exc}", file=sys.stderr)
        return 1
    bad = [c for c in res.checks if not c.passed]
    for c in bad:
        print(f"FAIL {c.quantity}: {c.metric} = {float(c.value):.3g} (tolerance {float(c.tolerance):.3g}) {c.detail}")
    print(
        f"{'PASS' if res.passed else 'FAIL'}: {len(res.checks) - len(bad)} of {len(res.checks)} checks "
        "agree; "
        f"report {res.outdir / 'report.html'}"
    )
    return 0 if res.passed else 1
