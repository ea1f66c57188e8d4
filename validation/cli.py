"""``gransim validate``: native gransim against LIGGGHTS and LAMMPS, case by case, and the HTML report.

A plug-in of the ``gransim`` command: ``pyproject.toml`` names :func:`register` in the entry-point
group ``gransim.commands`` and :func:`gransim.cli.build_parser` discovers it; gransim never imports
this package. Module level imports nothing but the standard library (``gransim --help`` stays fast).

Every option is checked before anything runs (``--jobs``, ``--timeout``, ``--results``, ``--case``:
an error naming the option, exit 2), and no reference job outlives the command, whatever ends it
(:func:`reference_runs.cli.jobs_die_with_us`, the jobs' watchdogs).
"""

from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser(
        "validate",
        help="run the validation suite and write results/report/index.html",
        description="Run the validation cases (native gransim vs LIGGGHTS and LAMMPS "
        "reference runs), write results/validation.json, results/validation.h5 and "
        "results/report/index.html. Exit status 1 when any case fails.",
    )
    p.add_argument(
        "--suite",
        default="default",
        choices=["quick", "default", "full"],
        help="quick (< 2 min, used by tests), default (make run), full (more seeds, larger)",
    )
    p.add_argument("--jobs", type=_integer, default=1, help="parallel reference jobs (>= 1, default 1)")
    p.add_argument("--results", default="results", help="results directory (default ./results)")
    p.add_argument("--case", action="append", default=None, help="run only this case (repeatable)")
    p.add_argument(
        "--timeout",
        type=_number,
        default=None,
        metavar="SECONDS",
        help="kill any reference job running longer than this (default: scaled with the job's "
        "work, ~20x LIGGGHTS' speed)",
    )
    p.set_defaults(func=_run)


def _integer(text):
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from gransim.cli._paths import integer

    return integer(text)


def _number(text):
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from gransim.cli._paths import number

    return number(text)


def _run(args) -> int:
    # lazy: this module is imported when `gransim` builds its parser (start-up time)
    from gransim._validate import check_choice
    from reference_runs.cli import check_count, check_seconds, check_writable_dir, jobs_die_with_us

    check_count(args.jobs, "--jobs")
    timeout = check_seconds(args.timeout, "--timeout")
    if args.case:
        from validation.core import registered_cases

        known = {c.id for c in registered_cases(args.suite)}
        for case in args.case:
            check_choice(case, "--case", known)
    results = check_writable_dir(args.results, "--results")
    from validation.runner import run_validation

    with jobs_die_with_us("validate"):
        ok, _ = run_validation(args.suite, results, args.jobs, only=args.case, timeout=timeout)
    return 0 if ok else 1
