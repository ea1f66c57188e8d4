"""``gransim warmup``: compile every command's numba kernels into the disk cache (run by ``make``).

Each built-in command is run for real, in its own process (``python -m gransim ...``), on a tiny
problem: a 60-disk packing (FIRE and frictional compaction), a biaxial test of a few dozen steps
with the default law, the threaded force loop and each ``--law``, a sheared cell, void cells, Taylor
RVEs, the slope's dead-load step on a 3x3 mesh (``--stop-after 1``: with the 60-disk RVE the footing
step does not converge on 2x2 or 3x3 meshes; measured). Not warmed: the relaxed RVE (``slope --rve
relaxed`` took over 10 minutes on a 3x3 mesh on the loaded machine, and no lighter command reaches
it). The kernels numba compiles are specialised on types, not sizes, so the cache written here
serves the full-size runs (docs/startup.md). Working at the command line keeps the warm-up
independent of the modules' internals: an option a command no longer has is left out (read from the
command's parser), a command that does not exist is skipped with a line that says so, and a command
that fails makes ``gransim warmup`` fail (exit 1) after the others have run.

One line per command: its name, the wall time and ``ok`` / ``FAILED`` / ``skipped``. The cache is
numba's (``NUMBA_CACHE_DIR``; unset, the one :mod:`gransim` picks, see :mod:`gransim._numba`).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from dataclasses import dataclass, replace
from pathlib import Path

from ..errors import InputError
from . import build_parser
from ._paths import check_count, check_given_values, check_input, check_number, check_output_dir, same_file

#: a value for each law parameter that the protocol does not fill (biaxial --law-param: kn, kt,
#: gamma_n, gamma_t, mu/friction default to the protocol's), SI, plausible for the 60-disk packing
#: (Hertz: README's tour; damp is a restitution coefficient under LAMMPS' tsuji damping)
LAW_PARAMS = {
    "youngs_modulus": "5e8",
    "poisson_ratio": "0.3",
    "restitution": "0.5",
    "damp": "0.5",
    "mu_r": "0.1",
    "eta_r": "0.3",
    "xgammat": "0.5",
    "kroll": "1e4",
    "gammaroll": "1e-3",
    "muroll": "0.1",
}
#: laws that take the parameters the protocol would fill in their own units (hertz-lammps: kn, kt
#: in Pa = 4/3 Y* and 2/7 of it for youngs_modulus 5e8, poisson_ratio 0.3; dampings in 1/(s m))
LAW_OWN_PARAMS = {"hertz-lammps": {"kn": "3.7e8", "kt": "1.06e8", "gamma_n": "1e3", "gamma_t": "5e2"}}
#: the contact laws ``--laws`` warms: every law in biaxial and shear, every law in biaxial only (make run:
#: the default validation suite runs each law in the orthogonal cell and the sheared cell with its
#: default law only, measured from the numba cache entries it loads), or the default laws only
LAW_SETS = ("all", "biaxial", "default")


@dataclass(frozen=True)
class Step:
    """One command of the warm-up: ``gransim <command> <args>`` after the steps ``after``.

    ``args`` holds the positional arguments and the options the step needs (kept as they are);
    ``optional`` holds ``(option, value...)`` tuples, each left out when the command's parser
    does not know the option (``value`` empty for a flag; an option given twice is repeated).
    """

    name: str
    command: str
    args: tuple = ()
    optional: tuple = ()
    after: tuple = ()


def register(sub) -> None:
    p = sub.add_parser(
        "warmup",
        help="compile every command's numba kernels into the disk cache",
        description=__doc__.split("\n\n")[1].replace("\n", " "),
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=None,
        help="commands run at once (default: 2, or 1 on a one-core machine)",
    )
    p.add_argument(
        "--only",
        action="append",
        metavar="NAME",
        help="only this step (repeatable; its prerequisites run too; --list names them)",
    )
    p.add_argument(
        "--laws",
        choices=LAW_SETS,
        default="all",
        help="all (default): the biaxial and shear commands once per contact law; biaxial: biaxial once per law, "
        "shear with its default law (what make run's validation suite runs); default: only their default law",
    )
    p.add_argument(
        "--timeout",
        type=float,
        default=900.0,
        help="seconds one command may take before it is killed and counted failed (default 900)",
    )
    p.add_argument(
        "--keep",
        metavar="DIR",
        help="run in DIR and keep the files (default: a temporary folder, removed)",
    )
    p.add_argument(
        "--packing",
        metavar="FILE.h5",
        help="run the other commands on this packing file instead of the one the pack step "
        "makes (they then need not wait for it; a small one: its size is each step's cost)",
    )
    p.add_argument("--list", action="store_true", help="print the steps and exit")
    p.set_defaults(func=_run)


def law_names() -> tuple[tuple[str, str, tuple], ...]:
    """``(name, code, required parameters)`` of every contact law ``--law`` accepts (empty when the
    registry is gone: the default laws are still warmed)."""
    try:
        from ..contacts import laws  # noqa: PLC0415 - start-up: numba; ImportError tolerated
    except ImportError:  # pragma: no cover
        return ()
    return tuple((n, laws.law_code(n), tuple(laws.law_parameters(n)[0])) for n in laws.law_names())


def _law_args(name: str, required: tuple) -> tuple:
    args = ("--law", name)
    own = LAW_OWN_PARAMS.get(name, {})
    for key in required:
        if key in own or key in LAW_PARAMS:
            args += ("--law-param", f"{key}={own.get(key, LAW_PARAMS.get(key))}")
    return args


def plan(laws: str = "all", own_packing: bool = False) -> list[Step]:
    """The warm-up steps, in an order that respects ``after`` (files are relative to the run folder).

    A step whose kernels another step compiles waits for that step (``pack --friction``: FIRE and
    the DEM engine; the other biaxial and shear steps: the engine's kernels of ``biaxial`` and
    ``shear``): two processes that compile one kernel at the same time each compile it, and the
    cache keeps one copy (``pack --friction`` beside ``pack`` and ``biaxial`` took 39 s of CPU, after
    them a few seconds).

    ``laws``: which contact laws the biaxial and shear steps run (:data:`LAW_SETS`).
    ``own_packing``: ``p.h5`` is put in the run folder beforehand (``--packing``), so no step
    waits for ``pack`` (which then writes ``p-pack.h5``).
    """
    if laws not in LAW_SETS:
        raise InputError(f"--laws: expected one of {', '.join(LAW_SETS)}, got {laws!r}")
    bi_small = (
        ("--strain", "1e-4"),
        ("--inertial-number", "1e-2"),
        ("--consolidation-steps", "200"),
        ("--allow-unsettled",),
        ("--snapshot-every", "10"),
        ("--series-every", "10"),
        ("--checkpoint-every", "0"),
    )
    steps = [
        Step("pack", "pack", ("--n", "60", "--seed", "1", "-o", "p.h5")),
        Step(
            "pack --friction",
            "pack",
            ("--n", "60", "--seed", "2", "-o", "pf.h5"),
            (("--friction", "0.05"),),
            after=("pack", "biaxial"),  # FIRE, then the DEM engine: both compiled by then
        ),
        Step("info", "info", ("p.h5",), after=("pack",)),
        Step("biaxial", "biaxial", ("--packing", "p.h5", "-o", "b.h5"), bi_small, after=("pack",)),
        Step(
            "biaxial --mode parallel",
            "biaxial",
            ("--packing", "p.h5", "-o", "bp.h5"),
            bi_small + (("--mode", "parallel"), ("--threads", "2")),
            after=("pack", "biaxial"),
        ),
        Step(
            "biaxial --flavour lammps",
            "biaxial",
            ("--packing", "p.h5", "-o", "bl.h5"),
            bi_small + (("--flavour", "lammps"),),
            after=("pack", "biaxial"),
        ),
        Step("dem-export", "dem-export", ("b.h5",), (("--vtu", "s.vtu"),), after=("biaxial",)),
        Step(
            "voidcells",
            "voidcells",
            ("b.h5",),
            (("--strain", "2e-5", "6e-5"), ("--out", "vc"), ("--all-frames",)),
            after=("biaxial",),
        ),
        Step(
            "shear",
            "shear",
            ("--packing", "p.h5", "--strain", "1e-4", "-o", "s.h5"),
            (("--flavour", "lammps"), ("--inertial-number", "1e-2")),
            after=("pack",),
        ),
        Step(
            "shear --servo",
            "shear",
            ("--packing", "p.h5", "--strain", "1e-4", "-o", "ss.h5"),
            (("--flavour", "lammps"), ("--inertial-number", "1e-2"), ("--servo", "25")),
            after=("pack", "shear"),
        ),
        Step(
            "rve-stress",
            "rve-stress",
            ("p.h5",),
            (("--F", "0.999", "0", "0", "1"),),
            after=("pack",),
        ),
        Step("rve-check", "rve-check", (), (("--packings", "p.h5"),), after=("pack",)),
        Step(
            "rve-study",
            "rve-study",
            (),
            (("--packings", "p.h5"), ("--steps", "2"), ("-o", "rs")),
            after=("pack",),
        ),
        Step(
            "slope",
            "slope",
            (),
            (
                ("--packing", "p.h5"),
                ("--mesh", "3x3"),
                ("--load-steps", "1"),
                ("--stop-after", "1"),
                ("--figures", "none"),
                ("--out", "slope"),
            ),
            after=("pack",),
        ),
    ]
    if own_packing:
        steps = [
            replace(
                s,
                # the file no longer waits for pack; the frictional pack still waits for its FIRE kernels
                after=tuple(a for a in s.after if a != "pack" or s.command == "pack"),
                args=tuple("p-pack.h5" if (s.name == "pack" and a == "p.h5") else a for a in s.args),
            )
            for s in steps
        ]
    if laws in ("all", "biaxial"):
        for name, code, required in law_names():
            steps.append(
                Step(
                    f"biaxial --law {name}",
                    "biaxial",
                    ("--packing", "p.h5", "-o", f"b-{name}.h5"),
                    bi_small + (_law_args(name, required),),
                    after=("biaxial",) if own_packing else ("pack", "biaxial"),
                )
            )
            if code == "lammps" and laws == "all":
                steps.append(
                    Step(
                        f"shear --law {name}",
                        "shear",
                        ("--packing", "p.h5", "--strain", "1e-4", "-o", f"s-{name}.h5"),
                        (
                            ("--flavour", "lammps"),
                            ("--inertial-number", "1e-2"),
                            _law_args(name, required),
                        ),
                        after=("shear",) if own_packing else ("pack", "shear"),
                    )
                )
    if laws == "all":  # the fast ordering of both cells (make test and make bench; make run's suite has none)
        pre_b = ("biaxial",) if own_packing else ("pack", "biaxial")
        pre_s = ("shear",) if own_packing else ("pack", "shear")
        fast = (("--order", "fast"), ("--threads", "2"))
        steps.append(
            Step("biaxial --order fast", "biaxial", ("--packing", "p.h5", "-o", "bf.h5"), bi_small + fast, after=pre_b)
        )
        steps.append(
            Step(
                "shear --order fast",
                "shear",
                ("--packing", "p.h5", "--strain", "1e-4", "-o", "sf.h5"),
                (("--flavour", "lammps"), ("--inertial-number", "1e-2"), *fast),
                after=pre_s,
            )
        )
    return steps


def command_options() -> dict[str, set[str]]:
    """``{command: option strings}`` of every built-in command, read from its parser."""
    parser = build_parser(["warmup"])
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {name: {s for a in p._actions for s in a.option_strings} for name, p in sub.choices.items()}


def argv_of(step: Step, options: dict[str, set[str]]) -> list[str] | None:
    """The command line of ``step`` (without ``gransim``), ``None`` when its command does not exist;
    pairs of ``step.optional`` whose option the command lacks are left out (``--law`` and
    ``--law-param`` go together: without ``--law`` the step is pointless, so it is ``None``)."""
    known = options.get(step.command)
    if known is None:
        return None
    argv = [step.command, *step.args]
    for item in step.optional:
        flags = [x for x in item if str(x).startswith("--") or x == "-o"]
        if flags[0] == "--law" and "--law" not in known:
            return None
        if all(f in known for f in flags):
            argv += list(item)
    return argv


def _selected(steps: list[Step], only) -> list[Step]:
    if not only:
        return steps
    by_name = {s.name: s for s in steps}
    unknown = [n for n in only if n not in by_name]
    if unknown:
        raise InputError(f"--only: expected step names from --list, got {', '.join(map(repr, unknown))}")
    keep, todo = set(), list(only)
    while todo:
        n = todo.pop()
        if n not in keep:
            keep.add(n)
            todo += list(by_name[n].after)
    return [s for s in steps if s.name in keep]


def _one(argv: list[str], cwd: str, timeout: float) -> tuple[int, float, float, str]:
    """Run ``gransim argv`` in ``cwd``: exit status (-1: killed after ``timeout`` s), wall and CPU
    seconds (user + system, of the child alone: the measure that does not depend on the load) and
    the tail of its output."""
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONUNBUFFERED="1")
    t0 = time.perf_counter()
    with tempfile.TemporaryFile("w+") as log:
        p = subprocess.Popen(
            [sys.executable, "-m", "gransim", *argv],
            cwd=cwd,
            env=env,
            stdout=log,
            stderr=subprocess.STDOUT,
            text=True,
        )
        killed = threading.Event()

        def _kill():
            killed.set()
            p.kill()

        timer = threading.Timer(timeout, _kill)
        timer.start()
        try:
            _, status, usage = os.wait4(p.pid, 0)
        finally:
            timer.cancel()
        p.returncode = rc = os.waitstatus_to_exitcode(status)
        wall, cpu = time.perf_counter() - t0, usage.ru_utime + usage.ru_stime
        log.seek(0)
        text = log.read()[-4000:]
    if killed.is_set():
        return -1, wall, cpu, f"killed after {timeout:g} s\n{text}"
    return rc, wall, cpu, text


def run_steps(steps: list[Step], cwd: str, jobs: int, timeout: float, out=None) -> list[dict]:
    """Run ``steps`` (prerequisites first, ``jobs`` at once) in ``cwd``; one line per step on ``out``.

    Returns one record per step: name, argv, status (``ok``, ``FAILED``, ``skipped``), seconds
    (wall) and, for a step that ran, cpu_seconds and returncode.
    A step whose prerequisite failed or was skipped is skipped.
    """
    out = sys.stdout if out is None else out
    options = command_options()
    done: dict[str, str] = {}
    records, pending, running = [], list(steps), {}
    names = {s.name for s in steps}

    def _line(rec):
        cpu = f" (cpu {rec['cpu_seconds']:6.1f} s)" if "cpu_seconds" in rec else " " * 16
        print(
            f"warmup: {rec['name']:<36s} {rec['seconds']:7.1f} s{cpu}  {rec['status']}"
            + (f"  ({rec['why']})" if rec.get("why") else ""),
            file=out,
            flush=True,
        )

    jobs = max(1, jobs)
    with ThreadPoolExecutor(max_workers=jobs) as pool:
        while pending or running:
            progressed = True
            while progressed:  # a skip can make later steps ready
                progressed = False
                for s in list(pending):
                    if len(running) >= jobs:  # submit in plan order, as workers free up
                        break
                    if all(a in done or a not in names for a in s.after):
                        pending.remove(s)
                        progressed = True
                        bad = [a for a in s.after if done.get(a) != "ok"]
                        argv = argv_of(s, options)
                        if bad or argv is None:
                            why = (
                                f"after {', '.join(bad)} did not succeed"
                                if bad
                                else f"no command {s.command!r} or option it needs"
                            )
                            rec = {
                                "name": s.name,
                                "argv": argv,
                                "status": "skipped",
                                "seconds": 0.0,
                                "why": why,
                            }
                            done[s.name] = "skipped"
                            records.append(rec)
                            _line(rec)
                            continue
                        running[pool.submit(_one, argv, cwd, timeout)] = (s, argv)
            if not running:
                if pending:  # only steps waiting on each other: a cycle in ``after``
                    raise RuntimeError(f"warm-up steps wait on each other: {[s.name for s in pending]}")
                continue
            finished, _ = wait(list(running), return_when=FIRST_COMPLETED)
            for fut in finished:
                s, argv = running.pop(fut)
                rc, secs, cpu, text = fut.result()
                rec = {
                    "name": s.name,
                    "argv": argv,
                    "status": "ok" if rc == 0 else "FAILED",
                    "seconds": secs,
                    "cpu_seconds": cpu,
                    "returncode": rc,
                }
                done[s.name] = rec["status"]
                records.append(rec)
                _line(rec)
                if rc != 0:
                    print(
                        f"warmup: {s.name} failed (exit {rc}): gransim {' '.join(argv)}\n"
                        + "\n".join("    " + ln for ln in text.strip().splitlines()[-15:]),
                        file=out,
                        flush=True,
                    )
    return records


def _run(args) -> int:
    # every option first, --list or not
    check_given_values(args)
    jobs = check_count(args.jobs, "--jobs", 1, 64) if args.jobs is not None else min(2, os.cpu_count() or 1)
    check_number(args.timeout, "--timeout", low=0, low_open=True)
    if args.keep is not None:
        check_output_dir(args.keep, "--keep")
    packing = None
    if args.packing is not None:
        from ..io import load_packing  # noqa: PLC0415 - start-up: h5py

        packing = os.path.abspath(check_input(args.packing, "--packing"))
        if args.keep is not None and (
            Path(packing).resolve().is_relative_to(Path(args.keep).resolve())
            or same_file(packing, Path(args.keep) / "p.h5")  # a hard link to the copy's name
        ):
            raise InputError(
                f"--packing: {args.packing!r} is inside --keep {args.keep!r}, where the warm-up writes its "
                "files (p.h5, b.h5, ...); keep the packing elsewhere"
            )
        load_packing(packing)  # a bad file is refused now (InputError naming it), not by each step
    steps = plan(args.laws, own_packing=packing is not None)
    steps_only = _selected(steps, args.only)
    if args.list:
        options = command_options()
        for s in steps:
            argv = argv_of(s, options)
            print(f"{s.name:<36s} " + ("(skipped: not available)" if argv is None else "gransim " + " ".join(argv)))
        return 0
    steps = steps_only
    cache = os.environ.get("NUMBA_CACHE_DIR") or "numba's default (__pycache__ beside the sources)"
    print(f"warmup: {len(steps)} commands, {jobs} at once, numba cache {cache}", flush=True)
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="gransim-warmup-") as tmp:
        cwd = tmp
        if args.keep:
            os.makedirs(args.keep, exist_ok=True)
            cwd = args.keep
        if packing is not None:
            shutil.copyfile(packing, os.path.join(cwd, "p.h5"))
        records = run_steps(steps, cwd, jobs, args.timeout)
    failed = [r["name"] for r in records if r["status"] == "FAILED"]
    cpu = sum(r.get("cpu_seconds", 0.0) for r in records)
    print(
        f"warmup: {sum(r['status'] == 'ok' for r in records)} of {len(records)} commands ok in "
        f"{time.perf_counter() - t0:.1f} s (cpu {cpu:.1f} s)" + (f"; FAILED: {', '.join(failed)}" if failed else ""),
        flush=True,
    )
    return 1 if failed else 0
